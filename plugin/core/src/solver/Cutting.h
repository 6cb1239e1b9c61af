#pragma once
// Cutting (internal): a blade is a straight edge moved by a transform per step. After each kept
// step, the springs and local volume terms of every muscle whose segment (at the step's end)
// crosses the surface the edge swept in that step or the one before (from transform to
// transform, two triangles a step: the step before too, so that a segment the muscle's motion
// carried across the seam between two steps' sweeps is cut) are cut for good, as tearing breaks
// them (Tearing.h); the pieces are recounted.
// Particles are neither split nor removed: each lies on one side and goes with it.
// Sequential per muscle, in the muscles' order, with no allocation: the same bits for every
// thread count.
#include <LinearMath/btTransform.h>

namespace fibremss {

struct ParticleState;
struct TearState;

/// A blade as a step sees it.
struct BladeState {
  btVector3 from{0, 0, 0};                          ///< one end of its edge, blade frame [m]
  btVector3 to{0, 0, 0};                            ///< the other end, blade frame [m]
  btTransform before = btTransform::getIdentity();  ///< at the end of the step before last
  btTransform last = btTransform::getIdentity();    ///< at the end of the previous step
  btTransform target = btTransform::getIdentity();  ///< to reach at the end of this step
};

/// Cuts the springs and volume terms of a muscle (its `tear` prepared for tearing, its particles
/// at `muscle`'s positions) that cross the surface `blade` swept from its transform before last
/// through its last to its target, and recounts the muscle's pieces when something was cut.
/// Returns whether something was cut (the integrator's workspace must then follow).
bool cutBySweep(const ParticleState& muscle, TearState& tear, const BladeState& blade);

}  // namespace fibremss
