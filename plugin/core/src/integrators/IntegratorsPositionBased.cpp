// Position-based integrators (docs/integrators.md): PBD (rigid distance constraints) and XPBD
// (compliant ones, compliance α = 1/k per spring). Jacobi passes with constraint averaging
// (Macklin et al. 2014): every spring's correction is computed from the positions at the start
// of the pass and each particle moves by the mean of its springs' corrections times ω. Gauss–
// Seidel in spring order was first: on a muscle that must lengthen (the hip sweeps), rigid
// constraints cannot all hold and Gauss–Seidel leaves the whole violation in the last springs
// of each path (3× their rest length at ~50° of hip extension, earlier with more passes);
// averaging spreads it over all of them. Every spring is independent within a pass, so a pass
// can run in parallel as it stands.
#include <algorithm>
#include <cmath>
#include <vector>

#include "IntegratorsInternal.h"

namespace fibremss {
namespace {

/// Over-relaxation of the averaged corrections (Macklin et al. 2014 suggest 1 ≤ ω ≤ 2).
constexpr btScalar kRelaxation = btScalar(1.5);

/// The passes' scratch and XPBD's Lagrange multipliers.
struct ProjectionWorkspace final : IntegratorWorkspace {
  std::vector<btScalar> lambda;        ///< XPBD: accumulated multiplier of each spring, reset
                                       ///< every iteration (empty for PBD)
  std::vector<btVector3> corrections;  ///< Σ of the pass's corrections of each particle
  std::vector<btScalar> weights;       ///< ω / (number of springs) of each particle (0: none)
};

/// Predicts x* = x + dt·v·(1 − c·dt/m)⁺ with v = (x − x(t−dt′))/dt′ (the damped Verlet
/// prediction without forces, clamped so strong damping cannot reverse the motion), then
/// projects the distance constraints C = |x_b − x_a| − L0 of the springs in `passes` Jacobi
/// passes: Δλ = (−C − α̃·λ)/(w_a + w_b + α̃), corrections −w_a·n·Δλ to a and +w_b·n·Δλ to b,
/// each particle moved by ω/(its spring count) × the sum of its corrections, with w = 1/m (0 for
/// fixed particles) and α̃ = 1/(k·dt²) for XPBD, 0 for PBD. The velocity of the next iteration
/// follows from x(t+dt) − x(t).
class PositionBasedIntegrator final : public TimeIntegrator {
 public:
  explicit PositionBasedIntegrator(bool compliant) : compliant_(compliant) {}

  IntegrationResult advance(const IntegratedMuscle& muscle, const MuscleSystemDef& def, btScalar dt,
                            btScalar previousDt) const override {
    const MuscleSettings& settings = muscle.settings;
    const btScalar inverseMass = 1 / settings.particleMass;
    const btScalar keep =
        std::max(btScalar(0), 1 - settings.damping * dt * inverseMass) * dt / previousDt;
    for (uint32_t i : muscle.particles.freeParticles) {
      const btVector3 x = muscle.particles.positions[i];
      muscle.particles.positions[i] += (x - muscle.particles.previous[i]) * keep;
      muscle.particles.previous[i] = x;
    }
    auto& w = static_cast<ProjectionWorkspace&>(*muscle.workspace);
    std::fill(w.lambda.begin(), w.lambda.end(), btScalar(0));
    btScalar* lambda = compliant_ ? w.lambda.data() : nullptr;
    const btScalar inverseDt2 = 1 / (dt * dt);
    const int passes = std::max(1, def.constraintIterations);
    for (int pass = 0; pass < passes; ++pass) {
      std::fill(w.corrections.begin(), w.corrections.end(), btVector3(0, 0, 0));
      for (size_t s = 0; s < settings.springs.size(); ++s) {
        const Spring& spring = settings.springs[s];
        const btScalar wa = settings.isFixed(spring.a) ? 0 : inverseMass;
        const btScalar wb = settings.isFixed(spring.b) ? 0 : inverseMass;
        const btVector3 d =
            muscle.particles.positions[spring.b] - muscle.particles.positions[spring.a];
        const btScalar length = d.length();
        const btScalar compliance = lambda ? inverseDt2 / spring.stiffness : 0;
        const btScalar denominator = wa + wb + compliance;
        if (!(length > 0) || !(denominator > 0)) continue;
        const btScalar current = lambda ? lambda[s] : 0;
        const btScalar delta = (spring.restLength - length - compliance * current) / denominator;
        if (lambda) lambda[s] += delta;
        const btVector3 move = d * (delta / length);
        w.corrections[spring.a] -= move * wa;
        w.corrections[spring.b] += move * wb;
      }
      for (uint32_t i : muscle.particles.freeParticles)
        muscle.particles.positions[i] += w.corrections[i] * w.weights[i];
    }
    IntegrationResult result;
    for (uint32_t i : muscle.particles.freeParticles)
      result.displacement +=
          (muscle.particles.positions[i] - muscle.particles.previous[i]).length();
    result.finite = std::isfinite(result.displacement);
    return result;
  }
  bool usesVelocities() const override { return false; }
  Integrator kind() const override { return compliant_ ? Integrator::Xpbd : Integrator::Pbd; }

 protected:
  std::unique_ptr<IntegratorWorkspace> makeWorkspace(const MuscleSettings& settings,
                                                     const ParticleState&) const override {
    auto w = std::make_unique<ProjectionWorkspace>();
    if (compliant_) w->lambda.assign(settings.springs.size(), 0);
    w->corrections.assign(settings.particleCount(), btVector3(0, 0, 0));
    w->weights.assign(settings.particleCount(), 0);
    for (const Spring& spring : settings.springs) {
      ++w->weights[spring.a];
      ++w->weights[spring.b];
    }
    for (btScalar& weight : w->weights) weight = weight > 0 ? kRelaxation / weight : 0;
    return w;
  }

 private:
  bool compliant_;  ///< XPBD (compliance 1/k) rather than PBD (rigid constraints)
};

const PositionBasedIntegrator pbd(false);
const PositionBasedIntegrator xpbd(true);
const IntegratorRegistration registrations[] = {{pbd, "pbd"}, {xpbd, "xpbd"}};

}  // namespace

}  // namespace fibremss
