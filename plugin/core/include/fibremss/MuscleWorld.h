#pragma once
// FibreMSS muscles inside a Bullet world, the way Bullet adds soft bodies: a world class
// derived from btSoftRigidDynamicsWorld, so FibreMSS muscles, btSoftBody baselines and rigid
// bones share one world and one stepSimulation. Every internal Bullet step (after rigid and
// soft bodies moved) is one FibreMSS step; bones are collision objects whose world transform
// the muscles read at each step.
//
// timeStep: Bullet's internal step (stepSimulation's fixedTimeStep) is not FibreMSS's dt. The
// muscles run in the thesis' quasi-static pose mode: each internal Bullet step is one FibreMSS
// step, which moves the muscles from the bones' previous transforms to their current ones in
// up to SimulationParameters::iterations iterations of SimulationParameters::timeStep each (its
// own, simulated-time dt; see docs/integrators.md). So the muscles follow the bones' poses
// whatever Bullet's dt, and a pose's cost does not depend on it; call stepSimulation(dt, 1, dt)
// to take exactly one FibreMSS step per call.
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

  /// Makes `body` a bone of the muscles (arguments in MuscleSystem::addBone's order): its world
  /// transform maps the bone's rest coordinates to current ones (a kinematic btRigidBody, see
  /// BoneBody). The body is added to this world unless it already is in one. As with any Bullet
  /// object, remove it (removeBone, removeRigidBody or removeCollisionObject) before deleting it
  /// or the world. Throws InputError for null settings or body.
  BoneHandle addBone(std::shared_ptr<const BoneSettings> settings, btCollisionObject* body);
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
  /// contacts as muscleDebugFlags says) through the world's btIDebugDraw when its debug mode
  /// asks for wireframes, AABBs or normals (when Bullet draws its actions).
  void debugDrawWorld() override;

  /// Bullet's removal; a bone's body also stops being a bone (its muscles treat it as gone), so
  /// deleting the body afterwards leaves no pointer to it.
  void removeCollisionObject(btCollisionObject* object) override;
  void removeRigidBody(btRigidBody* body) override;

 protected:
  /// Bullet's internal step (rigid and soft bodies, actions), then one FibreMSS step.
  void internalSingleStepSimulation(btScalar timeStep) override;

 private:
  struct Bone {
    BoneHandle handle;        ///< the bone in muscles_
    btCollisionObject* body;  ///< its body in the world
    bool addedHere;           ///< addBone put the body into this world
  };
  /// Removes the bone whose body is `body` from the muscles and from bones_, if there is one.
  void forgetBoneBody(const btCollisionObject* body);

  MuscleSystem muscles_;                                      ///< the FibreMSS solver
  std::vector<Bone> bones_;                                   ///< bones added through this world
  int muscleDebugFlags_ = kDrawParticles | kDrawBoneSpheres;  ///< DebugDrawFlag bits
  long muscleSteps_ = 0;                                      ///< FibreMSS steps taken
};

}  // namespace fibremss
