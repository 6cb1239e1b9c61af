#pragma once
// Two-way contact of muscles with rigid bodies (internal; fibremss/RigidContact.h says what it
// does): the bodies of one step, the per-muscle contact stage of an iteration, the Hooke term of
// contactWrench, and external forces on particles.
#include <BulletCollision/BroadphaseCollision/btDbvt.h>
#include <LinearMath/btMatrix3x3.h>
#include <LinearMath/btTransform.h>

#include <span>

#include "fibremss/RigidContact.h"
#include "state/MuscleState.h"

class btCollisionObject;
class btCollisionShape;

namespace fibremss {

/// A contact body as one step sees it: read at the step's start, its pose held through the step,
/// its velocities updated with every iteration's impulses (a dynamic btRigidBody's; others have
/// no inverse mass and keep theirs).
struct ContactBodyState {
  const btCollisionObject* body = nullptr;                  ///< the body (shape and transform)
  btTransform transform = btTransform::getIdentity();       ///< its pose in this step
  btDbvtVolume bounds;                                      ///< its shape's AABB at that pose [m]
  btVector3 centre{0, 0, 0};                                ///< centre of mass [m]
  btVector3 linear{0, 0, 0};                                ///< linear velocity [m/s]
  btVector3 angular{0, 0, 0};                               ///< angular velocity [rad/s]
  btScalar inverseMass = 0;                                 ///< 0: kinematic or static [1/kg]
  btMatrix3x3 inverseInertia = btMatrix3x3::getIdentity();  ///< world frame [1/(kg·m²)]
  bool touchable = false;  ///< its shape is one ShapeContact handles
  /// Σ of the step's impulses so far (contacts, support, stiffness: the last iteration's)
  BodyImpulse total;
};

/// The body's state at the start of a step (`body` must outlive the step), at its current pose.
ContactBodyState readContactBody(const btCollisionObject& body);

/// Moves the body by its velocities over `time` [s] (negative: back), bounds too. A duration step
/// starts its bodies `duration` back from where Bullet put them and moves them on every
/// iteration, so that they sweep through the muscles as fast as they move, not in one jump.
void moveContactBody(ContactBodyState& body, btScalar time);

/// Sizes the muscle's interaction state for `bodies` contact bodies (and its contact stiffness
/// when it has none yet); allocates only when they change.
void prepareInteraction(const MuscleSettings& settings, InteractionState& interaction,
                        size_t bodies);

/// The contact stage of one iteration of one muscle (after the collision response): every free
/// boundary particle overlapping a body is moved out of it and loses its velocity into the body
/// relative to the body's surface; what it lost (m·Δv over the iteration's `dt`) goes into
/// interaction.bodyImpulses, negated, with its moment. Then its velocity along the contact normal
/// is damped by `damping` times the muscle's damping coefficient (MuscleSystemDef::contactDamping),
/// and it is marked pushed (contact.pushedLast: the projective solver holds it, as a bone's
/// push). `stack` owns the traversal stack.
void collideBodies(const MuscleSettings& settings, const TreeState& trees, ParticleState& particles,
                   ContactState& contact, InteractionState& interaction,
                   std::span<const ContactBodyState> bodies, btScalar dt, bool hasVelocities,
                   btScalar damping, TreeTraversalStack& stack);

/// Adds the Hooke term of contactWrench for one muscle: every free boundary particle sphere the
/// body's shape overlaps at `transform` pushes it with contactStiffness·depth along the contact
/// normal (its moment about `centre`).
void addHookeWrench(const CollidingMuscle& muscle, const InteractionState& interaction,
                    const btCollisionObject& body, const btTransform& transform,
                    const btVector3& centre, TreeTraversalStack& stack, ContactWrench& wrench);

/// The deepest overlap of `shape` placed at `transform` with a free boundary particle sphere of
/// the muscle, a share of that particle's radius [1] (0: none).
btScalar deepestOverlap(const CollidingMuscle& muscle, const btCollisionShape& shape,
                        const btTransform& transform, TreeTraversalStack& stack);

/// Adds m·gravity and the muscle's external forces (interaction.externalForces) to `forces` of its
/// free particles.
void addExternalForces(const MuscleSettings& settings, const ParticleState& particles,
                       const InteractionState& interaction, const btVector3& gravity,
                       std::span<btVector3> forces);

}  // namespace fibremss
