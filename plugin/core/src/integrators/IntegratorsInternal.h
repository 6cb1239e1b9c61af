#pragma once
// The integrator families (internal to Integrators*.cpp): each returns its shared instance for a
// kind it implements, or null.
#include "Integrators.h"

namespace fibremss {

/// The heavy-ball step of free particle i: x⁺ = x + (x − x⁻)·keep + push·scale, x⁻ ← x (Verlet's
/// scalar path, the projective step). Returns |x⁺ − x| [m].
inline btScalar heavyBallStep(MuscleState& muscle, uint32_t i, const btVector3& push, btScalar keep,
                              btScalar scale) {
  const btVector3 x = muscle.positions[i];
  const btVector3 step = (x - muscle.previous[i]) * keep + push * scale;
  muscle.previous[i] = x;
  muscle.positions[i] = x + step;
  return step.length();
}

/// Verlet, semi-implicit Euler, explicit Euler, RK2, RK4 (IntegratorsExplicit.cpp).
const TimeIntegrator* explicitIntegratorFor(Integrator kind);
/// Implicit Euler, implicit midpoint, BDF2 (IntegratorsImplicit.cpp).
const TimeIntegrator* implicitIntegratorFor(Integrator kind);
/// PBD, XPBD (IntegratorsPositionBased.cpp).
const TimeIntegrator* positionBasedIntegratorFor(Integrator kind);
/// Projective dynamics' local/global step (IntegratorsProjective.cpp).
const TimeIntegrator* projectiveIntegratorFor(Integrator kind);

}  // namespace fibremss
