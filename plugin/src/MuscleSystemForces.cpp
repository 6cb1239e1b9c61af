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

/// The force on a of the springs that share the particle a: springs are sorted by a, so a run of
/// them sums in a register and reaches memory once.
struct RunSum {
  uint32_t particle;  ///< the run's particle a
  btVector3 sum;      ///< force summed over the run so far
};

/// One spring at a time, for every build (the tail of the SSE loop, and double precision).
void addSpring(const Spring& spring, const btVector3* x, btVector3* f, RunSum& run,
               double& deviation, size_t& overstretched) {
  const btVector3 d = x[spring.b] - x[spring.a];
  const btScalar length = d.length();
  const btScalar stretch = length - spring.restLength;
  deviation += std::fabs(stretch);
  if (!(stretch <= 2 * spring.restLength)) ++overstretched;
  const btVector3 force = d * (length > 0 ? spring.stiffness * stretch / length : 0);
  if (spring.a != run.particle) {
    f[run.particle] += run.sum;
    run = {spring.a, force};
  } else {
    run.sum += force;
  }
  f[spring.b] -= force;
}

#if FIBREMSS_SSE_SPRINGS
/// Springs per block: the deviation is summed in float lanes within a block, in double across
/// blocks, so that its rounding does not grow with the muscle.
constexpr size_t kDeviationBlock = 256;

static_assert(sizeof(Spring) == 16 && offsetof(Spring, restLength) == 8 &&
              offsetof(Spring, stiffness) == 12 && sizeof(btVector3) == 16);

/// RunSum in a register.
struct SseRunSum {
  uint32_t particle;  ///< the run's particle a
  __m128 sum;         ///< force summed over the run so far
};

__m128 load(const btVector3& v) {
  return _mm_load_ps(v.m_floats);
}
void store(btVector3& v, __m128 value) {
  _mm_store_ps(v.m_floats, value);
}

/// Springs [0, count), count a multiple of 4, four at a time: vectors transposed into x, y, z
/// lanes for the lengths, square roots and divisions, the forces transposed back (w = 0) for
/// the scatter. Returns Σ|l − L0| in float lanes.
__m128 addSpringsSse(const Spring* springs, size_t count, const btVector3* x, btVector3* f,
                     SseRunSum& run, size_t& overstretched) {
  const __m128 absolute = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  const __m128 zero = _mm_setzero_ps();
  __m128 deviation = zero;
  for (size_t s = 0; s < count; s += 4) {
    const Spring* group = springs + s;
    const uint32_t a0 = group[0].a, a1 = group[1].a, a2 = group[2].a, a3 = group[3].a;
    const uint32_t b0 = group[0].b, b1 = group[1].b, b2 = group[2].b, b3 = group[3].b;
    __m128 dx = _mm_sub_ps(load(x[b0]), load(x[a0])), dy = _mm_sub_ps(load(x[b1]), load(x[a1])),
           dz = _mm_sub_ps(load(x[b2]), load(x[a2])), dw = _mm_sub_ps(load(x[b3]), load(x[a3]));
    _MM_TRANSPOSE4_PS(dx, dy, dz, dw);
    // Rest lengths and stiffnesses are the upper halves of the 16-byte springs.
    const float* raw = reinterpret_cast<const float*>(group);
    const __m128 low = _mm_unpackhi_ps(_mm_loadu_ps(raw), _mm_loadu_ps(raw + 4));
    const __m128 high = _mm_unpackhi_ps(_mm_loadu_ps(raw + 8), _mm_loadu_ps(raw + 12));
    const __m128 restLength = _mm_movelh_ps(low, high);
    const __m128 stiffness = _mm_movehl_ps(high, low);

    const __m128 length = _mm_sqrt_ps(
        _mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy)), _mm_mul_ps(dz, dz)));
    const __m128 stretch = _mm_sub_ps(length, restLength);
    deviation = _mm_add_ps(deviation, _mm_and_ps(stretch, absolute));
    // Not (stretch ≤ 2·L0): beyond 3× the rest length, or NaN.
    const int beyond = _mm_movemask_ps(_mm_cmpnle_ps(stretch, _mm_add_ps(restLength, restLength)));
    if (beyond)  // rare: count the four mask bits
      overstretched += static_cast<size_t>((beyond & 1) + (beyond >> 1 & 1) + (beyond >> 2 & 1) +
                                           (beyond >> 3 & 1));
    // k·(l − L0)/l, 0 for coincident ends (0/0 masked).
    const __m128 factor =
        _mm_and_ps(_mm_div_ps(_mm_mul_ps(stiffness, stretch), length), _mm_cmpgt_ps(length, zero));
    __m128 f0 = _mm_mul_ps(dx, factor), f1 = _mm_mul_ps(dy, factor), f2 = _mm_mul_ps(dz, factor),
           f3 = zero;
    _MM_TRANSPOSE4_PS(f0, f1, f2, f3);

    store(f[b0], _mm_sub_ps(load(f[b0]), f0));
    store(f[b1], _mm_sub_ps(load(f[b1]), f1));
    store(f[b2], _mm_sub_ps(load(f[b2]), f2));
    store(f[b3], _mm_sub_ps(load(f[b3]), f3));
    if (a0 == run.particle && a3 == a0) {  // the common case: the whole group continues the run
      run.sum = _mm_add_ps(run.sum, _mm_add_ps(_mm_add_ps(f0, f1), _mm_add_ps(f2, f3)));
      continue;
    }
    const uint32_t ends[4] = {a0, a1, a2, a3};
    const __m128 forces[4] = {f0, f1, f2, f3};
    for (int k = 0; k < 4; ++k) {
      if (ends[k] != run.particle) {
        store(f[run.particle], _mm_add_ps(load(f[run.particle]), run.sum));
        run = {ends[k], forces[k]};
      } else {
        run.sum = _mm_add_ps(run.sum, forces[k]);
      }
    }
  }
  return deviation;
}

/// Sum of the four lanes in double.
double laneSum(__m128 lanes) {
  alignas(16) float values[4];
  _mm_store_ps(values, lanes);
  return double(values[0]) + values[1] + values[2] + values[3];
}
#endif

}  // namespace

SpringForceResult springForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                               std::span<btVector3> forces) {
  const Spring* springs = settings.springs.data();
  const size_t count = settings.springs.size();
  const btVector3* x = positions.data();
  std::fill(forces.begin(), forces.end(), btVector3(0, 0, 0));
  btVector3* f = forces.data();

  SpringForceResult result;
  if (count == 0) return result;
  size_t s = 0;
#if FIBREMSS_SSE_SPRINGS
  SseRunSum run{springs[0].a, _mm_setzero_ps()};
  for (const size_t groups = count & ~size_t{3}; s < groups; s += kDeviationBlock) {
    const size_t n = std::min(kDeviationBlock, groups - s);
    result.deviation += laneSum(addSpringsSse(springs + s, n, x, f, run, result.overstretched));
  }
  s = count & ~size_t{3};
  btVector3 sum;
  store(sum, run.sum);
  RunSum tail{run.particle, sum};
#else
  RunSum tail{springs[0].a, btVector3(0, 0, 0)};
#endif
  for (; s < count; ++s) addSpring(springs[s], x, f, tail, result.deviation, result.overstretched);
  f[tail.particle] += tail.sum;
  result.exploded = result.overstretched > 0;
  return result;
}

SpringForceResult springForces(MuscleState& muscle) {
  return springForces(*muscle.settings, muscle.positions, muscle.forces);
}

}  // namespace fibremss
