#include "MuscleSystemChecks.h"

#include <cmath>
#include <sstream>

#include "fibremss/Error.h"
#include "kernels/VolumeForces.h"

namespace fibremss {
namespace {

std::string format(const btVector3& p) {
  std::ostringstream out;
  out << "(" << p.x() << ", " << p.y() << ", " << p.z() << ")";
  return out.str();
}

std::string format(btScalar value) {
  std::ostringstream out;
  out << value;
  return out.str();
}

}  // namespace

void checkStepSettings(const StepSettings& settings, const char* call) {
  if (!(settings.timeStep > 0) || !std::isfinite(settings.timeStep))
    throw InputError(call, "StepSettings::timeStep",
                     "expected a finite dt > 0 [s], got " + format(settings.timeStep));
  if (settings.adaptiveTimeStep &&
      (!(settings.minTimeStep > 0) || !std::isfinite(settings.minTimeStep)))
    throw InputError(call, "StepSettings::minTimeStep",
                     "expected a finite lower clamp > 0 [s] with the adaptive dt, got " +
                         format(settings.minTimeStep));
  if (settings.iterations < 1)
    throw InputError(
        call, "StepSettings::iterations",
        "expected at least 1 iteration per step, got " + std::to_string(settings.iterations));
}

void checkDefinition(const MuscleSystemDef& def, const char* call) {
  checkStepSettings(def.stepSettings, call);
  if (def.projectiveHistory < 0 || def.projectiveHistory > kMaxProjectiveHistory)
    throw InputError(call, "MuscleSystemDef::projectiveHistory",
                     "expected 0 to " + std::to_string(kMaxProjectiveHistory) + " pairs, got " +
                         std::to_string(def.projectiveHistory));
  if (!(def.initialNoise >= 0) || !(def.initialNoise <= kMaxCoordinate))
    throw InputError(call, "MuscleSystemDef::initialNoise",
                     "expected a displacement in [0, 1e6] m, got " + format(def.initialNoise));
  if (!(def.contactDamping >= 0) || !(def.contactDamping <= kMaxCoordinate))
    throw InputError(call, "MuscleSystemDef::contactDamping",
                     "expected a multiple in [0, 1e6], got " + format(def.contactDamping));
}

void checkPoints(std::span<const btVector3> points, const std::string& call,
                 const std::string& what) {
  for (size_t i = 0; i < points.size(); ++i)
    if (!withinWorld(points[i]))
      throw InputError(
          call, what + " " + std::to_string(i),
          "expected finite coordinates within 1e6 m of the origin, got " + format(points[i]));
}

void checkRadii(std::span<const btScalar> radii, const std::string& call) {
  for (size_t i = 0; i < radii.size(); ++i)
    if (!(radii[i] >= 0) || !(radii[i] <= kMaxCoordinate))
      throw InputError(call, "radius " + std::to_string(i),
                       "expected a finite radius in [0, 1e6] m, got " + format(radii[i]));
}

void checkFans(const MuscleSettings& settings, const std::string& call) {
  const std::string where = "muscle '" + settings.name + "' volume fans";
  const std::vector<uint32_t>& offsets = settings.fanOffsets;
  const size_t fans = settings.fanInverseVolume.size();
  if (settings.fanRestGradient.size() != fans || offsets.size() != fans + 1 || offsets[0] != 0 ||
      offsets.back() != settings.fanParticles.size())
    throw InputError(call, where,
                     "expected fanOffsets from 0 to fanParticles' size, one entry more than the " +
                         std::to_string(fans) + " of fanInverseVolume and fanRestGradient");
  for (size_t k = 0; k < fans; ++k) {
    const size_t count = offsets[k + 1] >= offsets[k] ? offsets[k + 1] - offsets[k] : 0;
    const size_t least = k > 0 ? offsets[k] - offsets[k - 1] : 4;
    if (count < least || count > kMaxFanTetrahedra + 3)
      throw InputError(call, where + ", fan " + std::to_string(k),
                       "expected 4 to " + std::to_string(kMaxFanTetrahedra + 3) +
                           " particles, no fewer than the fan before, got " +
                           std::to_string(count));
  }
  for (uint32_t i : settings.fanParticles)
    if (i >= settings.particleCount())
      throw InputError(call, where,
                       "expected particle indices below " +
                           std::to_string(settings.particleCount()) + ", got " + std::to_string(i));
}

bool finiteTransform(const btTransform& transform) {
  const btMatrix3x3& basis = transform.getBasis();
  for (int row = 0; row < 3; ++row)
    if (!withinWorld(basis[row])) return false;
  return withinWorld(transform.getOrigin());
}

}  // namespace fibremss
