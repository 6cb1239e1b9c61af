#pragma once
// The coupling of a MuscleSystem to a Bullet world (internal; MuscleWorld and MuscleAction):
// each internal Bullet step, find the contact bodies through the world's broadphase, step the
// muscles as WorldCoupling::time says, and apply the reaction impulses to dynamic bodies.
#include <BulletCollision/BroadphaseCollision/btDbvt.h>

#include <vector>

#include "fibremss/MuscleSystem.h"
#include "fibremss/RigidContact.h"

class btCollisionWorld;
class btCollisionObject;

namespace fibremss {

class RigidCoupling {
 public:
  /// One FibreMSS step for Bullet's internal step `timeStep` [s]: gather, (pose step: hold back
  /// a dynamic body that passed more than half a particle radius into the muscles) step, apply.
  void step(btCollisionWorld& world, MuscleSystem& muscles, const WorldCoupling& coupling,
            btScalar timeStep);
  /// Forgets `object` as a contact body (it is leaving the world).
  void forget(const btCollisionObject* object, MuscleSystem& muscles);

 private:
  /// The world's rigid bodies and collision objects that are not bones, whose broadphase bounds
  /// lie within coupling.reach of the muscles' bounds and whose filters accept the muscles'
  /// (btDbvtBroadphase: its trees; other broadphases: every object's bounds), in the world's
  /// order. No allocation once the list has grown to the bodies in reach.
  void gather(btCollisionWorld& world, MuscleSystem& muscles, const WorldCoupling& coupling);
  /// Before a pose step of Bullet's `timeStep` [s]: moves every dynamic contact body that
  /// Bullet's step took deeper than half a particle radius into the muscles (beyond where it
  /// started) back along its path to that depth, so that it cannot pass a particle sphere in one
  /// step (continuous contact for a body the pose step holds still).
  void holdBack(const MuscleSystem& muscles, btScalar timeStep) const;
  /// Applies what every dynamic contact body received, scaled by `scale`. After a pose step of
  /// Bullet's `poseStep` > 0 [s] (MuscleTime::QuasiStaticPose) the muscles' static reaction,
  /// implicit over the next step, and the scaled angular impulse, at most what the pose change
  /// can supply (a body is stopped, held and carried, never thrown); after a duration step
  /// (poseStep 0) all of it, and the body takes the pose the step's iterations moved it to.
  void apply(const MuscleSystem& muscles, btScalar scale, btScalar poseStep) const;

  std::vector<const btCollisionObject*> bodies_;  ///< contact bodies of the running step
  btNodeStack stack_;                             ///< traversal stack of the broadphase query
};

/// Checks a WorldCoupling; InputError naming `call` for a reach that is not finite and ≥ 0.
void checkCoupling(const WorldCoupling& coupling, const char* call);

}  // namespace fibremss
