#pragma once
// Hand-made bones and attachments for the solver tests (collision_test, simulation_test).
#include <memory>
#include <utility>
#include <vector>

#include "fibremss/MuscleSettings.h"
#include "fibremss/Parameters.h"

namespace fibremss::testing {

/// The default definition with Verlet, the default time integrator, at its iteration count: for the
/// tests of time integration, the response's velocity rules and the guard's smaller steps (the
/// default solver of posed scenes, projective, has no dt).
inline MuscleSystemDef verletDef() {
  return defaultMuscleSystemDef(Integrator::Verlet);
}

/// A bone without spheres (attachments only) or with the given spheres (bone frame).
inline std::shared_ptr<BoneSettings> makeBone(std::vector<btVector3> centres = {},
                                              std::vector<btScalar> radii = {}) {
  auto bone = std::make_shared<BoneSettings>();
  bone->name = "bone";
  bone->sphereCentres = std::move(centres);
  bone->sphereRadii = std::move(radii);
  return bone;
}

/// Free boundary particles (spheres) at `points` with `radii`, no springs.
inline std::shared_ptr<MuscleSettings> makeSpheres(const std::vector<btVector3>& points,
                                                   const std::vector<btScalar>& radii,
                                                   btScalar mass = 1e-5) {
  auto muscle = std::make_shared<MuscleSettings>();
  muscle->name = "spheres";
  muscle->restPositions = points;
  muscle->radii = radii;
  muscle->flags.assign(points.size(), kBoundary);
  muscle->fixedBone.assign(points.size(), -1);
  muscle->nearestBone.assign(points.size(), -1);
  for (uint32_t i = 0; i < points.size(); ++i) muscle->boundaryParticles.push_back(i);
  muscle->particleMass = mass;
  return muscle;
}

/// Fixes `particle` of `muscle` to bone index `bone`.
inline void fix(MuscleSettings& muscle, uint32_t particle, int32_t bone) {
  muscle.flags[particle] |= kFixed;
  muscle.fixedBone[particle] = bone;
  muscle.fixedParticles.push_back(particle);
}

}  // namespace fibremss::testing
