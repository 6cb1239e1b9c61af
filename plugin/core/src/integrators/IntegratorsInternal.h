#pragma once
// What the integrator families share (internal to Integrators*.cpp).
#include "Integrators.h"

namespace fibremss {

/// The heavy-ball step of free particle i: x⁺ = x + (x − x⁻)·keep + push·scale, x⁻ ← x (Verlet's
/// scalar path, the projective step). Returns |x⁺ − x| [m].
inline btScalar heavyBallStep(ParticleState& particles, uint32_t i, const btVector3& push,
                              btScalar keep, btScalar scale) {
  const btVector3 x = particles.positions[i];
  const btVector3 step = (x - particles.previous[i]) * keep + push * scale;
  particles.previous[i] = x;
  particles.positions[i] = x + step;
  return step.length();
}

}  // namespace fibremss
