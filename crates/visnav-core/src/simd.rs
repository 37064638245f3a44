//! Run-time selection of wider SIMD for the hot numeric kernels.
//!
//! The build targets baseline x86-64 (SSE2), so a binary runs on any x86-64 CPU. The kernels the
//! dense flow spends its time in (variational sweeps, descriptor dot products, semi-global
//! matching, box filters) are plain loops the compiler auto-vectorises; `simd_kernel!`
//! compiles such a function twice, once as usual and once with AVX2 and FMA enabled, and picks
//! the second at run time when the CPU has both.
//!
//! The two versions compute **the same result bit for bit**: Rust never contracts `a * b + c`
//! into a fused multiply–add on its own and does not reorder floating-point sums, so enabling
//! the features only widens the vectors the same operations run on (checked by the unit test
//! below and, end to end, by identical KITTI trajectories; the speed-up is in
//! `docs/notes/2026-12-02-mono-history.md`, settled decisions (mono), AVX2).

/// Whether the AVX2 + FMA versions of the kernels run: the CPU has both, and the environment
/// variable `VISNAV_PORTABLE_SIMD` is not set (set it to compare the two paths, or to rule the
/// wide path out when chasing a problem). Decided once per process. Always `false` off x86-64.
#[must_use]
#[inline]
pub fn has_avx2_fma() -> bool {
    static WIDE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *WIDE.get_or_init(|| {
        #[cfg(target_arch = "x86_64")]
        {
            std::env::var_os("VISNAV_PORTABLE_SIMD").is_none()
                && std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            false
        }
    })
}

/// Defines a function whose body is compiled twice, for baseline x86-64 and for AVX2 + FMA,
/// and which runs the AVX2 version when [`has_avx2_fma`] says the CPU supports it. Arguments
/// are `name: Type` pairs (no patterns, no generics); the body must not use `return` to leave
/// early from a loop it means to continue (it is an ordinary function body).
///
/// ```
/// visnav_core::simd_kernel! {
///     /// Sum of products.
///     pub fn dot(a: &[f32], b: &[f32]) -> f32 {
///         a.iter().zip(b).map(|(x, y)| x * y).sum()
///     }
/// }
/// assert_eq!(dot(&[1.0, 2.0], &[3.0, 4.0]), 11.0);
/// ```
#[macro_export]
macro_rules! simd_kernel {
    (
        $(#[$meta:meta])*
        $vis:vis fn $name:ident($($arg:ident : $ty:ty),* $(,)?) $(-> $ret:ty)? $body:block
    ) => {
        $(#[$meta])*
        #[allow(unsafe_code, clippy::too_many_arguments)]
        $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[inline(always)]
            #[allow(clippy::too_many_arguments)]
            fn portable($($arg: $ty),*) $(-> $ret)? $body
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2,fma")]
                #[allow(clippy::too_many_arguments)]
                fn wide($($arg: $ty),*) $(-> $ret)? {
                    portable($($arg),*)
                }
                if $crate::simd::has_avx2_fma() {
                    // SAFETY: `wide` only differs from `portable` by being compiled for AVX2 and
                    // FMA, and the check above has just confirmed that this CPU executes both
                    // instruction sets, which is the one requirement of calling a
                    // `#[target_feature]` function.
                    return unsafe { wide($($arg),*) };
                }
            }
            portable($($arg),*)
        }
    };
}

#[cfg(test)]
mod tests {
    crate::simd_kernel! {
        /// A reduction with eight lanes, as the descriptor cost does it.
        fn lanes_dot(a: &[f32], b: &[f32]) -> f32 {
            let mut acc = [0.0_f32; 8];
            for (ca, cb) in a.chunks_exact(8).zip(b.chunks_exact(8)) {
                for k in 0..8 {
                    acc[k] += ca[k] * cb[k];
                }
            }
            acc.iter().sum()
        }
    }

    crate::simd_kernel! {
        /// A multiply–add the compiler must not fuse.
        fn axpy(out: &mut [f32], a: f32, x: &[f32], y: &[f32]) {
            for ((o, x), y) in out.iter_mut().zip(x).zip(y) {
                *o = a * x + y;
            }
        }
    }

    #[test]
    fn wide_and_portable_versions_agree_bit_for_bit() {
        let a: Vec<f32> = (0..1003)
            .map(|i| ((i * 37) % 101) as f32 * 0.013 - 0.6)
            .collect();
        let b: Vec<f32> = (0..1003)
            .map(|i| ((i * 53) % 97) as f32 * 0.021 - 1.1)
            .collect();
        let reference = {
            let mut acc = [0.0_f32; 8];
            for (ca, cb) in a.chunks_exact(8).zip(b.chunks_exact(8)) {
                for k in 0..8 {
                    acc[k] += ca[k] * cb[k];
                }
            }
            acc.iter().sum::<f32>()
        };
        assert_eq!(lanes_dot(&a, &b).to_bits(), reference.to_bits());
        let mut out = vec![0.0_f32; a.len()];
        axpy(&mut out, 1.000_000_1, &a, &b);
        for ((o, x), y) in out.iter().zip(&a).zip(&b) {
            // rounded twice (product, then sum), as without FMA
            let expected = std::hint::black_box(1.000_000_1_f32 * x) + y;
            assert_eq!(o.to_bits(), expected.to_bits());
        }
    }
}
