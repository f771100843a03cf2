//! Run-time selection of AVX2 code paths for the hot loops (triangular solves here, femu-mech's
//! element loop).
//!
//! The release build targets baseline x86-64 (SSE2) so that the binary runs on any x86-64 CPU;
//! a loop wrapped in [`with_avx2`] is compiled a second time with AVX2 enabled and that copy
//! runs when the CPU has it (checked once, cached by the standard library). No floating-point
//! contraction is enabled (AVX2 alone brings no FMA) and LLVM does not reassociate without
//! fast-math flags, so both copies give the same results to the bit; only the vector width
//! differs.

/// Whether the CPU running this process supports AVX2.
#[inline]
pub fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Runs `f`, compiled with AVX2 enabled when the CPU has it. For the AVX2 copy to contain the
/// loop, `f` must be a closure marked `#[inline(always)]` whose callees inline into it.
///
/// Safe to call from any crate: it is generic, so both copies are compiled in the caller's
/// crate (the closure inlines into each), and the unsafe call is guarded by the feature check.
#[inline(always)]
#[allow(unsafe_code)] // the one AVX2 call, guarded; see the SAFETY note
pub fn with_avx2<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if has_avx2() {
        // SAFETY: the CPU has AVX2, checked just above.
        return unsafe { call_avx2(f) };
    }
    f()
}

/// Calls `f` inside a function compiled for AVX2.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(unsafe_code)] // `target_feature` functions are unsafe to call before Rust 1.86
unsafe fn call_avx2<R>(f: impl FnOnce() -> R) -> R {
    f()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_copies_sum_to_the_same_bits() {
        // A reduction whose result depends on the order of the additions: the AVX2 copy
        // must not reorder them.
        let v: Vec<f64> = (0..1000)
            .map(|i| (i as f64 * 0.37).sin() * 10f64.powi(i % 7))
            .collect();
        let sum = |v: &[f64]| v.iter().fold(0.0, |s, x| s + x);
        let portable = sum(&v);
        let dispatched = with_avx2(
            #[inline(always)]
            || sum(&v),
        );
        assert_eq!(portable.to_bits(), dispatched.to_bits());
    }
}
