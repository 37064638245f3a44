//! Global image alignment: the integer shift that best maps one image onto another (mean
//! absolute difference over the overlap), searched exhaustively on a small, coarse image. A
//! motion prior where the frame-to-frame prediction is off, e.g. the yaw rate jumping at the
//! onset of a turn.

use visnav_core::GrayImage;

/// The shift `(dx, dy)`, pixels, within `±max_shift_px` that minimises the mean absolute
/// difference `|b(x + dx, y + dy) − a(x, y)|` over the overlap (at least half of `a` in each
/// direction); `None` for images of different sizes or too small for the search.
#[must_use]
pub fn dominant_shift(a: &GrayImage, b: &GrayImage, max_shift_px: usize) -> Option<(i32, i32)> {
    let (w, h) = (a.width(), a.height());
    if (w, h) != (b.width(), b.height()) || w < 4 * max_shift_px || h < 4 * max_shift_px {
        return None;
    }
    let r = max_shift_px as i64;
    let (wi, hi) = (w as i64, h as i64);
    let mut best: Option<(f64, (i32, i32))> = None;
    for dy in -r..=r {
        for dx in -r..=r {
            let (x0, x1) = ((-dx).max(0), (wi - dx).min(wi));
            let (y0, y1) = ((-dy).max(0), (hi - dy).min(hi));
            let mut sum = 0.0f64;
            for y in y0..y1 {
                for x in x0..x1 {
                    let pa = a.get(x as usize, y as usize);
                    let pb = b.get((x + dx) as usize, (y + dy) as usize);
                    sum += f64::from((pb - pa).abs());
                }
            }
            let mean = sum / ((x1 - x0) * (y1 - y0)) as f64;
            if best.is_none_or(|(m, _)| mean < m) {
                best = Some((mean, (dx as i32, dy as i32)));
            }
        }
    }
    best.map(|(_, s)| s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shift_of_a_translated_texture_is_found() {
        let (w, h) = (80, 40);
        let texture = |x: i64, y: i64| ((x * 7 + y * 13) % 17 + (x * x + 3 * y) % 11) as f32 * 10.0;
        let mut a = GrayImage::new(w, h, 0.0);
        let mut b = GrayImage::new(w, h, 0.0);
        for y in 0..h {
            for x in 0..w {
                a.data_mut()[y * w + x] = texture(x as i64, y as i64);
                // b(x, y) = a(x - 5, y + 2): a's content moved 5 right and 2 up
                b.data_mut()[y * w + x] = texture(x as i64 - 5, y as i64 + 2);
            }
        }
        assert_eq!(dominant_shift(&a, &b, 8), Some((5, -2)));
        assert_eq!(dominant_shift(&a, &GrayImage::new(10, 10, 0.0), 2), None);
    }
}
