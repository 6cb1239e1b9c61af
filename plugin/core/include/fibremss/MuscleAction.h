#pragma once
// FibreMSS muscles for applications that keep their own world class: a btActionInterface
// that owns a MuscleSystem and steps it once per internal Bullet step
// (world->addAction(&action)). Bones are added to the system with their collision objects;
// remove a bone from the system (muscleSystem().removeBone) before removing or deleting its
// body, which this action cannot see.
//
// timeStep and contact: as in MuscleWorld (WorldCoupling, fibremss/RigidContact.h). In the
// default quasi-static pose mode updateAction's timeStep (Bullet's internal step) is not
// FibreMSS's dt: each call is one FibreMSS step that moves the muscles to the bones' current poses
// in iterations of StepSettings::timeStep (simulated time); in MuscleTime::Dynamic each
// call advances the muscles by exactly timeStep. The world's other rigid bodies collide with the
// muscles and dynamic ones receive the reaction impulses.
#include <BulletDynamics/Dynamics/btActionInterface.h>

#include <memory>

#include "fibremss/MuscleSystem.h"
#include "fibremss/RigidContact.h"

namespace fibremss {

class RigidCoupling;

class MuscleAction : public btActionInterface {
 public:
  explicit MuscleAction(const MuscleSystemDef& def = defaultMuscleSystemDef());
  ~MuscleAction() override;

  /// One FibreMSS step (Bullet calls it once per internal step, after rigid bodies moved), with
  /// `timeStep` as coupling().time says (see the top of this header).
  void updateAction(btCollisionWorld* world, btScalar timeStep) override;
  /// Draws the muscles as debugFlags says (Bullet calls it from debugDrawWorld when the
  /// drawer's mode includes wireframe, AABBs or normals).
  void debugDraw(btIDebugDraw* drawer) override;

  /// The solver: add bones and muscles, read positions and statistics.
  MuscleSystem& muscleSystem() { return muscles_; }
  const MuscleSystem& muscleSystem() const { return muscles_; }

  /// The meaning of Bullet's dt and two-way contact, as MuscleWorld::setCoupling. Contact bodies
  /// that leave the world must leave the action too: call forgetBody before deleting one.
  void setCoupling(const WorldCoupling& coupling);
  const WorldCoupling& coupling() const { return coupling_; }
  /// Stops treating `body` as a contact body (it is leaving the world).
  void forgetBody(const btCollisionObject* body);

  /// What debugDraw draws (DebugDrawFlag bits; 0 draws nothing).
  void setDebugFlags(int flags) { debugFlags_ = flags; }
  int debugFlags() const { return debugFlags_; }

 private:
  MuscleSystem muscles_;                                ///< the FibreMSS solver
  int debugFlags_ = kDrawParticles | kDrawBoneSpheres;  ///< DebugDrawFlag bits
  WorldCoupling coupling_;                              ///< time meaning, rigid contact
  std::unique_ptr<RigidCoupling> rigid_;                ///< contact bodies of the step
};

}  // namespace fibremss
