#pragma once
// FibreMSS muscles inside a Bullet world, the way Bullet adds soft bodies: a world class
// derived from btSoftRigidDynamicsWorld, so FibreMSS muscles, btSoftBody baselines and rigid
// bones share one world and one stepSimulation. Every internal Bullet step (after rigid and
// soft bodies moved) is one FibreMSS step; bones are collision objects whose world transform
// the muscles read at each step.
//
// timeStep: what Bullet's internal step (stepSimulation's fixedTimeStep) means to the muscles is
// WorldCoupling::time (fibremss/RigidContact.h). MuscleTime::QuasiStaticPose (the default, the
// thesis' mode): each internal Bullet step is one FibreMSS step, which moves the muscles from the
// bones' previous transforms to their current ones in up to StepSettings::iterations
// iterations of StepSettings::timeStep each (its own, simulated-time dt; see
// docs/integrators.md), so the muscles follow the bones' poses whatever Bullet's dt and a pose's
// cost does not depend on it; call stepSimulation(dt, 1, dt) to take exactly one FibreMSS step
// per call. MuscleTime::Dynamic: each internal Bullet step of dt advances the muscles by exactly
// dt of simulated time (MuscleSystem::step(duration)): one clock for muscles and rigid bodies.
//
// Two-way contact (WorldCoupling::rigidContact, on by default): the world's rigid bodies and
// collision objects that are not bones (a ball, a probe, a hand; dynamic, kinematic or static),
// found through the world's broadphase near the muscles, collide with the muscles' particle
// spheres; the muscles deform and dynamic bodies receive the reaction impulses after the
// muscles' step (Dynamic: exactly the momentum the particles lost; QuasiStaticPose: the muscles'
// static reaction, implicit, never throwing; docs/contact.md). contactWrench: the haptic query.
#include <BulletCollision/CollisionDispatch/btCollisionObject.h>
#include <BulletSoftBody/btSoftRigidDynamicsWorld.h>

#include <memory>
#include <span>
#include <vector>

#include "fibremss/MuscleSystem.h"
#include "fibremss/RigidContact.h"

namespace fibremss {

class RigidCoupling;

class MuscleWorld : public btSoftRigidDynamicsWorld {
 public:
  /// The Bullet arguments as for btSoftRigidDynamicsWorld (the configuration should be a
  /// btSoftBodyRigidBodyCollisionConfiguration when soft bodies are added); `def` defines the
  /// FibreMSS solver (its step settings: MuscleSystem::setStepSettings).
  MuscleWorld(btDispatcher* dispatcher, btBroadphaseInterface* broadphase,
              btConstraintSolver* solver, btCollisionConfiguration* configuration,
              const MuscleSystemDef& def = defaultMuscleSystemDef(),
              btSoftBodySolver* softSolver = nullptr);
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

  /// The solver: positions, surfaces, statistics of the last step, definition and step settings.
  MuscleSystem& muscleSystem() { return muscles_; }
  const MuscleSystem& muscleSystem() const { return muscles_; }

  /// FibreMSS steps taken so far: one per internal Bullet step.
  long muscleSteps() const { return muscleSteps_; }

  /// How the muscles meet the world: the meaning of Bullet's dt, two-way contact with rigid
  /// bodies (fibremss/RigidContact.h). InputError for a reach that is not finite and ≥ 0.
  void setCoupling(const WorldCoupling& coupling);
  const WorldCoupling& coupling() const { return coupling_; }

  /// What `body` received from the muscles in the last FibreMSS step (MuscleSystem::bodyContact):
  /// impulse, angular impulse, mean force and torque, contacts. Zero for a body out of reach.
  BodyContact bodyContact(const btCollisionObject* body) const {
    return muscles_.bodyContact(body);
  }
  /// The haptic query (MuscleSystem::contactWrench) at the body's current world transform, or at
  /// `transform` (a tool's pose read from a device at 1 kHz, between the muscles' steps).
  ContactWrench contactWrench(const btCollisionObject& body) const {
    return muscles_.contactWrench(body, body.getWorldTransform());
  }
  ContactWrench contactWrench(const btCollisionObject& body, const btTransform& transform) const {
    return muscles_.contactWrench(body, transform);
  }

  /// What debugDrawWorld draws of the muscles (DebugDrawFlag bits; 0 draws nothing).
  void setMuscleDebugFlags(int flags) { muscleDebugFlags_ = flags; }
  int muscleDebugFlags() const { return muscleDebugFlags_; }

  /// Bullet's debug drawing, then the muscles' (particles, springs, fibres, bone spheres,
  /// contacts as muscleDebugFlags says) through the world's btIDebugDraw when its debug mode
  /// asks for wireframes, AABBs or normals (when Bullet draws its actions).
  void debugDrawWorld() override;

  /// Bullet's removal; a bone's body also stops being a bone (its muscles treat it as gone), a
  /// contact body stops being one, so deleting the body afterwards leaves no pointer to it.
  void removeCollisionObject(btCollisionObject* object) override;
  void removeRigidBody(btRigidBody* body) override;

 protected:
  /// Bullet's internal step (rigid and soft bodies, actions), then one FibreMSS step with the
  /// contact bodies in reach, then their reaction impulses.
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
  WorldCoupling coupling_;                                    ///< time meaning, rigid contact
  std::unique_ptr<RigidCoupling> rigid_;                      ///< contact bodies of the step
};

}  // namespace fibremss
