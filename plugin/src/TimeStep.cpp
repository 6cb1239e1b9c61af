#include "TimeStep.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <vector>

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

btScalar adaptiveTimeStep(const MuscleState& muscle, btScalar previousDt) {
  const MuscleSettings& settings = *muscle.settings;
  const btScalar inversePreviousDt = previousDt > 0 ? 1 / previousDt : 0;
  const bool centred = muscle.preparedFor == Integrator::Verlet;
  btScalar dt = muscle.stableTimeStep;
  for (uint32_t i : muscle.freeParticles) {
    const btScalar force = muscle.forces[i].length();
    const btScalar speed = (muscle.positions[i] - muscle.previous[i]).length() * inversePreviousDt;
    dt = std::min(dt, largestSafeTimeStep(force, speed, muscle.stepRadius[i], settings.particleMass,
                                          settings.damping, centred));
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
