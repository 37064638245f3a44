//! Flow metrics: EPE, Fl, sparsification and AUSE, sigma-ellipse coverage — being built.
