// Position-based integrators (docs/integrators.md): PBD (rigid distance constraints) and XPBD
// (compliant ones, compliance α = 1/k per spring). Gauss–Seidel over the springs in their stored
// order; a later pass may colour them into batches that run in parallel.
#include <algorithm>
#include <cmath>
#include <vector>

#include "IntegratorsInternal.h"

namespace fibremss {
namespace {

/// XPBD's Lagrange multipliers, one per spring, reset every iteration.
struct MultiplierWorkspace final : IntegratorWorkspace {
  std::vector<btScalar> lambda;  ///< accumulated multiplier of each spring's constraint
};

/// Predicts x* = x + dt·v·(1 − c·dt/m)⁺ with v = (x − x(t−dt′))/dt′ (the damped Verlet
/// prediction without forces, clamped so strong damping cannot reverse the motion), then
/// projects the distance constraints C = |x_b − x_a| − L0 of the springs in `passes`
/// Gauss–Seidel passes: Δλ = (−C − α̃·λ)/(w_a + w_b + α̃), x_a −= w_a·n·Δλ, x_b += w_b·n·Δλ with
/// w = 1/m (0 for fixed particles) and α̃ = 1/(k·dt²) for XPBD, 0 for PBD. The velocity of the
/// next iteration follows from x(t+dt) − x(t).
class PositionBasedIntegrator final : public TimeIntegrator {
 public:
  explicit PositionBasedIntegrator(bool compliant) : compliant_(compliant) {}

  IntegrationResult advance(MuscleState& muscle, btScalar dt, btScalar previousDt) const override {
    const MuscleSettings& settings = *muscle.settings;
    const btScalar inverseMass = 1 / settings.particleMass;
    const btScalar keep =
        std::max(btScalar(0), 1 - settings.damping * dt * inverseMass) * dt / previousDt;
    for (uint32_t i : muscle.freeParticles) {
      const btVector3 x = muscle.positions[i];
      muscle.positions[i] += (x - muscle.previous[i]) * keep;
      muscle.previous[i] = x;
    }
    btScalar* lambda = nullptr;
    if (compliant_) {
      auto& multipliers = static_cast<MultiplierWorkspace&>(*muscle.workspace);
      std::fill(multipliers.lambda.begin(), multipliers.lambda.end(), btScalar(0));
      lambda = multipliers.lambda.data();
    }
    const btScalar inverseDt2 = 1 / (dt * dt);
    const int passes = std::max(1, solverParameters(muscle).constraintIterations);
    for (int pass = 0; pass < passes; ++pass)
      for (size_t s = 0; s < settings.springs.size(); ++s) {
        const Spring& spring = settings.springs[s];
        const btScalar wa = settings.isFixed(spring.a) ? 0 : inverseMass;
        const btScalar wb = settings.isFixed(spring.b) ? 0 : inverseMass;
        const btVector3 d = muscle.positions[spring.b] - muscle.positions[spring.a];
        const btScalar length = d.length();
        const btScalar compliance = lambda ? inverseDt2 / spring.stiffness : 0;
        const btScalar denominator = wa + wb + compliance;
        if (!(length > 0) || !(denominator > 0)) continue;
        const btScalar current = lambda ? lambda[s] : 0;
        const btScalar delta = (spring.restLength - length - compliance * current) / denominator;
        if (lambda) lambda[s] += delta;
        const btVector3 move = d * (delta / length);
        muscle.positions[spring.a] -= move * wa;
        muscle.positions[spring.b] += move * wb;
      }
    IntegrationResult result;
    for (uint32_t i : muscle.freeParticles)
      result.displacement += (muscle.positions[i] - muscle.previous[i]).length();
    result.finite = std::isfinite(result.displacement);
    return result;
  }
  bool usesVelocities() const override { return false; }
  Integrator kind() const override { return compliant_ ? Integrator::Xpbd : Integrator::Pbd; }

 protected:
  std::unique_ptr<IntegratorWorkspace> makeWorkspace(const MuscleState& muscle) const override {
    if (!compliant_) return nullptr;
    auto multipliers = std::make_unique<MultiplierWorkspace>();
    multipliers->lambda.assign(muscle.settings->springs.size(), 0);
    return multipliers;
  }

 private:
  bool compliant_;  ///< XPBD (compliance 1/k) rather than PBD (rigid constraints)
};

}  // namespace

const TimeIntegrator* positionBasedIntegratorFor(Integrator kind) {
  static const PositionBasedIntegrator pbd(false);
  static const PositionBasedIntegrator xpbd(true);
  if (kind == Integrator::Pbd) return &pbd;
  if (kind == Integrator::Xpbd) return &xpbd;
  return nullptr;
}

}  // namespace fibremss
