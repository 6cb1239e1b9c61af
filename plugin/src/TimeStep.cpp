#include "TimeStep.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace fibremss {
namespace {
constexpr btScalar kInfinity = std::numeric_limits<btScalar>::infinity();
/// Margin below the stability limit (rounding, non-linear springs).
constexpr btScalar kStabilitySafety = btScalar(0.9);
}  // namespace

btScalar largestSafeTimeStep(btScalar force, btScalar speed, btScalar radius, btScalar mass,
                             btScalar damping) {
  // a·dt² + b·dt − m·r ≤ 0 holds at dt = 0; its first positive root, in the form that stays
  // accurate for a → 0 and a < 0 (damping outweighs the force): 2mr / (b + √(b² + 4a·mr)).
  const btScalar a = force - damping * speed;
  const btScalar b = mass * speed;
  const btScalar mr = mass * radius;
  const btScalar discriminant = b * b + 4 * a * mr;
  if (discriminant < 0) return kInfinity;  // a < 0 and the bound holds for every dt
  const btScalar denominator = b + std::sqrt(discriminant);
  return denominator > 0 ? 2 * mr / denominator : kInfinity;
}

btScalar adaptiveTimeStep(const MuscleState& muscle, btScalar previousDt) {
  const MuscleSettings& settings = *muscle.settings;
  const btScalar inversePreviousDt = previousDt > 0 ? 1 / previousDt : 0;
  btScalar dt = muscle.stableTimeStep;
  for (uint32_t i : muscle.freeParticles) {
    const btScalar force = muscle.forces[i].length();
    const btScalar speed = (muscle.positions[i] - muscle.previous[i]).length() * inversePreviousDt;
    dt = std::min(dt, largestSafeTimeStep(force, speed, muscle.stepRadius[i], settings.particleMass,
                                          settings.damping));
  }
  return dt;
}

btScalar stableTimeStep(const MuscleSettings& settings) {
  // Rows of free particles only: fixed ones are never integrated.
  std::vector<btScalar> stiffness(settings.particleCount(), 0);
  for (const Spring& spring : settings.springs) {
    if (!settings.isFixed(spring.a)) stiffness[spring.a] += spring.stiffness;
    if (!settings.isFixed(spring.b)) stiffness[spring.b] += spring.stiffness;
  }
  const btScalar stiffest =
      stiffness.empty() ? 0 : *std::max_element(stiffness.begin(), stiffness.end());
  if (stiffest <= 0 || settings.particleMass <= 0) return kInfinity;
  const btScalar lambda = 2 * stiffest / settings.particleMass;  // ω²max bound
  const btScalar dampingRate = settings.damping / settings.particleMass;
  const btScalar limit =
      (-dampingRate + std::sqrt(dampingRate * dampingRate + 4 * lambda)) / lambda;
  return kStabilitySafety * limit;
}

}  // namespace fibremss
