//! Synthetic image pairs with exact ground-truth flow, for tests, calibration and benchmarks:
//! a procedural texture (a seeded sum of sinusoids with periods 5 to 60 px) seen under a known
//! motion of the whole image (translation, rotation, zoom) and optionally a box moving on top.

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
