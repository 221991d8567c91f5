//! Proof of CPU features, and the scope non-temporal stores are issued in.
//!
//! A SIMD kernel (a `#[target_feature]` function) is only sound to call where the CPU has
//! its features. Rather than trusting every caller to have checked, each kernel is reached
//! through a token of this module: a zero-sized value with a private field, so the only
//! way to get one is its `detect`, which checks the features first. Code holding a token
//! may call the kernels of its features, and its `unsafe` blocks say so. No safe code can
//! make a token on a CPU that lacks the features.
//!
//! Non-temporal stores (`_mm_stream_*`, `_mm512_stream_*`) are weakly ordered: the thread
//! that issued them must fence (`_mm_sfence`) before anything else touches the memory
//! they wrote, or even a later release (rayon's join) does not publish them. Functions
//! that stream take a `NonTemporal` (crate-private), which only the scope `non_temporal`
//! lends, and that scope ends with the fence, on the same thread.

use std::marker::PhantomData;

/// Proof that this CPU has AVX-512F, and with it AVX2 and FMA (every CPU with AVX-512F has
/// them; they are checked anyway, so kernels that also enable them may rely on the token).
/// Only [`Avx512F::detect`] makes one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Avx512F(());

impl Avx512F {
    /// The token, if this CPU has the features.
    pub fn detect() -> Option<Avx512F> {
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx512f")
            && is_x86_feature_detected!("avx2")
            && is_x86_feature_detected!("fma")
        {
            return Some(Avx512F(()));
        }
        None
    }
}

/// Proof that this CPU has AVX2 and FMA. Only [`Avx2Fma::detect`] makes one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Avx2Fma(());

impl Avx2Fma {
    /// The token, if this CPU has the features.
    pub fn detect() -> Option<Avx2Fma> {
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
            return Some(Avx2Fma(()));
        }
        None
    }
}

/// Permission to issue non-temporal stores: proof that the code runs inside a
/// [`non_temporal`] scope, which fences on this thread before it returns. Neither `Send`
/// nor `Sync` (an `sfence` orders only its own thread's stores), and only lent by
/// reference, so it cannot leave the scope or its thread.
///
/// Functions that stream take one, and leave the bytes they streamed alone until the scope
/// ends (nothing in the scope reads or writes them again: each strip's output bytes are
/// written once).
pub(crate) struct NonTemporal {
    _thread_bound: PhantomData<*mut ()>,
}

/// Runs `f` with permission to issue non-temporal stores, then orders them: the fence is
/// issued before this returns, also when `f` panics. One scope per rayon task: a fence per
/// store would cost more than the stores save, and a fence per task costs nothing that
/// measures.
pub(crate) fn non_temporal<R>(f: impl FnOnce(&NonTemporal) -> R) -> R {
    /// Fences when dropped: at the end of the scope, however it ends.
    struct Fence;
    impl Drop for Fence {
        fn drop(&mut self) {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: SSE is baseline on x86-64; the fence has no memory-safety
            // preconditions.
            unsafe {
                std::arch::x86_64::_mm_sfence()
            };
        }
    }
    let _fence = Fence;
    f(&NonTemporal {
        _thread_bound: PhantomData,
    })
}
