#include "TimeStep.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <vector>

#include "kernels/ParticleSimd.h"
#include "kernels/VolumeForces.h"

namespace fibremss {
namespace {
constexpr btScalar kInfinity = std::numeric_limits<btScalar>::infinity();
/// Margin below the stability limit (rounding, non-linear springs).
constexpr btScalar kStabilitySafety = btScalar(0.9);

/// Whether an explicit Runge–Kutta method of `order` stages and order (stability polynomial: the
/// Taylor series of exp to that order) is stable at dt for every mode s² + γs + ω² = 0 with ω²
/// sampled over [0, lambda].
bool rungeKuttaStable(int order, double lambda, double gamma, double dt) {
  constexpr int kSamples = 64;
  for (int j = 0; j <= kSamples; ++j) {
    const double omega2 = lambda * j / kSamples;
    const std::complex<double> root = std::sqrt(std::complex<double>(gamma * gamma / 4 - omega2));
    for (const std::complex<double> s : {-gamma / 2 + root, -gamma / 2 - root}) {
      const std::complex<double> z = s * dt;
      std::complex<double> term = 1, sum = 1;
      for (int k = 1; k <= order; ++k) sum += term *= z / static_cast<double>(k);
      if (std::abs(sum) > 1 + 1e-12) return false;
    }
  }
  return true;
}

/// The largest stable dt of rungeKuttaStable (safety factor applied), searched from the Verlet
/// limit: doubled while stable, then bisected. Undamped springs give 0 for Euler and RK2, whose
/// regions miss the imaginary axis.
btScalar rungeKuttaLimit(int order, double lambda, double gamma, double start) {
  double stable = 0;
  double unstable = start;
  while (rungeKuttaStable(order, lambda, gamma, unstable) && unstable < 64 * start) {
    stable = unstable;
    unstable *= 2;
  }
  for (int k = 0; k < 40; ++k) {
    const double middle = (stable + unstable) / 2;
    (rungeKuttaStable(order, lambda, gamma, middle) ? stable : unstable) = middle;
  }
  return static_cast<btScalar>(kStabilitySafety * stable);
}

#if FIBREMSS_SSE_PARTICLES
/// adaptiveTimeStep over the free particles [begin, count), count − begin a multiple of 4, four
/// at a time, from `dt`: largestSafeTimeStep's operations in its order with exact square roots
/// and divisions, so each lane holds its value bit for bit (and a minimum does not depend on
/// order).
btScalar adaptiveTimeStepSse(const MuscleSettings& settings, const ParticleState& particles,
                             size_t begin, size_t count, btScalar inversePreviousDt, bool centred,
                             btScalar dt) {
  const uint32_t* indices = particles.freeParticles.data();
  const btVector3* f = particles.forces.data();
  const btVector3* x = particles.positions.data();
  const btVector3* previous = particles.previous.data();
  const btScalar* radii = particles.stepRadius.data();
  const __m128 mass = _mm_set1_ps(settings.particleMass);
  const __m128 damping = _mm_set1_ps(settings.damping);
  const __m128 half = _mm_set1_ps(btScalar(0.5));  // x·0.5 rounds as x/2
  const __m128 two = _mm_set1_ps(2), four = _mm_set1_ps(4);
  const __m128 inverseDt = _mm_set1_ps(inversePreviousDt);
  const __m128 zero = _mm_setzero_ps(), infinity = _mm_set1_ps(kInfinity);
  const auto step = [&](const btVector3& v, const btVector3& w) {
    return _mm_sub_ps(loadVector(v), loadVector(w));
  };
  __m128 minimum = _mm_set1_ps(dt);
  for (size_t k = begin; k < count; k += 4) {
    const uint32_t i0 = indices[k], i1 = indices[k + 1], i2 = indices[k + 2], i3 = indices[k + 3];
    const __m128 force = _mm_sqrt_ps(
        squaredLengths(loadVector(f[i0]), loadVector(f[i1]), loadVector(f[i2]), loadVector(f[i3])));
    const __m128 speed = _mm_mul_ps(
        _mm_sqrt_ps(squaredLengths(step(x[i0], previous[i0]), step(x[i1], previous[i1]),
                                   step(x[i2], previous[i2]), step(x[i3], previous[i3]))),
        inverseDt);
    const __m128 radius = _mm_setr_ps(radii[i0], radii[i1], radii[i2], radii[i3]);
    __m128 dampingForce = _mm_mul_ps(damping, speed);
    if (centred) dampingForce = _mm_mul_ps(dampingForce, half);
    const __m128 a = _mm_sub_ps(force, dampingForce);
    const __m128 b = _mm_sub_ps(_mm_mul_ps(mass, speed),
                                centred ? _mm_mul_ps(_mm_mul_ps(damping, radius), half) : zero);
    const __m128 mr = _mm_mul_ps(mass, radius);
    const __m128 discriminant = _mm_add_ps(_mm_mul_ps(b, b), _mm_mul_ps(_mm_mul_ps(four, a), mr));
    // A negative discriminant's root is NaN, so its denominator fails > 0 too: infinity.
    const __m128 denominator = _mm_add_ps(b, _mm_sqrt_ps(discriminant));
    const __m128 positive = _mm_cmpgt_ps(denominator, zero);
    const __m128 root =
        _mm_or_ps(_mm_and_ps(positive, _mm_div_ps(_mm_mul_ps(two, mr), denominator)),
                  _mm_andnot_ps(positive, infinity));
    minimum = _mm_min_ps(root, minimum);  // root < minimum ? root : minimum, as std::min
  }
  alignas(16) btScalar lanes[4];
  _mm_store_ps(lanes, minimum);
  return std::min(std::min(lanes[0], lanes[1]), std::min(lanes[2], lanes[3]));
}
#endif

#if FIBREMSS_AVX2_PARTICLES
/// x − previous of particles i and j, as loadPair.
FIBREMSS_AVX2_PASS __m256 stepPair(const btVector3* x, const btVector3* previous, uint32_t i,
                                   uint32_t j) {
  return _mm256_sub_ps(loadPair(x[i], x[j]), loadPair(previous[i], previous[j]));
}

/// adaptiveTimeStepSse eight particles at a time over [0, count), count a multiple of 8: the
/// same operations per lane (AVX2 without FMA), so the same bits.
FIBREMSS_AVX2_PASS btScalar adaptiveTimeStepAvx2(const MuscleSettings& settings,
                                                 const ParticleState& particles, size_t count,
                                                 btScalar inversePreviousDt, bool centred,
                                                 btScalar dt) {
  const uint32_t* indices = particles.freeParticles.data();
  const btVector3* f = particles.forces.data();
  const btVector3* x = particles.positions.data();
  const btVector3* previous = particles.previous.data();
  const btScalar* radii = particles.stepRadius.data();
  const __m256 mass = _mm256_set1_ps(settings.particleMass);
  const __m256 damping = _mm256_set1_ps(settings.damping);
  const __m256 half = _mm256_set1_ps(btScalar(0.5));  // x·0.5 rounds as x/2
  const __m256 two = _mm256_set1_ps(2), four = _mm256_set1_ps(4);
  const __m256 inverseDt = _mm256_set1_ps(inversePreviousDt);
  const __m256 zero = _mm256_setzero_ps(), infinity = _mm256_set1_ps(kInfinity);
  __m256 minimum = _mm256_set1_ps(dt);
  for (size_t k = 0; k < count; k += 8) {
    const uint32_t* i = indices + k;
    const __m256 force =
        _mm256_sqrt_ps(squaredLengths8(loadPair(f[i[0]], f[i[4]]), loadPair(f[i[1]], f[i[5]]),
                                       loadPair(f[i[2]], f[i[6]]), loadPair(f[i[3]], f[i[7]])));
    const __m256 speed =
        _mm256_mul_ps(_mm256_sqrt_ps(squaredLengths8(
                          stepPair(x, previous, i[0], i[4]), stepPair(x, previous, i[1], i[5]),
                          stepPair(x, previous, i[2], i[6]), stepPair(x, previous, i[3], i[7]))),
                      inverseDt);
    const __m256 radius = _mm256_i32gather_ps(
        radii, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(i)), sizeof(btScalar));
    __m256 dampingForce = _mm256_mul_ps(damping, speed);
    if (centred) dampingForce = _mm256_mul_ps(dampingForce, half);
    const __m256 a = _mm256_sub_ps(force, dampingForce);
    const __m256 b =
        _mm256_sub_ps(_mm256_mul_ps(mass, speed),
                      centred ? _mm256_mul_ps(_mm256_mul_ps(damping, radius), half) : zero);
    const __m256 mr = _mm256_mul_ps(mass, radius);
    const __m256 discriminant =
        _mm256_add_ps(_mm256_mul_ps(b, b), _mm256_mul_ps(_mm256_mul_ps(four, a), mr));
    // A negative discriminant's root is NaN, so its denominator fails > 0 too: infinity.
    const __m256 denominator = _mm256_add_ps(b, _mm256_sqrt_ps(discriminant));
    const __m256 positive = _mm256_cmp_ps(denominator, zero, _CMP_GT_OQ);
    const __m256 root =
        _mm256_blendv_ps(infinity, _mm256_div_ps(_mm256_mul_ps(two, mr), denominator), positive);
    minimum = _mm256_min_ps(root, minimum);  // root < minimum ? root : minimum, as std::min
  }
  alignas(32) btScalar lanes[8];
  _mm256_store_ps(lanes, minimum);
  return *std::min_element(lanes, lanes + 8);
}
#endif
}  // namespace

btScalar largestSafeTimeStep(btScalar force, btScalar speed, btScalar radius, btScalar mass,
                             btScalar damping, bool centredDamping) {
  // a·dt² + b·dt − m·r ≤ 0 holds at dt = 0; its first positive root, in the form that stays
  // accurate for a → 0 and a, b < 0 (damping outweighs the force): 2mr / (b + √(b² + 4a·mr)).
  // Centred damping (Verlet): (1 + γ)·|Δx| ≤ (1 − γ)·v·dt + |F|·dt²/m with γ = c·dt/(2m), so
  // half the damping enters a, and the (1 + γ) on the left adds −c·r/2 to b.
  const btScalar dampingForce = centredDamping ? damping * speed / 2 : damping * speed;
  const btScalar a = force - dampingForce;
  const btScalar b = mass * speed - (centredDamping ? damping * radius / 2 : 0);
  const btScalar mr = mass * radius;
  const btScalar discriminant = b * b + 4 * a * mr;
  if (discriminant < 0) return kInfinity;  // a < 0 and the bound holds for every dt
  const btScalar denominator = b + std::sqrt(discriminant);
  return denominator > 0 ? 2 * mr / denominator : kInfinity;
}

btScalar adaptiveTimeStep(const MuscleSettings& settings, const ParticleState& particles,
                          bool centred, btScalar previousDt) {
  return adaptiveTimeStep(settings, particles, centred, previousDt, fastestSpringKernel());
}

btScalar adaptiveTimeStep(const MuscleSettings& settings, const ParticleState& particles,
                          bool centred, btScalar previousDt, [[maybe_unused]] SpringKernel kernel) {
  const btScalar inversePreviousDt = previousDt > 0 ? 1 / previousDt : 0;
  btScalar dt = particles.stableTimeStep;
  size_t k = 0;
#if FIBREMSS_AVX2_PARTICLES
  if (kernel == SpringKernel::avx2) {
    k = particles.freeParticles.size() & ~size_t{7};
    dt = adaptiveTimeStepAvx2(settings, particles, k, inversePreviousDt, centred, dt);
  }
#endif
#if FIBREMSS_SSE_PARTICLES
  if (kernel != SpringKernel::scalar) {
    const size_t begin = k;
    k = particles.freeParticles.size() & ~size_t{3};
    dt = adaptiveTimeStepSse(settings, particles, begin, k, inversePreviousDt, centred, dt);
  }
#endif
  for (; k < particles.freeParticles.size(); ++k) {
    const uint32_t i = particles.freeParticles[k];
    const btScalar force = particles.forces[i].length();
    const btScalar speed =
        (particles.positions[i] - particles.previous[i]).length() * inversePreviousDt;
    dt = std::min(dt, largestSafeTimeStep(force, speed, particles.stepRadius[i],
                                          settings.particleMass, settings.damping, centred));
  }
  return dt;
}

btScalar stableTimeStep(const MuscleSettings& settings, Integrator kind) {
  // Rows of free particles only: fixed ones are never integrated.
  std::vector<btScalar> stiffness(settings.particleCount(), 0);
  for (const Spring& spring : settings.springs) {
    if (!settings.isFixed(spring.a)) stiffness[spring.a] += spring.stiffness;
    if (!settings.isFixed(spring.b)) stiffness[spring.b] += spring.stiffness;
  }
  addLocalVolumeStiffness(settings, stiffness);
  addEnclosedVolumeStiffness(settings, stiffness);
  const btScalar stiffest =
      stiffness.empty() ? 0 : *std::max_element(stiffness.begin(), stiffness.end());
  if (stiffest <= 0 || settings.particleMass <= 0) return kInfinity;
  const double lambda = 2.0 * stiffest / settings.particleMass;  // ω²max bound
  const double dampingRate = settings.damping / settings.particleMass;
  const double verletLimit =
      (-dampingRate + std::sqrt(dampingRate * dampingRate + 4 * lambda)) / lambda;
  switch (kind) {
    case Integrator::Verlet:  // (1 + γ)z² − (2 − λdt²)z + (1 − γ): |roots| < 1 iff λdt² < 4
      return static_cast<btScalar>(kStabilitySafety * 2 / std::sqrt(lambda));
    case Integrator::SemiImplicitEuler:
      return static_cast<btScalar>(kStabilitySafety * verletLimit);
    case Integrator::ExplicitEuler:
      return rungeKuttaLimit(1, lambda, dampingRate, verletLimit);
    case Integrator::Rk2:
      return rungeKuttaLimit(2, lambda, dampingRate, verletLimit);
    case Integrator::Rk4:
      return rungeKuttaLimit(4, lambda, dampingRate, verletLimit);
    default:
      return kInfinity;
  }
}

}  // namespace fibremss
