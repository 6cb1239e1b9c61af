#pragma once
// FibreMSS muscles inside a Bullet world, the way Bullet adds soft bodies: a world class
// derived from btSoftRigidDynamicsWorld, so FibreMSS muscles, btSoftBody baselines and rigid
// bones share one world and one stepSimulation. Every internal Bullet step (after rigid and
// soft bodies moved) is one FibreMSS step; bones are collision objects whose world transform
// the muscles read at each step.
#include <BulletSoftBody/btSoftRigidDynamicsWorld.h>

#include <memory>
#include <span>
#include <vector>

#include "fibremss/MuscleSystem.h"

namespace fibremss {

class MuscleWorld : public btSoftRigidDynamicsWorld {
 public:
  /// The Bullet arguments as for btSoftRigidDynamicsWorld (the configuration should be a
  /// btSoftBodyRigidBodyCollisionConfiguration when soft bodies are added); `parameters`
  /// configure the FibreMSS solver.
  MuscleWorld(btDispatcher* dispatcher, btBroadphaseInterface* broadphase,
              btConstraintSolver* solver, btCollisionConfiguration* configuration,
              const SimulationParameters& parameters = {}, btSoftBodySolver* softSolver = nullptr);
  ~MuscleWorld() override;

  /// Makes `body` a bone of the muscles: its world transform maps the bone's rest coordinates
  /// to current ones (a kinematic btRigidBody, see BoneBody). The body is added to this world
  /// unless it already is in one. As with any Bullet object, remove it (removeBone) before
  /// deleting it or the world; remove the muscles attached to a bone before the bone.
  BoneHandle addBone(btCollisionObject* body, std::shared_ptr<const BoneSettings> settings);
  /// Removes the bone, and its body from this world when addBone added it there. Returns false
  /// for a handle that is not (or no longer) a bone here.
  bool removeBone(BoneHandle bone);

  /// Adds a muscle; `bones[i]` is the bone the settings call bone i (see MuscleSystem).
  MuscleHandle addMuscle(std::shared_ptr<const MuscleSettings> settings,
                         std::span<const BoneHandle> bones);
  /// Removes a muscle; returns false (and changes nothing) for a stale or unknown handle.
  bool removeMuscle(MuscleHandle muscle);
  bool containsMuscle(MuscleHandle muscle) const { return muscles_.contains(muscle); }

  /// The solver: positions, surfaces, statistics of the last step, parameters.
  MuscleSystem& muscleSystem() { return muscles_; }
  const MuscleSystem& muscleSystem() const { return muscles_; }

  /// FibreMSS steps taken so far: one per internal Bullet step.
  long muscleSteps() const { return muscleSteps_; }

  /// What debugDrawWorld draws of the muscles (DebugDrawFlag bits; 0 draws nothing).
  void setMuscleDebugFlags(int flags) { muscleDebugFlags_ = flags; }
  int muscleDebugFlags() const { return muscleDebugFlags_; }

  /// Bullet's debug drawing, then the muscles' (particles, springs, fibres, bone spheres,
  /// contacts as muscleDebugFlags says) through the world's btIDebugDraw.
  void debugDrawWorld() override;

 protected:
  /// Bullet's internal step (rigid and soft bodies, actions), then one FibreMSS step.
  void internalSingleStepSimulation(btScalar timeStep) override;

 private:
  struct Bone {
    BoneHandle handle;        ///< the bone in muscles_
    btCollisionObject* body;  ///< its body in the world
    bool addedHere;           ///< addBone put the body into this world
  };
  MuscleSystem muscles_;                                      ///< the FibreMSS solver
  std::vector<Bone> bones_;                                   ///< bones added through this world
  int muscleDebugFlags_ = kDrawParticles | kDrawBoneSpheres;  ///< DebugDrawFlag bits
  long muscleSteps_ = 0;                                      ///< FibreMSS steps taken
};

}  // namespace fibremss
