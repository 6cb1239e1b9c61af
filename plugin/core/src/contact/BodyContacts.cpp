#include "BodyContacts.h"

#include <BulletCollision/CollisionDispatch/btCollisionObject.h>
#include <BulletCollision/CollisionShapes/btCollisionShape.h>
#include <BulletDynamics/Dynamics/btRigidBody.h>
#include <LinearMath/btTransformUtil.h>

#include <algorithm>

#include "ShapeContact.h"

namespace fibremss {
namespace {

/// Calls onLeaf(particle) for every leaf of the muscle's tree whose bounds overlap `box`.
template <typename OnLeaf>
void forLeavesIn(const SphereTree& tree, const btDbvtVolume& box, TreeTraversalStack& stack,
                 OnLeaf&& onLeaf) {
  if (tree.empty()) return;
  stack.clear();
  stack.push_back({0, -1});
  while (!stack.empty()) {
    const int32_t n = stack.back().first;
    stack.pop_back();
    if (!boundsOverlap(tree.bounds(n), box)) continue;
    const SphereTree::Node& node = tree.node(n);
    if (node.sphere >= 0) {
      onLeaf(static_cast<uint32_t>(node.sphere));
    } else {
      stack.push_back({node.children[0], -1});
      stack.push_back({node.children[1], -1});
    }
  }
}

/// `box` grown by `margin` on every side.
btDbvtVolume grown(const btDbvtVolume& box, btScalar margin) {
  const btVector3 m(margin, margin, margin);
  return btDbvtVolume::FromMM(box.Mins() - m, box.Maxs() + m);
}

/// How far a particle may have left its leaf's bounds since the tree's refit: the collision
/// response's pushes, at most about two radii.
btScalar leafSlack(const ParticleState& particles) {
  return 2 * particles.meanRadius;
}

/// The share of a touching particle's velocity along the contact normal that contact damping
/// c' = `damping` × the muscle's c takes in an iteration of `dt` [1]: implicit, c'·dt/m over
/// 1 + c'·dt/m.
btScalar dampedShare(const MuscleSettings& settings, btScalar damping, btScalar dt) {
  const btScalar rate = damping * settings.damping * dt / settings.particleMass;
  return rate / (1 + rate);
}

/// The response of particle i (of `mass` [kg]) to `contact` with `body`, its velocity along the
/// normal then damped by the share `damped`; returns the impulse the particle received [N·s].
btVector3 respond(btScalar mass, ParticleState& particles, uint32_t i, const ContactBodyState& body,
                  const ShapeContact& contact, btScalar dt, bool hasVelocities, btScalar damped) {
  const btVector3& n = contact.normal;
  const btVector3 surface = body.linear + body.angular.cross(contact.point - body.centre);
  btVector3 moved = particles.positions[i] - particles.previous[i];
  const btScalar approach = (moved - surface * dt).dot(n);
  if (approach < 0) moved -= n * approach;
  btVector3 impulse = n * (approach < 0 ? -mass * approach / dt : btScalar(0));
  if (hasVelocities) {
    btVector3& v = particles.velocities[i];
    const btScalar into = (v - surface).dot(n);
    impulse = n * (into < 0 ? -mass * into : btScalar(0));
    if (into < 0) v -= n * into;
    v -= n * (v.dot(n) * damped);
  }
  moved -= n * (moved.dot(n) * damped);
  particles.positions[i] += n * contact.depth;
  particles.previous[i] = particles.positions[i] - moved;
  return impulse;
}

/// Adds what touching particle i holds of a body to `sum`: the part of its net force that presses
/// into the body along the contact normal `n` (none pulls), and k/3·n·nᵀ.
void addSupport(const ParticleState& particles, const InteractionState& interaction, uint32_t i,
                const btVector3& n, BodyImpulse& sum) {
  sum.support -= n * std::max<btScalar>(-particles.forces[i].dot(n), 0);
  const btVector3 kn = n * interaction.contactStiffness[i];
  sum.stiffness += btMatrix3x3(kn * n.x(), kn * n.y(), kn * n.z());
}

/// Calls onContact(i, contact) for every free boundary particle of `muscle` whose sphere
/// overlaps `shape` placed at `transform` (none for a shape ShapeContact does not handle).
template <typename OnContact>
void forShapeContacts(const CollidingMuscle& muscle, const btCollisionShape& shape,
                      const btTransform& transform, TreeTraversalStack& stack,
                      OnContact&& onContact) {
  const SphereTree& tree = muscle.trees.tree;
  if (!touchableShape(shape) || tree.empty()) return;
  btVector3 lower, upper;
  shape.getAabb(transform, lower, upper);
  const btDbvtVolume box = grown(btDbvtVolume::FromMM(lower, upper), leafSlack(muscle.particles));
  if (!boundsOverlap(tree.bounds(0), box)) return;
  const MuscleSettings& settings = muscle.settings;
  const std::vector<btVector3>& positions = muscle.particles.positions;
  forLeavesIn(tree, box, stack, [&](uint32_t i) {
    ShapeContact contact;
    if (!settings.isFixed(i) &&
        sphereShapeContact(shape, transform, positions[i], settings.radii[i], contact))
      onContact(i, contact);
  });
}

/// Places the body at `transform`: its centre of mass and bounds follow.
void placeContactBody(ContactBodyState& state, const btTransform& transform) {
  state.transform = transform;
  // A btRigidBody's world transform is its centre of mass's.
  state.centre = transform.getOrigin();
  if (!state.touchable) return;
  btVector3 lower, upper;
  state.body->getCollisionShape()->getAabb(transform, lower, upper);
  state.bounds = btDbvtVolume::FromMM(lower, upper);
}

}  // namespace

ContactBodyState readContactBody(const btCollisionObject& body) {
  ContactBodyState state;
  state.body = &body;
  const btCollisionShape* shape = body.getCollisionShape();
  state.touchable = shape && touchableShape(*shape);
  placeContactBody(state, body.getWorldTransform());
  if (const btRigidBody* rigid = btRigidBody::upcast(&body)) {
    state.linear = rigid->getLinearVelocity();
    state.angular = rigid->getAngularVelocity();
    if (!rigid->isStaticOrKinematicObject()) {
      state.inverseMass = rigid->getInvMass();
      state.inverseInertia = rigid->getInvInertiaTensorWorld();
    }
  }
  return state;
}

void moveContactBody(ContactBodyState& body, btScalar time) {
  if (body.linear.isZero() && body.angular.isZero()) return;
  btTransform moved;
  btTransformUtil::integrateTransform(body.transform, body.linear, body.angular, time, moved);
  placeContactBody(body, moved);
}

void prepareInteraction(const MuscleSettings& settings, InteractionState& interaction,
                        size_t bodies) {
  if (interaction.bodyImpulses.size() != bodies) interaction.bodyImpulses.resize(bodies);
  if (bodies == 0 || interaction.contactStiffness.size() == settings.particleCount()) return;
  interaction.contactStiffness.assign(settings.particleCount(), 0);
  for (const Spring& spring : settings.springs) {
    interaction.contactStiffness[spring.a] += spring.stiffness / 3;
    interaction.contactStiffness[spring.b] += spring.stiffness / 3;
  }
}

void collideBodies(const MuscleSettings& settings, const TreeState& trees, ParticleState& particles,
                   ContactState& contact, InteractionState& interaction,
                   std::span<const ContactBodyState> bodies, btScalar dt, bool hasVelocities,
                   btScalar damping, TreeTraversalStack& stack) {
  const SphereTree& tree = trees.tree;
  const btScalar damped = dampedShare(settings, damping, dt);
  for (size_t k = 0; k < bodies.size(); ++k) {
    BodyImpulse& sum = interaction.bodyImpulses[k];
    sum = BodyImpulse{};
    const ContactBodyState& body = bodies[k];
    if (!body.touchable || tree.empty()) continue;
    const btDbvtVolume box = grown(body.bounds, leafSlack(particles));
    if (!boundsOverlap(tree.bounds(0), box)) continue;
    const btCollisionShape& shape = *body.body->getCollisionShape();
    forLeavesIn(tree, box, stack, [&](uint32_t i) {
      if (settings.isFixed(i)) return;
      ShapeContact touch;
      if (!sphereShapeContact(shape, body.transform, particles.positions[i], settings.radii[i],
                              touch))
        return;
      const btVector3 impulse =
          respond(settings.particleMass, particles, i, body, touch, dt, hasVelocities, damped);
      contact.pushedLast[i] = 1;
      sum.linear -= impulse;
      sum.angular -= (touch.point - body.centre).cross(impulse);
      ++sum.contacts;
      addSupport(particles, interaction, i, touch.normal, sum);
    });
  }
}

void addHookeWrench(const CollidingMuscle& muscle, const InteractionState& interaction,
                    const btCollisionObject& body, const btTransform& transform,
                    const btVector3& centre, TreeTraversalStack& stack, ContactWrench& wrench) {
  const btCollisionShape* shape = body.getCollisionShape();
  const std::vector<btScalar>& stiffness = interaction.contactStiffness;
  if (!shape || stiffness.empty()) return;
  forShapeContacts(muscle, *shape, transform, stack, [&](uint32_t i, const ShapeContact& contact) {
    const btVector3 force = contact.normal * (-stiffness[i] * contact.depth);
    wrench.force += force;
    wrench.torque += (contact.point - centre).cross(force);
    ++wrench.contacts;
  });
}

btScalar deepestOverlap(const CollidingMuscle& muscle, const btCollisionShape& shape,
                        const btTransform& transform, TreeTraversalStack& stack) {
  btScalar deepest = 0;
  forShapeContacts(muscle, shape, transform, stack, [&](uint32_t i, const ShapeContact& contact) {
    deepest = std::max(deepest, contact.depth / muscle.settings.radii[i]);
  });
  return deepest;
}

void addExternalForces(const MuscleSettings& settings, const ParticleState& particles,
                       const InteractionState& interaction, const btVector3& gravity,
                       std::span<btVector3> forces) {
  const std::vector<btVector3>& external = interaction.externalForces;
  const bool held = !external.empty();
  if (!held && gravity.isZero()) return;
  const btVector3 weight = gravity * settings.particleMass;
  for (uint32_t i : particles.freeParticles) forces[i] += held ? weight + external[i] : weight;
}

}  // namespace fibremss
