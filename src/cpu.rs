//! Code compiled for AVX2 and FMA, chosen at run time where the CPU has them.
//!
//! The hot loops (traversal, light sampling, scattering) run as copies compiled for AVX2: the
//! three-operand VEX forms spare most register copies, and traversal tests eight child boxes
//! per instruction. The compiler never contracts a separate multiply and add into a fused one,
//! so both copies compute the same bits; the FMA feature only comes with the AVX2 target
//! level. The baseline (SSE2) copy runs everywhere else.
//!
//! Also the hints the machine takes about memory: prefetches, and huge pages for the arrays
//! read at random all over hundreds of megabytes.

/// Whether the CPU has AVX2 and FMA (the standard library caches the answer).
#[inline]
pub fn has_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Whether the CPU has the AVX-512 subsets (F, DQ, VL, BW) that the systems' AVX-512 copies are
/// compiled for, with AVX2 and FMA: 32 vector registers, and 64-bit lane multiplies for the
/// sampler's hash. Asked of the CPU once, then one load: the lane kernels' vector loads and
/// stores ask it, where five feature tests out of line took 1.2% of a Cornell box render.
#[inline(always)]
pub fn has_avx512() -> bool {
    use std::sync::atomic::{AtomicU8, Ordering};
    /// 0: not asked yet; 1: no; 2: yes.
    static ANSWER: AtomicU8 = AtomicU8::new(0);
    match ANSWER.load(Ordering::Relaxed) {
        2 => true,
        1 => false,
        _ => {
            let yes = detect_avx512();
            ANSWER.store(1 + u8::from(yes), Ordering::Relaxed);
            yes
        }
    }
}

#[cold]
#[inline(never)]
fn detect_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        has_avx2_fma()
            && std::is_x86_feature_detected!("avx512f")
            && std::is_x86_feature_detected!("avx512dq")
            && std::is_x86_feature_detected!("avx512vl")
            && std::is_x86_feature_detected!("avx512bw")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Asks the CPU to bring the cache line holding `address` into the cache (nothing where the
/// target has no prefetch instruction). Any address will do: a prefetch never faults.
#[inline(always)]
pub fn prefetch<T>(address: *const T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        // SAFETY: a prefetch is a hint that never faults, whatever the address.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(address.cast::<i8>()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = address;
}

/// Asks the kernel to back the whole 2 MiB pages of `v`'s allocation (its capacity) with
/// transparent huge pages: traversal reads a tree's nodes and packets, and shading the triangle
/// columns, all over hundreds of megabytes, and with 4 KiB pages nearly every such read misses
/// the TLB. Only a hint: where the kernel refuses, nothing changes.
pub fn advise_huge_pages<T>(v: &Vec<T>) {
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        let start = v.as_ptr() as usize;
        let end = start + v.capacity() * std::mem::size_of::<T>();
        let (lo, hi) = (start.next_multiple_of(HUGE), end / HUGE * HUGE);
        if hi > lo {
            // SAFETY: madvise on whole pages inside `v`'s own allocation; MADV_HUGEPAGE only
            // changes how the kernel backs them, never their contents or their validity.
            unsafe { libc::madvise(lo as *mut libc::c_void, hi - lo, libc::MADV_HUGEPAGE) };
        }
    }
}
