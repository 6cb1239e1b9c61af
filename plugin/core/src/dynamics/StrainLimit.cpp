#include "StrainLimit.h"

#include <cmath>

#include "state/MuscleState.h"

namespace fibremss {
namespace {

/// A shortened spring ends this share of its limit inside it [1]: far beyond float rounding, so
/// that the next pass does not find it beyond again.
constexpr btScalar kInside = btScalar(1e-5);

/// One pass over the springs in order; returns the springs it shortened. A particle it moves is
/// marked pushed (pushedLast): the projective solver holds it as a contact's (W, its preconditioner
/// only) and leaves it out of the L-BFGS pairs, as a projection's move is no answer of the forces
/// (with it in, real-hip took 1.7× the time per iteration).
size_t projectionPass(const MuscleSettings& settings, ParticleState& particles,
                      ContactState& contact, btScalar limit) {
  btVector3* x = particles.positions.data();
  const auto move = [&](uint32_t i, const btVector3& by) {
    x[i] += by;
    contact.pushedLast[i] = 1;
  };
  size_t shortened = 0;
  for (const Spring& spring : settings.springs) {
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

}  // namespace

size_t limitStrain(const MuscleSettings& settings, ParticleState& particles, ContactState& contact,
                   int passes) {
  if (!(settings.strainLimit > 0)) return 0;
  size_t shortened = 0;
  for (int pass = 0; pass < passes; ++pass) {
    const size_t count = projectionPass(settings, particles, contact, settings.strainLimit);
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
