#pragma once
// SIMD helpers of the per-particle passes (Verlet, adaptive dt, pre-transform) and of the force
// kernels' gathers and scatters, internal. The float build on x86-64 has SSE2; AVX2 functions are
// compiled for their own target and run only when the CPU has it (the spring kernel's choice,
// fastestSpringKernel). AVX2 without FMA: the compiler cannot contract a product and a sum, so
// each lane rounds as the scalar code does.
#include <LinearMath/btVector3.h>

#if defined(__SSE2__) && !defined(BT_USE_DOUBLE_PRECISION)
#include <immintrin.h>
#define FIBREMSS_SSE_PARTICLES 1
#else
#define FIBREMSS_SSE_PARTICLES 0
#endif
#if FIBREMSS_SSE_PARTICLES && defined(__x86_64__) && defined(__GNUC__)
#define FIBREMSS_AVX2_PARTICLES 1
#define FIBREMSS_AVX2_PASS __attribute__((target("avx2")))
#else
#define FIBREMSS_AVX2_PARTICLES 0
#endif

#include <cstdint>
#include <type_traits>

namespace fibremss {

/// The vector `offset` bytes after `base` (the kernels' particle byte offsets).
template <class T>
inline T& at(T* base, uint32_t offset) {
  using Byte = std::conditional_t<std::is_const_v<T>, const char, char>;
  return *reinterpret_cast<T*>(reinterpret_cast<Byte*>(base) + offset);
}

#if FIBREMSS_SSE_PARTICLES
/// |v|² of four vectors, one per lane, in btVector3::length2's order: (x² + y²) + z².
inline __m128 squaredLengths(__m128 v0, __m128 v1, __m128 v2, __m128 v3) {
  _MM_TRANSPOSE4_PS(v0, v1, v2, v3);
  return _mm_add_ps(_mm_add_ps(_mm_mul_ps(v0, v0), _mm_mul_ps(v1, v1)), _mm_mul_ps(v2, v2));
}

/// The vector loaded (w lane included).
inline __m128 loadVector(const btVector3& v) {
  return _mm_load_ps(v.m_floats);
}

/// A mask of the x, y and z lanes: and-ed with a vector, it sets w to 0 as btVector3's
/// arithmetic does.
inline __m128 xyzMask() {
  return _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0));
}
#endif

#if FIBREMSS_AVX2_PARTICLES
/// Vectors v and w in the low and high half of one register.
FIBREMSS_AVX2_PASS inline __m256 loadPair(const btVector3& v, const btVector3& w) {
  return _mm256_insertf128_ps(_mm256_castps128_ps256(loadVector(v)), loadVector(w), 1);
}

/// xyzMask in each half.
FIBREMSS_AVX2_PASS inline __m256 xyzMask8() {
  return _mm256_castsi256_ps(_mm256_setr_epi32(-1, -1, -1, 0, -1, -1, -1, 0));
}

/// The vector `offset` bytes after `base` plus `force`, stored back: a VEX load-add and a store
/// through an indexed address. GCC otherwise adds base and offset into a register first, one
/// instruction more per scatter (callgrind, thigh13 R=20: the fans' step 1 089.8 → 1 070.0 M
/// instructions). force + f, rounded once: the same bits as _mm_add_ps either way round.
FIBREMSS_AVX2_PASS inline void addAt(btVector3* base, uint32_t offset, __m128 force) {
  __m128 sum;
  asm("vaddps %[f], %[force], %[sum]\n\t"
      "vmovaps %[sum], %[f]"
      : [sum] "=&x"(sum), [f] "+m"(at(reinterpret_cast<__m128*>(base), offset))
      : [force] "x"(force));
}

/// |v|² of eight vectors given as loadPair(v_j, v_{j+4}) for j = 0..3: lane k holds v_k's, in
/// btVector3::length2's order.
FIBREMSS_AVX2_PASS inline __m256 squaredLengths8(__m256 r0, __m256 r1, __m256 r2, __m256 r3) {
  const __m256 t0 = _mm256_unpacklo_ps(r0, r1), t1 = _mm256_unpacklo_ps(r2, r3);
  const __m256 t2 = _mm256_unpackhi_ps(r0, r1), t3 = _mm256_unpackhi_ps(r2, r3);
  const __m256 x = _mm256_shuffle_ps(t0, t1, 0x44), y = _mm256_shuffle_ps(t0, t1, 0xee),
               z = _mm256_shuffle_ps(t2, t3, 0x44);
  return _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(x, x), _mm256_mul_ps(y, y)),
                       _mm256_mul_ps(z, z));
}
#endif

}  // namespace fibremss
