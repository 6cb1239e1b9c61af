#include <algorithm>
#include <cmath>
#include <cstddef>

#include "SpringForces.h"

#if defined(__SSE2__) && !defined(BT_USE_DOUBLE_PRECISION)
#include <immintrin.h>
#define FIBREMSS_SSE_SPRINGS 1
#else
#define FIBREMSS_SSE_SPRINGS 0
#endif

namespace fibremss {
namespace {

/// Force factors k·(l − L0)/l of springs [begin, end) from their vectors; adds Σ|l − L0| and
/// the springs beyond 3·L0 (or not finite) to `result`. Four springs at a time with SSE.
void forceFactors(const Spring* springs, const btVector3* vectors, btScalar* factors, size_t count,
                  SpringForceResult& result) {
  size_t s = 0;
#if FIBREMSS_SSE_SPRINGS
  static_assert(sizeof(Spring) == 16 && offsetof(Spring, restLength) == 8 &&
                offsetof(Spring, stiffness) == 12);
  __m128 deviation4 = _mm_setzero_ps();
  const __m128 absolute = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  for (; s + 4 <= count; s += 4) {
    __m128 dx = _mm_loadu_ps(vectors[s].m_floats), dy = _mm_loadu_ps(vectors[s + 1].m_floats),
           dz = _mm_loadu_ps(vectors[s + 2].m_floats), dw = _mm_loadu_ps(vectors[s + 3].m_floats);
    _MM_TRANSPOSE4_PS(dx, dy, dz, dw);
    const float* raw = reinterpret_cast<const float*>(springs + s);
    __m128 ab0 = _mm_loadu_ps(raw), ab1 = _mm_loadu_ps(raw + 4), restLength = _mm_loadu_ps(raw + 8),
           stiffness = _mm_loadu_ps(raw + 12);
    _MM_TRANSPOSE4_PS(ab0, ab1, restLength, stiffness);
    const __m128 length = _mm_sqrt_ps(
        _mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy)), _mm_mul_ps(dz, dz)));
    const __m128 stretch = _mm_sub_ps(length, restLength);
    deviation4 = _mm_add_ps(deviation4, _mm_and_ps(stretch, absolute));
    // Not (stretch ≤ 2·L0): beyond 3× the rest length, or NaN.
    const int beyond = _mm_movemask_ps(_mm_cmpnle_ps(stretch, _mm_add_ps(restLength, restLength)));
    if (beyond)  // rare: count the four mask bits
      result.overstretched += static_cast<size_t>((beyond & 1) + (beyond >> 1 & 1) +
                                                  (beyond >> 2 & 1) + (beyond >> 3 & 1));
    const __m128 factor = _mm_div_ps(_mm_mul_ps(stiffness, stretch), length);
    _mm_storeu_ps(factors + s, _mm_and_ps(factor, _mm_cmpgt_ps(length, _mm_setzero_ps())));
  }
  alignas(16) float lanes[4];
  _mm_store_ps(lanes, deviation4);
  result.deviation += double(lanes[0]) + lanes[1] + lanes[2] + lanes[3];
#endif
  for (; s < count; ++s) {
    const btScalar length = vectors[s].length();
    const btScalar stretch = length - springs[s].restLength;
    result.deviation += std::fabs(stretch);
    if (!(stretch <= 2 * springs[s].restLength)) ++result.overstretched;
    factors[s] = length > 0 ? springs[s].stiffness * stretch / length : 0;
  }
}

}  // namespace

SpringForceResult springForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                               std::span<btVector3> forces, std::span<btVector3> vectorScratch,
                               std::span<btScalar> factorScratch) {
  const Spring* springs = settings.springs.data();
  const size_t count = settings.springs.size();
  const btVector3* x = positions.data();
  btVector3* vectors = vectorScratch.data();
  btScalar* factors = factorScratch.data();
  std::fill(forces.begin(), forces.end(), btVector3(0, 0, 0));
  btVector3* f = forces.data();

  SpringForceResult result;
  uint32_t current = count ? springs[0].a : 0;
  btVector3 sum(0, 0, 0);
  // Blocks small enough for the scratch to stay in the L1 cache.
  for (size_t begin = 0; begin < count; begin += kSpringBlock) {
    const size_t end = std::min(count, begin + kSpringBlock);
    const Spring* block = springs + begin;
    const size_t n = end - begin;
    for (size_t k = 0; k < n; ++k) vectors[k] = x[block[k].b] - x[block[k].a];
    forceFactors(block, vectors, factors, n, result);
    // Springs are sorted by a: a's force is summed in a register, stored once.
    for (size_t k = 0; k < n; ++k) {
      if (block[k].a != current) {
        f[current] += sum;
        current = block[k].a;
        sum.setZero();
      }
      const btVector3 force = vectors[k] * factors[k];
      sum += force;
      f[block[k].b] -= force;
    }
  }
  if (count) f[current] += sum;
  result.exploded = result.overstretched > 0;
  return result;
}

SpringForceResult springForces(MuscleState& muscle) {
  return springForces(*muscle.settings, muscle.positions, muscle.forces, muscle.springVectors,
                      muscle.springFactors);
}

}  // namespace fibremss
