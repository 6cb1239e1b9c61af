#pragma once
// Two-way contact between muscles and rigid bodies (seed 003 ch. 5, the local
// interaction model): a rigid body (a ball, a probe, a hand) collides with the muscles' boundary
// particle spheres, the muscles deform, and the body receives the reaction as impulses, equal and
// opposite to the momentum the particles gain (docs/contact.md).
//
// Per iteration of a muscle step, every free boundary particle whose sphere overlaps a contact
// body's shape is moved out of it by the whole overlap (the body holds its pose during the step,
// like a bone) and loses its velocity into the body relative to the body's surface (inelastic,
// frictionless); the momentum it loses, m·Δv, is the impulse the body receives, and a dynamic
// body's velocity takes it at once (so it slows within the step). Its velocity along the normal
// is then damped (MuscleSystemDef::contactDamping), so that a body landing on a muscle loses its
// impact. Fixed particles do not touch bodies (the bone they sit on collides with them in Bullet).
#include <LinearMath/btMatrix3x3.h>
#include <LinearMath/btScalar.h>
#include <LinearMath/btTransform.h>
#include <LinearMath/btVector3.h>

#include <cstddef>
#include <cstdint>

namespace fibremss {

/// What Bullet's time step means to the muscles (MuscleWorld, MuscleAction).
enum class MuscleTime : uint8_t {
  /// Each internal Bullet step is one FibreMSS step to the bones' current poses in iterations of
  /// StepSettings::timeStep (the muscles' own simulated time): the thesis' pose mode.
  /// A dynamic contact body receives the muscles' static reaction (BodyContact::support),
  /// implicit over Bullet's next step, at most what the pose change can supply, and is held back
  /// when Bullet's step moved it more than half a particle radius into the muscles.
  QuasiStaticPose,
  /// Each internal Bullet step of dt advances the muscles by exactly dt of simulated time in
  /// k = max(iterations, ⌈dt / min(timeStep, stable dt)⌉) iterations of dt/k (the stable dt of
  /// every muscle's springs and volume term; fixed, whatever the stop rule and adaptiveTimeStep
  /// say; bones move over all k): muscles and rigid bodies share one
  /// clock, and contact bodies receive exactly the impulses of the step (momentum conserved).
  /// Needs a time integrator (MuscleSystemDef::integrator = Verlet, say): the default,
  /// projective, solves each step's equilibrium and has no inertia.
  Dynamic,
};

/// How a MuscleWorld or MuscleAction couples its muscles to the world's rigid bodies.
struct WorldCoupling {
  MuscleTime time = MuscleTime::QuasiStaticPose;  ///< meaning of Bullet's dt to the muscles
  /// Collide muscles with the world's rigid bodies that are not bones (dynamic, kinematic and
  /// static ones whose broadphase filter accepts contactGroup/contactMask). With no such body
  /// in reach a step is bit-identical to one without contact.
  bool rigidContact = true;
  int contactGroup = 1;   ///< muscles' collision filter group (btBroadphaseProxy::DefaultFilter)
  int contactMask = -1;   ///< groups muscles collide with (btBroadphaseProxy::AllFilter)
  btScalar reach = 0.05;  ///< bodies this far beyond the muscles' bounds are candidates [m]
};

/// What one contact body received from the muscles in the last step (MuscleSystem::bodyContacts).
struct BodyContact {
  btVector3 impulse{0, 0, 0};         ///< linear impulse on the body, Σ over the step [N·s]
  btVector3 angularImpulse{0, 0, 0};  ///< about its centre of mass, Σ over the step [N·m·s]
  btVector3 force{0, 0, 0};           ///< impulse / the step's simulated time [N]
  btVector3 torque{0, 0, 0};          ///< angularImpulse / the step's simulated time [N·m]
  size_t contacts = 0;                ///< particle contacts in the step's last iteration
  /// The muscles' static reaction in the step's last iteration: the part of the touching
  /// particles' net forces (springs, volume, gravity) that presses into the body [N].
  btVector3 support{0, 0, 0};
  /// Σ k/3·n·nᵀ over the touching particles (k their springs' stiffness, n the contact normal):
  /// how the support grows as the body moves into them [N/m].
  btMatrix3x3 supportStiffness{0, 0, 0, 0, 0, 0, 0, 0, 0};
  /// Where the step's iterations moved the body: in a duration step (MuscleTime::Dynamic) a body
  /// sweeps through the muscles at its velocity, which each iteration's impulses change, from
  /// `duration` before its pose at the step's start; Bullet's body takes this pose with the
  /// impulses, so that its path is the one the muscles pushed against. Else its pose.
  btTransform transform = btTransform::getIdentity();
};

/// The force and torque (about the body's centre of mass) muscles exert on a body [N], [N·m].
struct ContactWrench {
  btVector3 force{0, 0, 0};   ///< [N]
  btVector3 torque{0, 0, 0};  ///< [N·m]
  size_t contacts = 0;        ///< particle spheres overlapping the body where it is now
};

}  // namespace fibremss
