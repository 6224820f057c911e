//! The widths of the packet traversal's lane-by-lane tests (`packet.rs`): eight rays to an AVX
//! vector, or sixteen to an AVX-512 one. Both run the same IEEE operations on each lane, in the
//! same order, so a ray gets the same bits at either width.
//!
//! The methods are `unsafe` and always inlined: they may only be called from code compiled
//! with the features of their width ([`Avx8`]: AVX and FMA; [`Avx16`]: AVX-512F as well),
//! where the intrinsics they call are then inlined too.

#![cfg(target_arch = "x86_64")]

use std::arch::x86_64::*;

/// One width of lane-by-lane tests: `N` lanes of f32 in a vector `V`, comparison results in a
/// mask `M`.
pub(crate) trait Lanes {
    /// Lanes per vector.
    const N: usize;
    /// A vector of `N` f32.
    type V: Copy;
    /// The lanes where a comparison held.
    type M: Copy;

    /// `N` f32 from `p`.
    ///
    /// # Safety
    /// `p` must point to `N` readable f32, and the CPU must have the width's features.
    unsafe fn load(p: *const f32) -> Self::V;
    /// Stores the lanes to `p`.
    ///
    /// # Safety
    /// `p` must point to `N` writable f32, and the CPU must have the width's features.
    unsafe fn store(p: *mut f32, v: Self::V);
    /// `x` in every lane.
    ///
    /// # Safety
    /// The CPU must have the width's features (as for every method below).
    unsafe fn splat(x: f32) -> Self::V;
    /// `a * b`.
    unsafe fn mul(a: Self::V, b: Self::V) -> Self::V;
    /// `a - b`.
    unsafe fn sub(a: Self::V, b: Self::V) -> Self::V;
    /// `a + b`.
    unsafe fn add(a: Self::V, b: Self::V) -> Self::V;
    /// `a / b`.
    unsafe fn div(a: Self::V, b: Self::V) -> Self::V;
    /// `_mm_max_ps(a, b)` lane by lane (`b` where either is NaN).
    unsafe fn max(a: Self::V, b: Self::V) -> Self::V;
    /// `_mm_min_ps(a, b)` lane by lane (`b` where either is NaN).
    unsafe fn min(a: Self::V, b: Self::V) -> Self::V;
    /// `a * b - c` with one rounding.
    unsafe fn fmsub(a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    /// `a <= b`, false where either is NaN.
    unsafe fn le(a: Self::V, b: Self::V) -> Self::M;
    /// `a < b`, false where either is NaN.
    unsafe fn lt(a: Self::V, b: Self::V) -> Self::M;
    /// `a >= b`, false where either is NaN.
    unsafe fn ge(a: Self::V, b: Self::V) -> Self::M;
    /// `a > b`, false where either is NaN.
    unsafe fn gt(a: Self::V, b: Self::V) -> Self::M;
    /// `a != b`, true where either is NaN.
    unsafe fn ne(a: Self::V, b: Self::V) -> Self::M;
    /// `!(a < b)`, true where either is NaN.
    unsafe fn not_lt(a: Self::V, b: Self::V) -> Self::M;
    /// `!(a > b)`, true where either is NaN.
    unsafe fn not_gt(a: Self::V, b: Self::V) -> Self::M;
    /// Both masks.
    unsafe fn and(a: Self::M, b: Self::M) -> Self::M;
    /// The mask as bits, lane `j` in bit `j`.
    unsafe fn bits(m: Self::M) -> u32;
}

/// Eight lanes: AVX with FMA.
pub(crate) struct Avx8;

/// Sixteen lanes: AVX-512F (with AVX and FMA).
pub(crate) struct Avx16;

impl Lanes for Avx8 {
    const N: usize = 8;
    type V = __m256;
    type M = __m256;

    #[inline(always)]
    unsafe fn load(p: *const f32) -> __m256 {
        // SAFETY: the caller's contract (`p` points to 8 f32; the CPU has AVX).
        unsafe { _mm256_loadu_ps(p) }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f32, v: __m256) {
        // SAFETY: the caller's contract (`p` points to 8 writable f32; the CPU has AVX).
        unsafe { _mm256_storeu_ps(p, v) }
    }
    // SAFETY (every method below): register operations, no memory; the caller's CPU has AVX
    // and FMA.
    #[inline(always)]
    unsafe fn splat(x: f32) -> __m256 {
        unsafe { _mm256_set1_ps(x) }
    }
    #[inline(always)]
    unsafe fn mul(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_mul_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn sub(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_sub_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn add(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_add_ps(a, b) }
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
    unsafe fn fmsub(a: __m256, b: __m256, c: __m256) -> __m256 {
        unsafe { _mm256_fmsub_ps(a, b, c) }
    }
    #[inline(always)]
    unsafe fn le(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_cmp_ps::<_CMP_LE_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn lt(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_cmp_ps::<_CMP_LT_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn ge(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_cmp_ps::<_CMP_GE_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn gt(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_cmp_ps::<_CMP_GT_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn ne(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_cmp_ps::<_CMP_NEQ_UQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn not_lt(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_cmp_ps::<_CMP_NLT_UQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn not_gt(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_cmp_ps::<_CMP_NGT_UQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn and(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_and_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn bits(m: __m256) -> u32 {
        unsafe { _mm256_movemask_ps(m) as u32 }
    }
}

impl Lanes for Avx16 {
    const N: usize = 16;
    type V = __m512;
    type M = __mmask16;

    #[inline(always)]
    unsafe fn load(p: *const f32) -> __m512 {
        // SAFETY: the caller's contract (`p` points to 16 f32; the CPU has AVX-512F).
        unsafe { _mm512_loadu_ps(p) }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f32, v: __m512) {
        // SAFETY: the caller's contract (`p` points to 16 writable f32; the CPU has AVX-512F).
        unsafe { _mm512_storeu_ps(p, v) }
    }
    // SAFETY (every method below): register operations, no memory; the caller's CPU has
    // AVX-512F.
    #[inline(always)]
    unsafe fn splat(x: f32) -> __m512 {
        unsafe { _mm512_set1_ps(x) }
    }
    #[inline(always)]
    unsafe fn mul(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_mul_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn sub(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_sub_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn add(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_add_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn div(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_div_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn max(a: __m512, b: __m512) -> __m512 {
        // vmaxps at any width: `b` where either is NaN or both are zeros
        unsafe { _mm512_max_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn min(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_min_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn fmsub(a: __m512, b: __m512, c: __m512) -> __m512 {
        unsafe { _mm512_fmsub_ps(a, b, c) }
    }
    #[inline(always)]
    unsafe fn le(a: __m512, b: __m512) -> __mmask16 {
        unsafe { _mm512_cmp_ps_mask::<_CMP_LE_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn lt(a: __m512, b: __m512) -> __mmask16 {
        unsafe { _mm512_cmp_ps_mask::<_CMP_LT_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn ge(a: __m512, b: __m512) -> __mmask16 {
        unsafe { _mm512_cmp_ps_mask::<_CMP_GE_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn gt(a: __m512, b: __m512) -> __mmask16 {
        unsafe { _mm512_cmp_ps_mask::<_CMP_GT_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn ne(a: __m512, b: __m512) -> __mmask16 {
        unsafe { _mm512_cmp_ps_mask::<_CMP_NEQ_UQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn not_lt(a: __m512, b: __m512) -> __mmask16 {
        unsafe { _mm512_cmp_ps_mask::<_CMP_NLT_UQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn not_gt(a: __m512, b: __m512) -> __mmask16 {
        unsafe { _mm512_cmp_ps_mask::<_CMP_NGT_UQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn and(a: __mmask16, b: __mmask16) -> __mmask16 {
        a & b
    }
    #[inline(always)]
    unsafe fn bits(m: __mmask16) -> u32 {
        m as u32
    }
}
