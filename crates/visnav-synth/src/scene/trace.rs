//! Ray casting through the [`Scene`]: the ground plane, then the objects of the grid cells the
//! ray crosses (boxes and cylinders, slab and quadric tests in f64); the nearest hit wins.

use nalgebra::Vector3;

use super::{Hit, Scene, Shape, Surface};

impl Scene {
    /// Casts the ray `origin + t * dir` (t >= 0) and returns the nearest hit within the
    /// maximum distance, or `None` for the sky.
    pub(crate) fn trace(&self, origin: &Vector3<f64>, dir: &Vector3<f64>) -> Option<Hit> {
        let dir_norm = dir.norm();
        let mut t_max = self.config.max_distance_m / dir_norm;
        let g = &self.ground;
        let mut ground_hit = None;
        // height above the ground (unnormalised) at the origin and its rate along the ray
        let above = g.a * origin.x + g.b * origin.z + g.k - origin.y;
        let rate = g.a * dir.x + g.b * dir.z - dir.y;
        if above > 0.0 && rate < 0.0 {
            let t = -above / rate;
            if t < t_max {
                t_max = t;
                ground_hit = Some(t);
            }
        }
        let mut t_min = 0.0f64;
        // vertical slab that holds all objects
        if dir.y < 0.0 {
            t_max = t_max.min((self.y_top_min - origin.y) / dir.y);
        } else if origin.y < self.y_top_min {
            if dir.y <= 0.0 {
                t_max = -1.0;
            } else {
                t_min = (self.y_top_min - origin.y) / dir.y;
            }
        }
        let mut best: Option<Hit> = None;
        if t_min < t_max {
            best = self.trace_objects(origin, dir, t_min, t_max);
        }
        match (best, ground_hit) {
            (Some(h), _) => Some(h),
            (None, Some(t)) => Some(Hit {
                t,
                normal: g.normal_up(),
                surface: Surface::Ground {
                    x: origin.x + t * dir.x,
                    z: origin.z + t * dir.z,
                },
            }),
            (None, None) => None,
        }
    }

    /// 2-D DDA through the object grid between `t_min` and `t_max`.
    fn trace_objects(
        &self,
        origin: &Vector3<f64>,
        dir: &Vector3<f64>,
        t_min: f64,
        t_max: f64,
    ) -> Option<Hit> {
        let g = &self.object_grid;
        // clip to the grid rectangle
        let mut t0 = t_min;
        let mut t1 = t_max;
        for (o, d, lo, hi) in [
            (origin.x, dir.x, g.x0, g.x1()),
            (origin.z, dir.z, g.z0, g.z1()),
        ] {
            if d.abs() < 1e-15 {
                if o < lo || o >= hi {
                    return None;
                }
            } else {
                let ta = (lo - o) / d;
                let tb = (hi - o) / d;
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
        }
        if t0 >= t1 {
            return None;
        }
        let px = origin.x + t0 * dir.x;
        let pz = origin.z + t0 * dir.z;
        let (mut ix, mut iz) = g.cell_clamped(px, pz);
        let step_x: isize = if dir.x > 0.0 { 1 } else { -1 };
        let step_z: isize = if dir.z > 0.0 { 1 } else { -1 };
        let next_boundary = |i: usize, step: isize, lo: f64| -> f64 {
            lo + (i as f64 + if step > 0 { 1.0 } else { 0.0 }) * g.cell_m
        };
        let mut t_next_x = if dir.x.abs() < 1e-15 {
            f64::INFINITY
        } else {
            (next_boundary(ix, step_x, g.x0) - origin.x) / dir.x
        };
        let mut t_next_z = if dir.z.abs() < 1e-15 {
            f64::INFINITY
        } else {
            (next_boundary(iz, step_z, g.z0) - origin.z) / dir.z
        };
        let dt_x = if dir.x.abs() < 1e-15 {
            f64::INFINITY
        } else {
            g.cell_m / dir.x.abs()
        };
        let dt_z = if dir.z.abs() < 1e-15 {
            f64::INFINITY
        } else {
            g.cell_m / dir.z.abs()
        };
        let mut best: Option<Hit> = None;
        let mut best_t = t1;
        loop {
            for &oi in g.cell_items(ix, iz) {
                if let Some(h) = self.intersect(oi, origin, dir, best_t) {
                    best_t = h.t;
                    best = Some(h);
                }
            }
            let t_exit = t_next_x.min(t_next_z);
            if best_t <= t_exit || t_exit >= t1 {
                break;
            }
            if t_next_x < t_next_z {
                let n = ix as isize + step_x;
                if n < 0 || n >= g.nx as isize {
                    break;
                }
                ix = n as usize;
                t_next_x += dt_x;
            } else {
                let n = iz as isize + step_z;
                if n < 0 || n >= g.nz as isize {
                    break;
                }
                iz = n as usize;
                t_next_z += dt_z;
            }
        }
        best
    }

    /// Nearest intersection of the ray with object `oi` closer than `t_best`.
    #[inline]
    fn intersect(
        &self,
        oi: u32,
        origin: &Vector3<f64>,
        dir: &Vector3<f64>,
        t_best: f64,
    ) -> Option<Hit> {
        match self.objects[oi as usize].shape {
            Shape::Cuboid(c) => {
                let rx = origin.x - c.centre[0];
                let rz = origin.z - c.centre[1];
                let (au, az) = (c.axis_u[0], c.axis_u[1]);
                let o_u = rx * au + rz * az;
                let o_w = -rx * az + rz * au;
                let d_u = dir.x * au + dir.z * az;
                let d_w = -dir.x * az + dir.z * au;
                let mut t_enter = f64::NEG_INFINITY;
                let mut t_exit = f64::INFINITY;
                let mut axis = 0usize;
                let mut sign = 1.0f64;
                for (k, (o, d, lo, hi)) in [
                    (o_u, d_u, -c.half_u, c.half_u),
                    (o_w, d_w, -c.half_w, c.half_w),
                    (origin.y, dir.y, c.y_top, c.y_bottom),
                ]
                .into_iter()
                .enumerate()
                {
                    if d.abs() < 1e-15 {
                        if o < lo || o > hi {
                            return None;
                        }
                        continue;
                    }
                    let (ta, tb) = ((lo - o) / d, (hi - o) / d);
                    let (tn, tf, s) = if ta < tb {
                        (ta, tb, -1.0)
                    } else {
                        (tb, ta, 1.0)
                    };
                    if tn > t_enter {
                        t_enter = tn;
                        axis = k;
                        sign = s;
                    }
                    t_exit = t_exit.min(tf);
                }
                if !(t_enter <= t_exit && t_enter > 1e-9 && t_enter < t_best) {
                    return None;
                }
                let t = t_enter;
                let pu = o_u + t * d_u;
                let pw = o_w + t * d_w;
                let height = c.y_base - (origin.y + t * dir.y);
                let (normal, u, v, top) = match axis {
                    0 => (
                        Vector3::new(sign * au, 0.0, sign * az),
                        pw + c.half_w,
                        height,
                        false,
                    ),
                    1 => (
                        Vector3::new(-sign * az, 0.0, sign * au),
                        pu + c.half_u,
                        height,
                        false,
                    ),
                    _ => (Vector3::new(0.0, sign, 0.0), pu, pw, true),
                };
                Some(Hit {
                    t,
                    normal,
                    surface: Surface::Object {
                        index: oi,
                        u,
                        v,
                        top,
                        face: (2 * axis + usize::from(sign > 0.0)) as u8,
                    },
                })
            }
            Shape::Cylinder(c) => {
                let rx = origin.x - c.centre[0];
                let rz = origin.z - c.centre[1];
                let a = dir.x * dir.x + dir.z * dir.z;
                if a < 1e-18 {
                    return None;
                }
                let b = rx * dir.x + rz * dir.z;
                let cc = rx * rx + rz * rz - c.radius * c.radius;
                let disc = b * b - a * cc;
                if disc < 0.0 {
                    return None;
                }
                let t = (-b - disc.sqrt()) / a;
                if !(t > 1e-9 && t < t_best) {
                    return None;
                }
                let y = origin.y + t * dir.y;
                if y < c.y_top || y > c.y_bottom {
                    return None;
                }
                let nx = (rx + t * dir.x) / c.radius;
                let nz = (rz + t * dir.z) / c.radius;
                Some(Hit {
                    t,
                    normal: Vector3::new(nx, 0.0, nz),
                    surface: Surface::Object {
                        index: oi,
                        u: nz.atan2(nx) * c.radius,
                        v: c.y_base - y,
                        top: false,
                        face: 6,
                    },
                })
            }
        }
    }
}
