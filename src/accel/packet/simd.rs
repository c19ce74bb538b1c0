//! The vector operations the packet traversal is written in, for AVX-512 (sixteen rays a
//! packet) and AVX2 (eight): one trait, so that the traversal is one source for both widths.
//!
//! Each operation is one instruction (or, where AVX2 has none, the shortest exact sequence) of
//! the same IEEE semantics on both ISAs: `max` and `min` take their second operand where
//! either is NaN, as `maxps` and `minps` do, and compares are the ordered, quiet ones. So both
//! widths compute each lane's values with the same operations, and the same bits.
//!
//! A lane mask (`Simd::K`) is an AVX-512 mask register (a bit a lane), or for AVX2 a vector
//! whose lanes' sign bits are the flags (what `vblendvps` and `vmovmskps` read; compares set
//! every bit of a lane). Control flow reads masks as bits (`Simd::bits`), a `u32` whose bit i
//! is lane i.

use std::arch::x86_64::*;

/// The vector operations of one ISA at its width. Every method is `unsafe`: it must only be
/// called from code compiled with the ISA's target features (`FEATURES`), on a CPU that has
/// them, where it is inlined.
pub(crate) trait Simd: Copy {
    /// Rays in a packet: lanes a vector.
    const WIDTH: usize;
    /// f32 lanes.
    type V: Copy;
    /// u32 lanes.
    type U: Copy;
    /// A flag a lane.
    type K: Copy;

    /// Lanes `0..WIDTH` of `p`.
    unsafe fn load(p: &[f32; 16]) -> Self::V;
    /// Into lanes `0..WIDTH` of `p`.
    unsafe fn store(p: &mut [f32; 16], v: Self::V);
    unsafe fn splat(x: f32) -> Self::V;
    unsafe fn zero() -> Self::V;
    unsafe fn add(a: Self::V, b: Self::V) -> Self::V;
    unsafe fn sub(a: Self::V, b: Self::V) -> Self::V;
    unsafe fn mul(a: Self::V, b: Self::V) -> Self::V;
    unsafe fn div(a: Self::V, b: Self::V) -> Self::V;
    /// `maxps`: `b` where either is NaN.
    unsafe fn max(a: Self::V, b: Self::V) -> Self::V;
    /// `minps`: `b` where either is NaN.
    unsafe fn min(a: Self::V, b: Self::V) -> Self::V;
    unsafe fn abs(a: Self::V) -> Self::V;
    unsafe fn and(a: Self::V, b: Self::V) -> Self::V;
    unsafe fn or(a: Self::V, b: Self::V) -> Self::V;
    unsafe fn xor(a: Self::V, b: Self::V) -> Self::V;
    unsafe fn eq(a: Self::V, b: Self::V) -> Self::K;
    unsafe fn ne(a: Self::V, b: Self::V) -> Self::K;
    unsafe fn lt(a: Self::V, b: Self::V) -> Self::K;
    unsafe fn le(a: Self::V, b: Self::V) -> Self::K;
    unsafe fn gt(a: Self::V, b: Self::V) -> Self::K;
    /// The lanes whose sign bit is set (negative numbers, -0.0 and NaNs with the bit).
    unsafe fn sign(a: Self::V) -> Self::K;
    /// `if k { b } else { a }`, lane by lane (`_mm512_mask_blend_ps`'s order).
    unsafe fn blend(k: Self::K, a: Self::V, b: Self::V) -> Self::V;
    /// The smallest of the lanes `k` sets (+inf if none).
    unsafe fn reduce_min(k: Self::K, a: Self::V) -> f32;

    unsafe fn and_k(a: Self::K, b: Self::K) -> Self::K;
    unsafe fn or_k(a: Self::K, b: Self::K) -> Self::K;
    /// `a & !b`.
    unsafe fn and_not_k(a: Self::K, b: Self::K) -> Self::K;
    /// Bit i set for lane i set (bits `WIDTH..` clear).
    unsafe fn bits(k: Self::K) -> u32;
    /// The mask of bits `0..WIDTH` of `bits`.
    unsafe fn from_bits(bits: u32) -> Self::K;

    /// Lanes `0..WIDTH` of `p`.
    unsafe fn load_u(p: &[u32; 16]) -> Self::U;
    /// Into lanes `0..WIDTH` of `p`.
    unsafe fn store_u(p: &mut [u32; 16], v: Self::U);
    unsafe fn splat_u(x: u32) -> Self::U;
    /// `a < b` as unsigned numbers.
    unsafe fn lt_u(a: Self::U, b: Self::U) -> Self::K;
    unsafe fn ne_u(a: Self::U, b: Self::U) -> Self::K;
    /// `if k { b } else { a }`, lane by lane.
    unsafe fn blend_u(k: Self::K, a: Self::U, b: Self::U) -> Self::U;
}

/// Sixteen lanes of AVX-512 (F, DQ, VL, BW, with AVX2 and FMA: `crate::cpu::has_avx512`).
#[derive(Clone, Copy)]
pub(crate) struct Avx512;

/// Eight lanes of AVX2 (with FMA: `crate::cpu::has_avx2_fma`). On AVX2 only coherent rays are
/// traced with it (`trace_coherent_closest`, `trace_coherent_shadow`): eight-ray packets lose
/// to single rays on the later bounces (docs/measurements/2026-12-02-avx2-packets.md).
#[derive(Clone, Copy)]
pub(crate) struct Avx2;

// SAFETY (both impls): each method is a sequence of intrinsics of its ISA's target features,
// which the trait's contract makes the caller's to guarantee; loads and stores are unaligned
// ones of at most sixteen lanes from and to arrays of sixteen.
impl Simd for Avx512 {
    const WIDTH: usize = 16;
    type V = __m512;
    type U = __m512i;
    type K = u16;

    #[inline(always)]
    unsafe fn load(p: &[f32; 16]) -> __m512 {
        unsafe { _mm512_loadu_ps(p.as_ptr()) }
    }
    #[inline(always)]
    unsafe fn store(p: &mut [f32; 16], v: __m512) {
        unsafe { _mm512_storeu_ps(p.as_mut_ptr(), v) }
    }
    #[inline(always)]
    unsafe fn splat(x: f32) -> __m512 {
        unsafe { _mm512_set1_ps(x) }
    }
    #[inline(always)]
    unsafe fn zero() -> __m512 {
        unsafe { _mm512_setzero_ps() }
    }
    #[inline(always)]
    unsafe fn add(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_add_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn sub(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_sub_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn mul(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_mul_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn div(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_div_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn max(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_max_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn min(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_min_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn abs(a: __m512) -> __m512 {
        unsafe { _mm512_abs_ps(a) }
    }
    #[inline(always)]
    unsafe fn and(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_and_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn or(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_or_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn xor(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_xor_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn eq(a: __m512, b: __m512) -> u16 {
        unsafe { _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn ne(a: __m512, b: __m512) -> u16 {
        unsafe { _mm512_cmp_ps_mask::<_CMP_NEQ_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn lt(a: __m512, b: __m512) -> u16 {
        unsafe { _mm512_cmp_ps_mask::<_CMP_LT_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn le(a: __m512, b: __m512) -> u16 {
        unsafe { _mm512_cmp_ps_mask::<_CMP_LE_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn gt(a: __m512, b: __m512) -> u16 {
        unsafe { _mm512_cmp_ps_mask::<_CMP_GT_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn sign(a: __m512) -> u16 {
        unsafe { _mm512_movepi32_mask(_mm512_castps_si512(a)) }
    }
    #[inline(always)]
    unsafe fn blend(k: u16, a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_mask_blend_ps(k, a, b) }
    }
    #[inline(always)]
    unsafe fn reduce_min(k: u16, a: __m512) -> f32 {
        unsafe { _mm512_mask_reduce_min_ps(k, a) }
    }
    #[inline(always)]
    unsafe fn and_k(a: u16, b: u16) -> u16 {
        a & b
    }
    #[inline(always)]
    unsafe fn or_k(a: u16, b: u16) -> u16 {
        a | b
    }
    #[inline(always)]
    unsafe fn and_not_k(a: u16, b: u16) -> u16 {
        a & !b
    }
    #[inline(always)]
    unsafe fn bits(k: u16) -> u32 {
        u32::from(k)
    }
    #[inline(always)]
    unsafe fn from_bits(bits: u32) -> u16 {
        bits as u16
    }
    #[inline(always)]
    unsafe fn load_u(p: &[u32; 16]) -> __m512i {
        unsafe { _mm512_loadu_si512(p.as_ptr().cast()) }
    }
    #[inline(always)]
    unsafe fn store_u(p: &mut [u32; 16], v: __m512i) {
        unsafe { _mm512_storeu_si512(p.as_mut_ptr().cast(), v) }
    }
    #[inline(always)]
    unsafe fn splat_u(x: u32) -> __m512i {
        unsafe { _mm512_set1_epi32(x as i32) }
    }
    #[inline(always)]
    unsafe fn lt_u(a: __m512i, b: __m512i) -> u16 {
        unsafe { _mm512_cmplt_epu32_mask(a, b) }
    }
    #[inline(always)]
    unsafe fn ne_u(a: __m512i, b: __m512i) -> u16 {
        unsafe { _mm512_cmpneq_epu32_mask(a, b) }
    }
    #[inline(always)]
    unsafe fn blend_u(k: u16, a: __m512i, b: __m512i) -> __m512i {
        unsafe { _mm512_mask_mov_epi32(a, k, b) }
    }
}

impl Simd for Avx2 {
    const WIDTH: usize = 8;
    type V = __m256;
    type U = __m256i;
    type K = __m256;

    #[inline(always)]
    unsafe fn load(p: &[f32; 16]) -> __m256 {
        unsafe { _mm256_loadu_ps(p.as_ptr()) }
    }
    #[inline(always)]
    unsafe fn store(p: &mut [f32; 16], v: __m256) {
        unsafe { _mm256_storeu_ps(p.as_mut_ptr(), v) }
    }
    #[inline(always)]
    unsafe fn splat(x: f32) -> __m256 {
        unsafe { _mm256_set1_ps(x) }
    }
    #[inline(always)]
    unsafe fn zero() -> __m256 {
        unsafe { _mm256_setzero_ps() }
    }
    #[inline(always)]
    unsafe fn add(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_add_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn sub(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_sub_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn mul(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_mul_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn div(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_div_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn max(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_max_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn min(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_min_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn abs(a: __m256) -> __m256 {
        unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), a) }
    }
    #[inline(always)]
    unsafe fn and(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_and_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn or(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_or_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn xor(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_xor_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn eq(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_cmp_ps::<_CMP_EQ_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn ne(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_cmp_ps::<_CMP_NEQ_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn lt(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_cmp_ps::<_CMP_LT_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn le(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_cmp_ps::<_CMP_LE_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn gt(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_cmp_ps::<_CMP_GT_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn sign(a: __m256) -> __m256 {
        // The flags are the sign bits themselves.
        a
    }
    #[inline(always)]
    unsafe fn blend(k: __m256, a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_blendv_ps(a, b, k) }
    }
    #[inline(always)]
    unsafe fn reduce_min(k: __m256, a: __m256) -> f32 {
        unsafe {
            let v = _mm256_blendv_ps(_mm256_set1_ps(f32::INFINITY), a, k);
            let v = _mm_min_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
            let v = _mm_min_ps(v, _mm_movehl_ps(v, v));
            let v = _mm_min_ss(v, _mm_shuffle_ps::<0b01>(v, v));
            _mm_cvtss_f32(v)
        }
    }
    #[inline(always)]
    unsafe fn and_k(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_and_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn or_k(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_or_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn and_not_k(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_andnot_ps(b, a) }
    }
    #[inline(always)]
    unsafe fn bits(k: __m256) -> u32 {
        unsafe { _mm256_movemask_ps(k) as u32 }
    }
    #[inline(always)]
    unsafe fn from_bits(bits: u32) -> __m256 {
        unsafe {
            // Lane i keeps bit i of `bits`, moved to its sign bit.
            let shift = _mm256_setr_epi32(31, 30, 29, 28, 27, 26, 25, 24);
            _mm256_castsi256_ps(_mm256_sllv_epi32(_mm256_set1_epi32(bits as i32), shift))
        }
    }
    #[inline(always)]
    unsafe fn load_u(p: &[u32; 16]) -> __m256i {
        unsafe { _mm256_loadu_si256(p.as_ptr().cast()) }
    }
    #[inline(always)]
    unsafe fn store_u(p: &mut [u32; 16], v: __m256i) {
        unsafe { _mm256_storeu_si256(p.as_mut_ptr().cast(), v) }
    }
    #[inline(always)]
    unsafe fn splat_u(x: u32) -> __m256i {
        unsafe { _mm256_set1_epi32(x as i32) }
    }
    #[inline(always)]
    unsafe fn lt_u(a: __m256i, b: __m256i) -> __m256 {
        unsafe {
            // Unsigned order is signed order with the sign bits flipped.
            let flip = _mm256_set1_epi32(i32::MIN);
            let (a, b) = (_mm256_xor_si256(a, flip), _mm256_xor_si256(b, flip));
            _mm256_castsi256_ps(_mm256_cmpgt_epi32(b, a))
        }
    }
    #[inline(always)]
    unsafe fn ne_u(a: __m256i, b: __m256i) -> __m256 {
        unsafe {
            let eq = _mm256_cmpeq_epi32(a, b);
            _mm256_castsi256_ps(_mm256_xor_si256(eq, _mm256_set1_epi32(-1)))
        }
    }
    #[inline(always)]
    unsafe fn blend_u(k: __m256, a: __m256i, b: __m256i) -> __m256i {
        unsafe {
            _mm256_castps_si256(_mm256_blendv_ps(
                _mm256_castsi256_ps(a),
                _mm256_castsi256_ps(b),
                k,
            ))
        }
    }
}
