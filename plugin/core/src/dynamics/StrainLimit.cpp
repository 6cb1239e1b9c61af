#include "StrainLimit.h"

#include <cmath>

#include "kernels/ParticleSimd.h"
#include "kernels/SpringForces.h"
#include "state/MuscleState.h"

namespace fibremss {
namespace {

/// A shortened spring ends this share of its limit inside it [1]: far beyond float rounding, so
/// that the next pass does not find it beyond again.
constexpr btScalar kInside = btScalar(1e-5);

/// Springs [first, last) in order, each longer than `limit`·L0 shortened; returns how many. A
/// particle it moves is marked pushed (pushedLast): the projective solver holds it as a
/// contact's (W, its preconditioner only) and leaves it out of the L-BFGS pairs, as a
/// projection's move is no answer of the forces (with it in, real-hip took 1.7× the time per
/// iteration).
size_t projectRange(const MuscleSettings& settings, btVector3* x, uint8_t* pushed, btScalar limit,
                    size_t first, size_t last) {
  const auto move = [&](uint32_t i, const btVector3& by) {
    x[i] += by;
    pushed[i] = 1;
  };
  size_t shortened = 0;
  for (size_t s = first; s < last; ++s) {
    const Spring& spring = settings.springs[s];
    const btScalar longest = limit * spring.restLength;
    const btVector3 d = x[spring.b] - x[spring.a];
    const btScalar length2 = d.length2();
    if (!(length2 > longest * longest)) continue;  // within, or not finite: the guard's
    const bool fixedA = settings.isFixed(spring.a), fixedB = settings.isFixed(spring.b);
    if (fixedA && fixedB) continue;
    const btScalar length = std::sqrt(length2);
    const btVector3 excess = d * ((length - longest * (1 - kInside)) / length);
    if (fixedA) {
      move(spring.b, -excess);
    } else if (fixedB) {
      move(spring.a, excess);
    } else {
      move(spring.a, excess * btScalar(0.5));
      move(spring.b, excess * btScalar(-0.5));
    }
    ++shortened;
  }
  return shortened;
}

#if FIBREMSS_AVX2_PARTICLES
/// Which of the eight springs from `springs` are longer than `limit`·L0 by projectRange's test
/// (the same differences, lengths and products, lane by lane): bit j for spring j.
FIBREMSS_AVX2_PASS inline int beyondAvx2(const Spring* springs, const btVector3* x,
                                         btScalar limit) {
  __m256 d[4], raw[4];
  for (int j = 0; j < 4; ++j) {
    const Spring &low = springs[j], &high = springs[j + 4];
    d[j] = _mm256_sub_ps(loadPair(x[low.b], x[high.b]), loadPair(x[low.a], x[high.a]));
    raw[j] = _mm256_insertf128_ps(
        _mm256_castps128_ps256(_mm_loadu_ps(reinterpret_cast<const float*>(&low))),
        _mm_loadu_ps(reinterpret_cast<const float*>(&high)), 1);
  }
  // Each spring's third word, L0, into its lane (squaredLengths8's transposition).
  const __m256 rest = _mm256_shuffle_ps(_mm256_unpackhi_ps(raw[0], raw[1]),
                                        _mm256_unpackhi_ps(raw[2], raw[3]), 0x44);
  const __m256 longest = _mm256_mul_ps(_mm256_set1_ps(limit), rest);
  const __m256 beyond = _mm256_cmp_ps(squaredLengths8(d[0], d[1], d[2], d[3]),
                                      _mm256_mul_ps(longest, longest), _CMP_GT_OQ);
  return _mm256_movemask_ps(beyond);
}

/// projectionPass's springs eight at a time: those before the first beyond the limit are passed
/// over (the pass moves nothing there), the rest of the eight go through projectRange.
FIBREMSS_AVX2_PASS size_t projectionPassAvx2(const MuscleSettings& settings, btVector3* x,
                                             uint8_t* pushed, btScalar limit) {
  const size_t count = settings.springs.size();
  size_t shortened = 0, first = 0;
  for (; first + 8 <= count; first += 8)
    if (const int beyond = beyondAvx2(settings.springs.data() + first, x, limit))
      shortened += projectRange(settings, x, pushed, limit, first + size_t(__builtin_ctz(beyond)),
                                first + 8);
  return shortened + projectRange(settings, x, pushed, limit, first, count);
}
#endif

/// One pass over the springs in order; returns the springs it shortened. With AVX2 eight springs
/// are tested at once and only those from the first beyond the limit taken one by one: the pass
/// moves nothing before it, so the same positions as spring by spring.
size_t projectionPass(const MuscleSettings& settings, ParticleState& particles,
                      ContactState& contact, btScalar limit, SpringKernel kernel) {
  btVector3* x = particles.positions.data();
  uint8_t* pushed = contact.pushedLast.data();
#if FIBREMSS_AVX2_PARTICLES
  if (kernel == SpringKernel::avx2) return projectionPassAvx2(settings, x, pushed, limit);
#else
  (void)kernel;
#endif
  return projectRange(settings, x, pushed, limit, 0, settings.springs.size());
}

}  // namespace

size_t limitStrain(const MuscleSettings& settings, ParticleState& particles, ContactState& contact,
                   int passes) {
  return limitStrain(settings, particles, contact, passes, fastestSpringKernel());
}

size_t limitStrain(const MuscleSettings& settings, ParticleState& particles, ContactState& contact,
                   int passes, SpringKernel kernel) {
  if (!(settings.strainLimit > 0)) return 0;
  size_t shortened = 0;
  for (int pass = 0; pass < passes; ++pass) {
    const size_t count = projectionPass(settings, particles, contact, settings.strainLimit, kernel);
    if (count == 0) break;
    shortened += count;
  }
  return shortened;
}

double freeDisplacement(const ParticleState& particles) {
  double sum = 0;
  for (uint32_t i : particles.freeParticles)
    sum += (particles.positions[i] - particles.previous[i]).length();
  return sum;
}

}  // namespace fibremss
