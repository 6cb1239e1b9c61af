#pragma once
// FibreMSS muscles for applications that keep their own world class: a btActionInterface
// that owns a MuscleSystem and steps it once per internal Bullet step
// (world->addAction(&action)). Bones are added to the system with their collision objects;
// remove a bone from the system (muscleSystem().removeBone) before removing or deleting its
// body, which this action cannot see.
//
// timeStep: as in MuscleWorld, the quasi-static pose mode. updateAction's timeStep (Bullet's
// internal step) is not FibreMSS's dt: each call is one FibreMSS step that moves the muscles
// to the bones' current poses in iterations of SimulationParameters::timeStep (simulated time).
#include <BulletDynamics/Dynamics/btActionInterface.h>

#include "fibremss/MuscleSystem.h"

namespace fibremss {

class MuscleAction : public btActionInterface {
 public:
  explicit MuscleAction(const SimulationParameters& parameters = {}) : muscles_(parameters) {}

  /// One FibreMSS step (Bullet calls it once per internal step, after rigid bodies moved);
  /// `timeStep` is not used (see the top of this header).
  void updateAction(btCollisionWorld* world, btScalar timeStep) override;
  /// Draws the muscles as debugFlags says (Bullet calls it from debugDrawWorld when the
  /// drawer's mode includes wireframe, AABBs or normals).
  void debugDraw(btIDebugDraw* drawer) override;

  /// The solver: add bones and muscles, read positions and statistics.
  MuscleSystem& muscleSystem() { return muscles_; }
  const MuscleSystem& muscleSystem() const { return muscles_; }

  /// What debugDraw draws (DebugDrawFlag bits; 0 draws nothing).
  void setDebugFlags(int flags) { debugFlags_ = flags; }
  int debugFlags() const { return debugFlags_; }

 private:
  MuscleSystem muscles_;                                ///< the FibreMSS solver
  int debugFlags_ = kDrawParticles | kDrawBoneSpheres;  ///< DebugDrawFlag bits
};

}  // namespace fibremss
