#pragma once
// A muscle's part of the state for rigid contact bodies and external forces (internal, one of
// MuscleState's parts): empty until a step has contact bodies, or a force is set.
#include <LinearMath/btMatrix3x3.h>
#include <LinearMath/btVector3.h>

#include <cstdint>
#include <vector>

namespace fibremss {

/// What one muscle gave one contact body in the running iteration.
struct BodyImpulse {
  btVector3 linear{0, 0, 0};   ///< impulse on the body [N·s]
  btVector3 angular{0, 0, 0};  ///< its moment about the body's centre of mass [N·m·s]
  uint32_t contacts = 0;       ///< particles that touched the body
  btVector3 support{0, 0, 0};  ///< the touching particles' net forces pressing into it [N]
  /// Σ k/3·n·nᵀ of the touching particles (k their springs' stiffness, n their normals) [N/m]
  btMatrix3x3 stiffness{0, 0, 0, 0, 0, 0, 0, 0, 0};
};

/// Contact bodies and external forces of one muscle.
struct InteractionState {
  /// Per contact body (MuscleSystem::setContactBodies order): this iteration's impulses, written
  /// only by the muscle's own task and summed in insertion order afterwards.
  std::vector<BodyImpulse> bodyImpulses;
  /// Per particle: Σ k/3 of its springs, the local stiffness of contactWrench's Hooke term [N/m].
  std::vector<btScalar> contactStiffness;
  /// Per particle: a force held on it, added to the spring forces (empty: none) [N].
  std::vector<btVector3> externalForces;
};

}  // namespace fibremss
