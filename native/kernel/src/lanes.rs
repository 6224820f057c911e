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

/// Implements [`Lanes`] for `$t` from one family of intrinsics: `$p` is their prefix
/// (`_mm256` or `_mm512`), `$cmp` the comparison taking the predicate as a constant
/// (`_mm256_cmp_ps` gives a vector mask, `_mm512_cmp_ps_mask` a bit mask), `$and` and `$bits`
/// what to do with those masks. The rest are the same operations at either width (vmaxps and
/// vminps give their second operand where either is NaN or both are zeros, as _mm_max_ps).
macro_rules! lanes {
    ($t:ty, $n:expr, $v:ty, $m:ty, $cmp:ident, $and:expr, $bits:expr,
     $load:ident, $store:ident, $set1:ident, $mul:ident, $sub:ident, $add:ident, $div:ident,
     $max:ident, $min:ident, $fmsub:ident) => {
        impl Lanes for $t {
            const N: usize = $n;
            type V = $v;
            type M = $m;

            #[inline(always)]
            unsafe fn load(p: *const f32) -> $v {
                // SAFETY: the caller's contract (`p` points to N f32; the CPU has the features).
                unsafe { $load(p) }
            }
            #[inline(always)]
            unsafe fn store(p: *mut f32, v: $v) {
                // SAFETY: the caller's contract (`p` points to N writable f32; the CPU has the
                // features).
                unsafe { $store(p, v) }
            }
            // SAFETY (every method below): register operations, no memory; the caller's CPU
            // has the width's features.
            #[inline(always)]
            unsafe fn splat(x: f32) -> $v {
                unsafe { $set1(x) }
            }
            #[inline(always)]
            unsafe fn mul(a: $v, b: $v) -> $v {
                unsafe { $mul(a, b) }
            }
            #[inline(always)]
            unsafe fn sub(a: $v, b: $v) -> $v {
                unsafe { $sub(a, b) }
            }
            #[inline(always)]
            unsafe fn add(a: $v, b: $v) -> $v {
                unsafe { $add(a, b) }
            }
            #[inline(always)]
            unsafe fn div(a: $v, b: $v) -> $v {
                unsafe { $div(a, b) }
            }
            #[inline(always)]
            unsafe fn max(a: $v, b: $v) -> $v {
                unsafe { $max(a, b) }
            }
            #[inline(always)]
            unsafe fn min(a: $v, b: $v) -> $v {
                unsafe { $min(a, b) }
            }
            #[inline(always)]
            unsafe fn fmsub(a: $v, b: $v, c: $v) -> $v {
                unsafe { $fmsub(a, b, c) }
            }
            #[inline(always)]
            unsafe fn le(a: $v, b: $v) -> $m {
                unsafe { $cmp::<_CMP_LE_OQ>(a, b) }
            }
            #[inline(always)]
            unsafe fn lt(a: $v, b: $v) -> $m {
                unsafe { $cmp::<_CMP_LT_OQ>(a, b) }
            }
            #[inline(always)]
            unsafe fn ge(a: $v, b: $v) -> $m {
                unsafe { $cmp::<_CMP_GE_OQ>(a, b) }
            }
            #[inline(always)]
            unsafe fn gt(a: $v, b: $v) -> $m {
                unsafe { $cmp::<_CMP_GT_OQ>(a, b) }
            }
            #[inline(always)]
            unsafe fn ne(a: $v, b: $v) -> $m {
                unsafe { $cmp::<_CMP_NEQ_UQ>(a, b) }
            }
            #[inline(always)]
            unsafe fn not_lt(a: $v, b: $v) -> $m {
                unsafe { $cmp::<_CMP_NLT_UQ>(a, b) }
            }
            #[inline(always)]
            unsafe fn not_gt(a: $v, b: $v) -> $m {
                unsafe { $cmp::<_CMP_NGT_UQ>(a, b) }
            }
            #[inline(always)]
            unsafe fn and(a: $m, b: $m) -> $m {
                #[allow(unused_unsafe)]
                unsafe {
                    $and(a, b)
                }
            }
            #[inline(always)]
            unsafe fn bits(m: $m) -> u32 {
                #[allow(unused_unsafe)]
                unsafe {
                    $bits(m)
                }
            }
        }
    };
}

lanes!(
    Avx8,
    8,
    __m256,
    __m256,
    _mm256_cmp_ps,
    |a, b| _mm256_and_ps(a, b),
    |m| _mm256_movemask_ps(m) as u32,
    _mm256_loadu_ps,
    _mm256_storeu_ps,
    _mm256_set1_ps,
    _mm256_mul_ps,
    _mm256_sub_ps,
    _mm256_add_ps,
    _mm256_div_ps,
    _mm256_max_ps,
    _mm256_min_ps,
    _mm256_fmsub_ps
);

lanes!(
    Avx16,
    16,
    __m512,
    __mmask16,
    _mm512_cmp_ps_mask,
    |a: __mmask16, b: __mmask16| a & b,
    |m: __mmask16| m as u32,
    _mm512_loadu_ps,
    _mm512_storeu_ps,
    _mm512_set1_ps,
    _mm512_mul_ps,
    _mm512_sub_ps,
    _mm512_add_ps,
    _mm512_div_ps,
    _mm512_max_ps,
    _mm512_min_ps,
    _mm512_fmsub_ps
);
