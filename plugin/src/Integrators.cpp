#include "Integrators.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace fibremss {
namespace {

/// Verlet with velocity damping (method.md §4), time-corrected for a changing dt:
/// x(t+dt) = x(t) + v·dt + dt²/m·(F − c·v) with v = (x(t) − x(t−dt′))/dt′ (dt′ the previous
/// step). With a fixed dt this is the thesis' x(t+dt) = 2x(t) − x(t−dt) + dt²/m·(F − c·v);
/// without the correction, a shrinking adaptive dt would raise the velocity and pump energy in.
class VerletIntegrator final : public TimeIntegrator {
 public:
  IntegrationResult advance(MuscleState& muscle, btScalar dt, btScalar previousDt) const override {
    const MuscleSettings& settings = *muscle.settings;
    const btScalar forceScale = dt * dt / settings.particleMass;
    const btScalar keep = (1 - settings.damping * dt / settings.particleMass) * dt / previousDt;
    IntegrationResult result;
    for (uint32_t i : muscle.freeParticles) {
      const btVector3 x = muscle.positions[i];
      const btVector3 step = (x - muscle.previous[i]) * keep + muscle.forces[i] * forceScale;
      muscle.previous[i] = x;
      muscle.positions[i] = x + step;
      result.displacement += step.length();
    }
    result.finite = std::isfinite(result.displacement);
    return result;
  }
  bool usesVelocities() const override { return false; }
  Integrator kind() const override { return Integrator::Verlet; }
};

/// Semi-implicit (symplectic) Euler: v += dt/m·(F − c·v); x += dt·v.
class SemiImplicitEulerIntegrator final : public TimeIntegrator {
 public:
  IntegrationResult advance(MuscleState& muscle, btScalar dt, btScalar) const override {
    const MuscleSettings& settings = *muscle.settings;
    const btScalar inverseMass = 1 / settings.particleMass;
    IntegrationResult result;
    for (uint32_t i : muscle.freeParticles) {
      btVector3& v = muscle.velocities[i];
      v += (muscle.forces[i] - v * settings.damping) * (dt * inverseMass);
      const btVector3 step = v * dt;
      muscle.previous[i] = muscle.positions[i];
      muscle.positions[i] += step;
      result.displacement += step.length();
    }
    result.finite = std::isfinite(result.displacement);
    return result;
  }
  bool usesVelocities() const override { return true; }
  Integrator kind() const override { return Integrator::SemiImplicitEuler; }
};

}  // namespace

const TimeIntegrator& integratorFor(Integrator kind) {
  static const VerletIntegrator verlet;
  static const SemiImplicitEulerIntegrator semiImplicitEuler;
  switch (kind) {
    case Integrator::SemiImplicitEuler:
      return semiImplicitEuler;
    case Integrator::Verlet:
      return verlet;
    default:
      break;
  }
  throw std::invalid_argument(std::string("integrator not available yet: ") + toString(kind));
}

}  // namespace fibremss
