//! Synthetic image pairs with exact ground-truth flow, for tests, calibration and benchmarks:
//! a procedural texture (a seeded sum of sinusoids with periods 5 to 60 px) seen under a known
//! motion of the whole image (translation, rotation, zoom) and optionally a box moving on top;
//! [`render_scene`] adds several overlapping boxes and scene-fixed contrast and shading (flat,
//! low-texture regions), for calibrating the uncertainty model on more realistic pairs.

/// A continuous procedural texture, intensities about 30..225.
#[derive(Debug, Clone)]
pub struct Texture {
    waves: Vec<[f64; 4]>,
}

impl Texture {
    /// A texture from a seed (a small deterministic generator, no RNG crate needed).
    #[must_use]
    pub fn new(seed: u64) -> Self {
        let mut state = seed
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        let mut next = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((state >> 11) as f64) / ((1_u64 << 53) as f64)
        };
        let waves = (0..40)
            .map(|_| {
                let period = 5.0 * 12.0_f64.powf(next());
                let angle = std::f64::consts::TAU * next();
                let k = std::f64::consts::TAU / period;
                [
                    k * angle.cos(),
                    k * angle.sin(),
                    std::f64::consts::TAU * next(),
                    0.5 + next(),
                ]
            })
            .collect();
        Self { waves }
    }

    /// Intensity at a continuous position.
    #[must_use]
    pub fn at(&self, x: f64, y: f64) -> f32 {
        let s: f64 = self
            .waves
            .iter()
            .map(|w| w[3] * (w[0] * x + w[1] * y + w[2]).sin())
            .sum();
        (127.5 + 95.0 * (s / 6.0).tanh()) as f32
    }
}

/// A global motion `x2 = c + zoom * R(angle) (x1 - c) + translation` about the image centre `c`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// Translation, px.
    pub translation_px: [f64; 2],
    /// Rotation, radians.
    pub angle_rad: f64,
    /// Scale factor.
    pub zoom: f64,
}

impl Motion {
    fn apply(&self, c: [f64; 2], p: [f64; 2]) -> [f64; 2] {
        let (s, co) = self.angle_rad.sin_cos();
        let d = [p[0] - c[0], p[1] - c[1]];
        [
            c[0] + self.zoom * (co * d[0] - s * d[1]) + self.translation_px[0],
            c[1] + self.zoom * (s * d[0] + co * d[1]) + self.translation_px[1],
        ]
    }

    fn inverse(&self, c: [f64; 2], p: [f64; 2]) -> [f64; 2] {
        let (s, co) = self.angle_rad.sin_cos();
        let d = [
            (p[0] - c[0] - self.translation_px[0]) / self.zoom,
            (p[1] - c[1] - self.translation_px[1]) / self.zoom,
        ];
        [c[0] + co * d[0] + s * d[1], c[1] - s * d[0] + co * d[1]]
    }
}

/// A box `[x0, y0, x1, y1)` (image-1 pixels) of its own texture translating by `translation_px`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MovingBox {
    /// Corners in image 1, px.
    pub rect_px: [f64; 4],
    /// Translation, px.
    pub translation_px: [f64; 2],
}

/// A synthetic pair with its ground truth.
#[derive(Debug, Clone)]
pub struct SyntheticPair {
    /// Image 1.
    pub image1: visnav_core::GrayImage,
    /// Image 2.
    pub image2: visnav_core::GrayImage,
    /// True flow per pixel of image 1, px.
    pub flow: Vec<[f32; 2]>,
    /// Whether the ground truth is meaningful (the point stays visible in image 2).
    pub visible: Vec<bool>,
}

/// How a [`render_scene`] surface looks: the procedural texture with a contrast and a mean
/// brightness that vary slowly over the surface (both fixed to the surface, so they move with
/// it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Appearance {
    /// Smallest contrast factor (1: the full texture everywhere; near 0: flat patches).
    pub min_contrast: f64,
    /// Amplitude of the slow brightness variation, intensity levels.
    pub shading: f64,
    /// Period scale of the contrast and shading fields, px.
    pub period_px: f64,
}

impl Default for Appearance {
    /// The plain texture of [`render_pair`].
    fn default() -> Self {
        Self {
            min_contrast: 1.0,
            shading: 0.0,
            period_px: 80.0,
        }
    }
}

/// A textured surface: texture, contrast field and shading field.
struct Surface {
    texture: Texture,
    field: Texture,
    look: Appearance,
}

impl Surface {
    fn new(seed: u64, look: Appearance) -> Self {
        Self {
            texture: Texture::new(seed),
            field: Texture::new(seed ^ 0x5851_f42d_4c95_7f2d),
            look,
        }
    }

    fn at(&self, x: f64, y: f64) -> f32 {
        let t = self.texture.at(x, y);
        if self.look.min_contrast >= 1.0 && self.look.shading == 0.0 {
            return t;
        }
        // the field texture has periods 5..60 px: scaled by period_px / 30 it varies slowly
        let k = 30.0 / self.look.period_px;
        let c = (f64::from(self.field.at(k * x, k * y)) - 30.0) / 195.0;
        let s = (f64::from(self.field.at(k * y + 17.0, k * x - 31.0)) - 127.5) / 95.0;
        let contrast = self.look.min_contrast + (1.0 - self.look.min_contrast) * c.clamp(0.0, 1.0);
        (127.5 + contrast * (f64::from(t) - 127.5) + self.look.shading * s).clamp(0.0, 255.0) as f32
    }
}

/// Renders a pair of `w` x `h` images: the background under `motion`, then `boxes` in order
/// (later ones on top, each translating by its own motion), every surface with its own texture
/// and `look`. Pixels whose point is hidden in image 2 (by a box on top) or leaves it are not
/// `visible`.
#[must_use]
pub fn render_scene(
    w: usize,
    h: usize,
    seed: u64,
    motion: Motion,
    boxes: &[MovingBox],
    look: Appearance,
) -> SyntheticPair {
    let bg = Surface::new(seed, look);
    let fgs: Vec<Surface> = (0..boxes.len() as u64)
        .map(|k| Surface::new(seed ^ (0x9e37_79b9_7f4a_7c15_u64.wrapping_mul(k + 1)), look))
        .collect();
    let c = [(w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0];
    let in_box = |b: &MovingBox, p: [f64; 2]| {
        p[0] >= b.rect_px[0] && p[0] < b.rect_px[2] && p[1] >= b.rect_px[1] && p[1] < b.rect_px[3]
    };
    // topmost box covering p in image 1 / image 2
    let top1 = |p: [f64; 2]| (0..boxes.len()).rev().find(|k| in_box(&boxes[*k], p));
    let top2 = |p: [f64; 2]| {
        (0..boxes.len()).rev().find(|k| {
            let t = boxes[*k].translation_px;
            in_box(&boxes[*k], [p[0] - t[0], p[1] - t[1]])
        })
    };
    let image1 = visnav_core::GrayImage::from_fn(w, h, |x, y| {
        let p = [x as f64, y as f64];
        match top1(p) {
            Some(k) => fgs[k].at(p[0], p[1]),
            None => bg.at(p[0], p[1]),
        }
    });
    let image2 = visnav_core::GrayImage::from_fn(w, h, |x, y| {
        let p = [x as f64, y as f64];
        if let Some(k) = top2(p) {
            let t = boxes[k].translation_px;
            return fgs[k].at(p[0] - t[0], p[1] - t[1]);
        }
        let q = motion.inverse(c, p);
        bg.at(q[0], q[1])
    });
    let mut flow = vec![[0.0_f32; 2]; w * h];
    let mut visible = vec![true; w * h];
    for y in 0..h {
        for x in 0..w {
            let p = [x as f64, y as f64];
            let i = y * w + x;
            let layer = top1(p);
            let q = match layer {
                Some(k) => {
                    let t = boxes[k].translation_px;
                    [p[0] + t[0], p[1] + t[1]]
                }
                None => motion.apply(c, p),
            };
            flow[i] = [(q[0] - p[0]) as f32, (q[1] - p[1]) as f32];
            let inside =
                q[0] >= 0.0 && q[1] >= 0.0 && q[0] <= (w - 1) as f64 && q[1] <= (h - 1) as f64;
            // hidden in image 2 when the topmost surface there is another one
            visible[i] = inside && top2(q) == layer;
        }
    }
    SyntheticPair {
        image1,
        image2,
        flow,
        visible,
    }
}

/// Renders a pair of `w` x `h` images under `motion`, with an optional moving box.
#[must_use]
pub fn render_pair(
    w: usize,
    h: usize,
    seed: u64,
    motion: Motion,
    moving_box: Option<MovingBox>,
) -> SyntheticPair {
    let bg = Texture::new(seed);
    let fg = Texture::new(seed ^ 0x9e37_79b9_7f4a_7c15);
    let c = [(w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0];
    let in_box = |b: &MovingBox, p: [f64; 2]| {
        p[0] >= b.rect_px[0] && p[0] < b.rect_px[2] && p[1] >= b.rect_px[1] && p[1] < b.rect_px[3]
    };
    let image1 = visnav_core::GrayImage::from_fn(w, h, |x, y| {
        let p = [x as f64, y as f64];
        match &moving_box {
            Some(b) if in_box(b, p) => fg.at(p[0], p[1]),
            _ => bg.at(p[0], p[1]),
        }
    });
    let image2 = visnav_core::GrayImage::from_fn(w, h, |x, y| {
        let p = [x as f64, y as f64];
        if let Some(b) = &moving_box {
            let q = [p[0] - b.translation_px[0], p[1] - b.translation_px[1]];
            if in_box(b, q) {
                return fg.at(q[0], q[1]);
            }
        }
        let q = motion.inverse(c, p);
        bg.at(q[0], q[1])
    });
    let mut flow = vec![[0.0_f32; 2]; w * h];
    let mut visible = vec![true; w * h];
    for y in 0..h {
        for x in 0..w {
            let p = [x as f64, y as f64];
            let i = y * w + x;
            let (q, on_box) = match &moving_box {
                Some(b) if in_box(b, p) => (
                    [p[0] + b.translation_px[0], p[1] + b.translation_px[1]],
                    true,
                ),
                _ => (motion.apply(c, p), false),
            };
            flow[i] = [(q[0] - p[0]) as f32, (q[1] - p[1]) as f32];
            let inside =
                q[0] >= 0.0 && q[1] >= 0.0 && q[0] <= (w - 1) as f64 && q[1] <= (h - 1) as f64;
            // background points hidden by the box in image 2 are occluded
            let occluded = !on_box
                && moving_box.is_some_and(|b| {
                    in_box(&b, [q[0] - b.translation_px[0], q[1] - b.translation_px[1]])
                });
            visible[i] = inside && !occluded;
        }
    }
    SyntheticPair {
        image1,
        image2,
        flow,
        visible,
    }
}

/// Mean end-point error of `flow` against the pair's ground truth over visible pixels at least
/// `margin` px from the border.
#[must_use]
pub fn mean_epe(pair: &SyntheticPair, flow: &[[f32; 2]], margin: usize) -> f64 {
    let (w, h) = (pair.image1.width(), pair.image1.height());
    let mut sum = 0.0;
    let mut n = 0_usize;
    for y in margin..h.saturating_sub(margin) {
        for x in margin..w.saturating_sub(margin) {
            let i = y * w + x;
            if pair.visible[i] {
                let e = [flow[i][0] - pair.flow[i][0], flow[i][1] - pair.flow[i][1]];
                sum += f64::from(e[0].hypot(e[1]));
                n += 1;
            }
        }
    }
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// A small deterministic generator of uniform numbers in `[0, 1)`.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((self.0 >> 11) as f64) / ((1_u64 << 53) as f64)
    }

    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

/// A `w` x `h` pair drawn from `seed` for calibrating the uncertainty model: a global motion of
/// up to ±16 x ±9 px, ±2 degrees and ±5 % zoom; zero to three overlapping boxes with their own
/// motion of up to ±12 px (occlusion boundaries, independently moving objects); flat patches
/// and shading on every surface in half the pairs; then, on image 2, a gain of ±10 %, an offset
/// of ±8 levels and a left-to-right illumination ramp of ±10 levels, in a third of the pairs a
/// 3x3 blur, and on both images sensor noise of 1 to 4 levels (uniform).
#[must_use]
pub fn varied_pair(w: usize, h: usize, seed: u64) -> SyntheticPair {
    let mut r = Lcg(seed.wrapping_mul(0x2545_f491_4f6c_dd1d).wrapping_add(7));
    r.next();
    let (wf, hf) = (w as f64, h as f64);
    let motion = Motion {
        translation_px: [r.range(-16.0, 16.0), r.range(-9.0, 9.0)],
        angle_rad: r.range(-0.035, 0.035),
        zoom: r.range(0.95, 1.05),
    };
    let n_boxes = (r.next() * 4.0) as usize;
    let boxes: Vec<MovingBox> = (0..n_boxes)
        .map(|_| {
            let (bw, bh) = (r.range(0.12, 0.4) * wf, r.range(0.15, 0.45) * hf);
            let (x0, y0) = (r.range(0.0, wf - bw), r.range(0.0, hf - bh));
            MovingBox {
                rect_px: [x0, y0, x0 + bw, y0 + bh],
                translation_px: [r.range(-12.0, 12.0), r.range(-8.0, 8.0)],
            }
        })
        .collect();
    let look = if r.next() < 0.5 {
        Appearance::default()
    } else {
        Appearance {
            min_contrast: r.range(0.02, 0.3),
            shading: r.range(0.0, 40.0),
            period_px: r.range(50.0, 150.0),
        }
    };
    let mut pair = render_scene(w, h, seed, motion, &boxes, look);
    let gain = r.range(0.9, 1.1);
    let offset = r.range(-8.0, 8.0);
    let ramp = r.range(-10.0, 10.0);
    let blur = r.next() < 1.0 / 3.0;
    let noise = r.range(1.0, 4.0);
    let mut img2 = pair.image2.clone();
    if blur {
        img2 = visnav_core::GrayImage::from_fn(w, h, |x, y| {
            let mut acc = 0.0;
            for dy in -1..=1 {
                for dx in -1..=1 {
                    acc += pair.image2.get_clamped(x as isize + dx, y as isize + dy);
                }
            }
            acc / 9.0
        });
    }
    let mut n = Lcg(seed ^ 0xdead_beef);
    for (i, v) in img2.data_mut().iter_mut().enumerate() {
        let x = (i % w) as f64 / wf - 0.5;
        let u = n.next() - 0.5;
        *v = ((f64::from(*v) * gain + offset + 2.0 * ramp * x + 2.0 * noise * u) as f32)
            .clamp(0.0, 255.0);
    }
    for v in pair.image1.data_mut() {
        let u = n.next() - 0.5;
        *v = ((f64::from(*v) + 2.0 * noise * u) as f32).clamp(0.0, 255.0);
    }
    pair.image2 = img2;
    pair
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn render_scene_with_one_plain_box_is_render_pair() {
        let motion = Motion {
            translation_px: [2.5, -1.0],
            angle_rad: 0.01,
            zoom: 1.02,
        };
        let b = MovingBox {
            rect_px: [20.0, 10.0, 50.0, 40.0],
            translation_px: [-4.0, 3.0],
        };
        let a = render_pair(80, 60, 3, motion, Some(b));
        let s = render_scene(80, 60, 3, motion, &[b], Appearance::default());
        assert_eq!(a.image1, s.image1);
        assert_eq!(a.image2, s.image2);
        assert_eq!(a.flow, s.flow);
        assert_eq!(a.visible, s.visible);
    }

    #[test]
    fn overlapping_boxes_occlude_and_contrast_varies() {
        let motion = Motion {
            translation_px: [0.0, 0.0],
            angle_rad: 0.0,
            zoom: 1.0,
        };
        // box 1 moves onto box 0, which stands still
        let boxes = [
            MovingBox {
                rect_px: [10.0, 10.0, 40.0, 40.0],
                translation_px: [0.0, 0.0],
            },
            MovingBox {
                rect_px: [50.0, 10.0, 70.0, 40.0],
                translation_px: [-20.0, 0.0],
            },
        ];
        let look = Appearance {
            min_contrast: 0.02,
            shading: 20.0,
            period_px: 60.0,
        };
        let p = render_scene(80, 60, 5, motion, &boxes, look);
        let i = |x: usize, y: usize| y * 80 + x;
        // box 0 at x 35 is covered by box 1 (now at 30..50) in image 2; at x 15 it is not
        assert!(!p.visible[i(35, 20)] && p.visible[i(15, 20)]);
        assert!(p.visible[i(60, 20)]);
        assert_eq!(p.flow[i(60, 20)], [-20.0, 0.0]);
        // background revealed by box 1 stays visible (its target is itself)
        assert!(p.visible[i(5, 50)]);
        // the contrast field lowers the texture: fewer 7x7 patches span 60 levels or more
        let plain = render_scene(80, 60, 5, motion, &boxes, Appearance::default());
        let textured = |img: &visnav_core::GrayImage| {
            (3..57)
                .step_by(7)
                .flat_map(|y| (3..77).step_by(7).map(move |x| (x, y)))
                .filter(|&(x, y)| {
                    let v: Vec<f32> = (0..7)
                        .flat_map(|dy| (0..7).map(move |dx| (dx, dy)))
                        .map(|(dx, dy)| img.get(x + dx - 3, y + dy - 3))
                        .collect();
                    let lo = v.iter().copied().fold(f32::INFINITY, f32::min);
                    let hi = v.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                    hi - lo >= 60.0
                })
                .count()
        };
        assert!(textured(&p.image1) < textured(&plain.image1));
    }

    #[test]
    fn varied_pairs_are_deterministic_and_differ_by_seed() {
        let a = varied_pair(64, 48, 7);
        let b = varied_pair(64, 48, 7);
        let c = varied_pair(64, 48, 8);
        assert_eq!(a.image2, b.image2);
        assert_ne!(a.image2, c.image2);
        assert!(a.visible.iter().any(|v| *v));
        assert!(a.image2.data().iter().all(|v| (0.0..=255.0).contains(v)));
    }
}
