//! The lane widths the kernels run at, behind one trait: 4 lanes (SSE2),
//! 8 (AVX2) and 16 (AVX-512). A kernel written once over `Lanes` is
//! compiled for each width it is called with; every method is one
//! instruction (or two), inlined, so the generic code is the hand-written
//! code it replaced.
//!
//! Comparisons keep the SSE predicates at every width (`lt` is LT_OS,
//! `ne` is NEQ_UQ, …), so a NaN compares the same way on every path and
//! the lanes of every width give the scalar code's answers bit for bit.
//! Masks stay in the width's own form (a vector for SSE and AVX, a mask
//! register for AVX-512) until `bits`, which gives bit i for lane i.

use std::arch::x86_64::*;

/// A register of f32 lanes and its comparison masks.
///
/// # Safety
/// Every method needs the width's instruction set: SSE2 (every x86-64
/// CPU) for `__m128`, AVX2 for `__m256`, AVX-512F for `__m512`. Callers
/// run inside a function compiled with that feature, where these
/// inline to single instructions.
pub(super) trait Lanes: Copy {
    type Mask: Copy;
    unsafe fn splat(x: f32) -> Self;
    unsafe fn add(self, b: Self) -> Self;
    unsafe fn sub(self, b: Self) -> Self;
    unsafe fn mul(self, b: Self) -> Self;
    unsafe fn div(self, b: Self) -> Self;
    /// `self > b ? self : b` per lane (maxps: a NaN in `self` gives `b`).
    unsafe fn max(self, b: Self) -> Self;
    /// `self < b ? self : b` per lane (minps: a NaN in `self` gives `b`).
    unsafe fn min(self, b: Self) -> Self;
    /// `self` with the sign bit cleared.
    unsafe fn abs(self) -> Self;
    unsafe fn eq(self, b: Self) -> Self::Mask;
    unsafe fn lt(self, b: Self) -> Self::Mask;
    unsafe fn gt(self, b: Self) -> Self::Mask;
    unsafe fn le(self, b: Self) -> Self::Mask;
    unsafe fn ge(self, b: Self) -> Self::Mask;
    unsafe fn ne(self, b: Self) -> Self::Mask;
    unsafe fn and(a: Self::Mask, b: Self::Mask) -> Self::Mask;
    unsafe fn or(a: Self::Mask, b: Self::Mask) -> Self::Mask;
    /// `!a & b`.
    unsafe fn and_not(a: Self::Mask, b: Self::Mask) -> Self::Mask;
    /// Bit i set when lane i of the mask is.
    unsafe fn bits(m: Self::Mask) -> u32;
    /// Lanes loaded from `at`, aligned to the register's width.
    unsafe fn load(at: *const f32) -> Self;
    /// Lanes stored at `out` (unaligned).
    unsafe fn store(self, out: *mut f32);
}

impl Lanes for __m128 {
    type Mask = __m128;
    #[inline(always)]
    unsafe fn splat(x: f32) -> Self {
        _mm_set1_ps(x)
    }
    #[inline(always)]
    unsafe fn add(self, b: Self) -> Self {
        _mm_add_ps(self, b)
    }
    #[inline(always)]
    unsafe fn sub(self, b: Self) -> Self {
        _mm_sub_ps(self, b)
    }
    #[inline(always)]
    unsafe fn mul(self, b: Self) -> Self {
        _mm_mul_ps(self, b)
    }
    #[inline(always)]
    unsafe fn div(self, b: Self) -> Self {
        _mm_div_ps(self, b)
    }
    #[inline(always)]
    unsafe fn max(self, b: Self) -> Self {
        _mm_max_ps(self, b)
    }
    #[inline(always)]
    unsafe fn min(self, b: Self) -> Self {
        _mm_min_ps(self, b)
    }
    #[inline(always)]
    unsafe fn abs(self) -> Self {
        _mm_and_ps(self, _mm_castsi128_ps(_mm_set1_epi32(0x7fff_ffff)))
    }
    #[inline(always)]
    unsafe fn eq(self, b: Self) -> Self {
        _mm_cmpeq_ps(self, b)
    }
    #[inline(always)]
    unsafe fn lt(self, b: Self) -> Self {
        _mm_cmplt_ps(self, b)
    }
    #[inline(always)]
    unsafe fn gt(self, b: Self) -> Self {
        _mm_cmpgt_ps(self, b)
    }
    #[inline(always)]
    unsafe fn le(self, b: Self) -> Self {
        _mm_cmple_ps(self, b)
    }
    #[inline(always)]
    unsafe fn ge(self, b: Self) -> Self {
        _mm_cmpge_ps(self, b)
    }
    #[inline(always)]
    unsafe fn ne(self, b: Self) -> Self {
        _mm_cmpneq_ps(self, b)
    }
    #[inline(always)]
    unsafe fn and(a: Self, b: Self) -> Self {
        _mm_and_ps(a, b)
    }
    #[inline(always)]
    unsafe fn or(a: Self, b: Self) -> Self {
        _mm_or_ps(a, b)
    }
    #[inline(always)]
    unsafe fn and_not(a: Self, b: Self) -> Self {
        _mm_andnot_ps(a, b)
    }
    #[inline(always)]
    unsafe fn bits(m: Self) -> u32 {
        _mm_movemask_ps(m) as u32
    }
    #[inline(always)]
    unsafe fn load(at: *const f32) -> Self {
        _mm_load_ps(at)
    }
    #[inline(always)]
    unsafe fn store(self, out: *mut f32) {
        _mm_storeu_ps(out, self)
    }
}

impl Lanes for __m256 {
    type Mask = __m256;
    #[inline(always)]
    unsafe fn splat(x: f32) -> Self {
        _mm256_set1_ps(x)
    }
    #[inline(always)]
    unsafe fn add(self, b: Self) -> Self {
        _mm256_add_ps(self, b)
    }
    #[inline(always)]
    unsafe fn sub(self, b: Self) -> Self {
        _mm256_sub_ps(self, b)
    }
    #[inline(always)]
    unsafe fn mul(self, b: Self) -> Self {
        _mm256_mul_ps(self, b)
    }
    #[inline(always)]
    unsafe fn div(self, b: Self) -> Self {
        _mm256_div_ps(self, b)
    }
    #[inline(always)]
    unsafe fn max(self, b: Self) -> Self {
        _mm256_max_ps(self, b)
    }
    #[inline(always)]
    unsafe fn min(self, b: Self) -> Self {
        _mm256_min_ps(self, b)
    }
    #[inline(always)]
    unsafe fn abs(self) -> Self {
        _mm256_and_ps(self, _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff)))
    }
    #[inline(always)]
    unsafe fn eq(self, b: Self) -> Self {
        _mm256_cmp_ps::<_CMP_EQ_OQ>(self, b)
    }
    #[inline(always)]
    unsafe fn lt(self, b: Self) -> Self {
        _mm256_cmp_ps::<_CMP_LT_OS>(self, b)
    }
    #[inline(always)]
    unsafe fn gt(self, b: Self) -> Self {
        _mm256_cmp_ps::<_CMP_GT_OS>(self, b)
    }
    #[inline(always)]
    unsafe fn le(self, b: Self) -> Self {
        _mm256_cmp_ps::<_CMP_LE_OS>(self, b)
    }
    #[inline(always)]
    unsafe fn ge(self, b: Self) -> Self {
        _mm256_cmp_ps::<_CMP_GE_OS>(self, b)
    }
    #[inline(always)]
    unsafe fn ne(self, b: Self) -> Self {
        _mm256_cmp_ps::<_CMP_NEQ_UQ>(self, b)
    }
    #[inline(always)]
    unsafe fn and(a: Self, b: Self) -> Self {
        _mm256_and_ps(a, b)
    }
    #[inline(always)]
    unsafe fn or(a: Self, b: Self) -> Self {
        _mm256_or_ps(a, b)
    }
    #[inline(always)]
    unsafe fn and_not(a: Self, b: Self) -> Self {
        _mm256_andnot_ps(a, b)
    }
    #[inline(always)]
    unsafe fn bits(m: Self) -> u32 {
        _mm256_movemask_ps(m) as u32
    }
    #[inline(always)]
    unsafe fn load(at: *const f32) -> Self {
        _mm256_load_ps(at)
    }
    #[inline(always)]
    unsafe fn store(self, out: *mut f32) {
        _mm256_storeu_ps(out, self)
    }
}

impl Lanes for __m512 {
    type Mask = __mmask16;
    #[inline(always)]
    unsafe fn splat(x: f32) -> Self {
        _mm512_set1_ps(x)
    }
    #[inline(always)]
    unsafe fn add(self, b: Self) -> Self {
        _mm512_add_ps(self, b)
    }
    #[inline(always)]
    unsafe fn sub(self, b: Self) -> Self {
        _mm512_sub_ps(self, b)
    }
    #[inline(always)]
    unsafe fn mul(self, b: Self) -> Self {
        _mm512_mul_ps(self, b)
    }
    #[inline(always)]
    unsafe fn div(self, b: Self) -> Self {
        _mm512_div_ps(self, b)
    }
    #[inline(always)]
    unsafe fn max(self, b: Self) -> Self {
        _mm512_max_ps(self, b)
    }
    #[inline(always)]
    unsafe fn min(self, b: Self) -> Self {
        _mm512_min_ps(self, b)
    }
    #[inline(always)]
    unsafe fn abs(self) -> Self {
        _mm512_abs_ps(self)
    }
    #[inline(always)]
    unsafe fn eq(self, b: Self) -> __mmask16 {
        _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(self, b)
    }
    #[inline(always)]
    unsafe fn lt(self, b: Self) -> __mmask16 {
        _mm512_cmp_ps_mask::<_CMP_LT_OS>(self, b)
    }
    #[inline(always)]
    unsafe fn gt(self, b: Self) -> __mmask16 {
        _mm512_cmp_ps_mask::<_CMP_GT_OS>(self, b)
    }
    #[inline(always)]
    unsafe fn le(self, b: Self) -> __mmask16 {
        _mm512_cmp_ps_mask::<_CMP_LE_OS>(self, b)
    }
    #[inline(always)]
    unsafe fn ge(self, b: Self) -> __mmask16 {
        _mm512_cmp_ps_mask::<_CMP_GE_OS>(self, b)
    }
    #[inline(always)]
    unsafe fn ne(self, b: Self) -> __mmask16 {
        _mm512_cmp_ps_mask::<_CMP_NEQ_UQ>(self, b)
    }
    #[inline(always)]
    unsafe fn and(a: __mmask16, b: __mmask16) -> __mmask16 {
        a & b
    }
    #[inline(always)]
    unsafe fn or(a: __mmask16, b: __mmask16) -> __mmask16 {
        a | b
    }
    #[inline(always)]
    unsafe fn and_not(a: __mmask16, b: __mmask16) -> __mmask16 {
        !a & b
    }
    #[inline(always)]
    unsafe fn bits(m: __mmask16) -> u32 {
        m as u32
    }
    #[inline(always)]
    unsafe fn load(at: *const f32) -> Self {
        _mm512_load_ps(at)
    }
    #[inline(always)]
    unsafe fn store(self, out: *mut f32) {
        _mm512_storeu_ps(out, self)
    }
}
