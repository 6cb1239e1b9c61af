#include "MuscleSystemChecks.h"

#include <cmath>
#include <sstream>

#include "fibremss/Error.h"

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

void checkStepParameters(const SimulationParameters& parameters, const char* call) {
  if (!(parameters.timeStep > 0) || !std::isfinite(parameters.timeStep))
    throw InputError(call, "SimulationParameters::timeStep",
                     "expected a finite dt > 0 [s], got " + format(parameters.timeStep));
  if (parameters.adaptiveTimeStep &&
      (!(parameters.minTimeStep > 0) || !std::isfinite(parameters.minTimeStep)))
    throw InputError(call, "SimulationParameters::minTimeStep",
                     "expected a finite lower clamp > 0 [s] with the adaptive dt, got " +
                         format(parameters.minTimeStep));
  if (parameters.iterations < 1)
    throw InputError(
        call, "SimulationParameters::iterations",
        "expected at least 1 iteration per step, got " + std::to_string(parameters.iterations));
  if (!(parameters.initialNoise >= 0) || !(parameters.initialNoise <= kMaxCoordinate))
    throw InputError(
        call, "SimulationParameters::initialNoise",
        "expected a displacement in [0, 1e6] m, got " + format(parameters.initialNoise));
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

bool finiteTransform(const btTransform& transform) {
  const btMatrix3x3& basis = transform.getBasis();
  for (int row = 0; row < 3; ++row)
    if (!withinWorld(basis[row])) return false;
  return withinWorld(transform.getOrigin());
}

}  // namespace fibremss
