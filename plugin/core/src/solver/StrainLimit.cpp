#include "StrainLimit.h"

#include <cmath>

#include "MuscleState.h"

namespace fibremss {
namespace {

/// A shortened spring ends this share of its limit inside it [1]: far beyond float rounding, so
/// that the next pass does not find it beyond again.
constexpr btScalar kInside = btScalar(1e-5);

/// One pass over the springs in order; returns the springs it shortened.
size_t projectionPass(const MuscleSettings& settings, btScalar limit, btVector3* x) {
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
      x[spring.b] -= excess;
    } else if (fixedB) {
      x[spring.a] += excess;
    } else {
      x[spring.a] += excess * btScalar(0.5);
      x[spring.b] -= excess * btScalar(0.5);
    }
    ++shortened;
  }
  return shortened;
}

}  // namespace

size_t limitStrain(MuscleState& muscle) {
  const MuscleSettings& settings = *muscle.settings;
  if (!(settings.strainLimit > 0)) return 0;
  size_t shortened = 0;
  for (int pass = 0; pass < kStrainLimitPasses; ++pass) {
    const size_t count = projectionPass(settings, settings.strainLimit, muscle.positions.data());
    if (count == 0) break;
    shortened += count;
  }
  return shortened;
}

double freeDisplacement(const MuscleState& muscle) {
  double sum = 0;
  for (uint32_t i : muscle.freeParticles)
    sum += (muscle.positions[i] - muscle.previous[i]).length();
  return sum;
}

}  // namespace fibremss
