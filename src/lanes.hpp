// Eight float lanes: one AVX register, or two SSE registers in the baseline build. A wide
// node's boxes (traverse_wide.hpp) and a leaf's triangles (triangle_filter.hpp) are tested
// eight at a time in them.
#pragma once

#include <immintrin.h>

#include <cstdint>

namespace vrc {

#if defined(__AVX__)
using Lane8 = __m256;
/// Eight bytes as floats (exactly).
[[gnu::always_inline]] inline Lane8 lanes_load_u8(const uint8_t* p) {
#if defined(__AVX2__)
    return _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p))));
#else
    const __m128i zero = _mm_setzero_si128();
    const __m128i x = _mm_unpacklo_epi8(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p)), zero);
    return _mm256_set_m128(_mm_cvtepi32_ps(_mm_unpackhi_epi16(x, zero)), _mm_cvtepi32_ps(_mm_unpacklo_epi16(x, zero)));
#endif
}
[[gnu::always_inline]] inline Lane8 lanes_set(float x) { return _mm256_set1_ps(x); }
[[gnu::always_inline]] inline Lane8 lanes_load(const float* p) { return _mm256_load_ps(p); }
[[gnu::always_inline]] inline Lane8 lanes_add(Lane8 a, Lane8 b) { return _mm256_add_ps(a, b); }
[[gnu::always_inline]] inline Lane8 lanes_sub(Lane8 a, Lane8 b) { return _mm256_sub_ps(a, b); }
[[gnu::always_inline]] inline Lane8 lanes_mul(Lane8 a, Lane8 b) { return _mm256_mul_ps(a, b); }
[[gnu::always_inline]] inline Lane8 lanes_max(Lane8 a, Lane8 b) { return _mm256_max_ps(a, b); }
[[gnu::always_inline]] inline Lane8 lanes_min(Lane8 a, Lane8 b) { return _mm256_min_ps(a, b); }
[[gnu::always_inline]] inline Lane8 lanes_or(Lane8 a, Lane8 b) { return _mm256_or_ps(a, b); }
[[gnu::always_inline]] inline Lane8 lanes_and(Lane8 a, Lane8 b) { return _mm256_and_ps(a, b); }
[[gnu::always_inline]] inline Lane8 lanes_abs(Lane8 a) { return _mm256_andnot_ps(_mm256_set1_ps(-0.0f), a); }
[[gnu::always_inline]] inline Lane8 lanes_neg(Lane8 a) { return _mm256_xor_ps(_mm256_set1_ps(-0.0f), a); }
/// All-ones lanes where a < b.
[[gnu::always_inline]] inline Lane8 lanes_lt(Lane8 a, Lane8 b) { return _mm256_cmp_ps(a, b, _CMP_LT_OQ); }
[[gnu::always_inline]] inline unsigned lanes_bits(Lane8 a) { return unsigned(_mm256_movemask_ps(a)); }
[[gnu::always_inline]] inline void lanes_store(float* p, Lane8 a) { _mm256_store_ps(p, a); }
[[gnu::always_inline]] inline unsigned lanes_le(Lane8 a, Lane8 b) { return unsigned(_mm256_movemask_ps(_mm256_cmp_ps(a, b, _CMP_LE_OQ))); }
#else
struct Lane8 {
    __m128 lo, hi;
};
[[gnu::always_inline]] inline Lane8 lanes_load_u8(const uint8_t* p) {
    const __m128i zero = _mm_setzero_si128();
    const __m128i x = _mm_unpacklo_epi8(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p)), zero);
    return {_mm_cvtepi32_ps(_mm_unpacklo_epi16(x, zero)), _mm_cvtepi32_ps(_mm_unpackhi_epi16(x, zero))};
}
[[gnu::always_inline]] inline Lane8 lanes_set(float x) { return {_mm_set1_ps(x), _mm_set1_ps(x)}; }
[[gnu::always_inline]] inline Lane8 lanes_load(const float* p) { return {_mm_load_ps(p), _mm_load_ps(p + 4)}; }
[[gnu::always_inline]] inline Lane8 lanes_add(Lane8 a, Lane8 b) { return {_mm_add_ps(a.lo, b.lo), _mm_add_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline Lane8 lanes_sub(Lane8 a, Lane8 b) { return {_mm_sub_ps(a.lo, b.lo), _mm_sub_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline Lane8 lanes_mul(Lane8 a, Lane8 b) { return {_mm_mul_ps(a.lo, b.lo), _mm_mul_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline Lane8 lanes_max(Lane8 a, Lane8 b) { return {_mm_max_ps(a.lo, b.lo), _mm_max_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline Lane8 lanes_min(Lane8 a, Lane8 b) { return {_mm_min_ps(a.lo, b.lo), _mm_min_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline Lane8 lanes_or(Lane8 a, Lane8 b) { return {_mm_or_ps(a.lo, b.lo), _mm_or_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline Lane8 lanes_and(Lane8 a, Lane8 b) { return {_mm_and_ps(a.lo, b.lo), _mm_and_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline Lane8 lanes_abs(Lane8 a) {
    const __m128 sign = _mm_set1_ps(-0.0f);
    return {_mm_andnot_ps(sign, a.lo), _mm_andnot_ps(sign, a.hi)};
}
[[gnu::always_inline]] inline Lane8 lanes_neg(Lane8 a) {
    const __m128 sign = _mm_set1_ps(-0.0f);
    return {_mm_xor_ps(sign, a.lo), _mm_xor_ps(sign, a.hi)};
}
[[gnu::always_inline]] inline Lane8 lanes_lt(Lane8 a, Lane8 b) { return {_mm_cmplt_ps(a.lo, b.lo), _mm_cmplt_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline unsigned lanes_bits(Lane8 a) {
    return unsigned(_mm_movemask_ps(a.lo)) | unsigned(_mm_movemask_ps(a.hi)) << 4;
}
[[gnu::always_inline]] inline void lanes_store(float* p, Lane8 a) {
    _mm_store_ps(p, a.lo);
    _mm_store_ps(p + 4, a.hi);
}
[[gnu::always_inline]] inline unsigned lanes_le(Lane8 a, Lane8 b) {
    return unsigned(_mm_movemask_ps(_mm_cmple_ps(a.lo, b.lo))) | unsigned(_mm_movemask_ps(_mm_cmple_ps(a.hi, b.hi))) << 4;
}
#endif

/// a * b + c, in one rounding where the CPU has FMA.
[[gnu::always_inline]] inline Lane8 lanes_fmadd(Lane8 a, Lane8 b, Lane8 c) {
#if defined(__FMA__)
    return _mm256_fmadd_ps(a, b, c);
#else
    return lanes_add(lanes_mul(a, b), c);
#endif
}

}  // namespace vrc
