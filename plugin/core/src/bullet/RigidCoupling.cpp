#include "RigidCoupling.h"

#include <BulletCollision/BroadphaseCollision/btDbvtBroadphase.h>
#include <BulletCollision/CollisionDispatch/btCollisionWorld.h>
#include <BulletDynamics/Dynamics/btRigidBody.h>
#include <LinearMath/btTransformUtil.h>

#include <algorithm>
#include <cmath>

#include "contact/BodyContacts.h"
#include "contact/ShapeContact.h"
#include "fibremss/Error.h"
#include "solver/MuscleSystemAccess.h"

namespace fibremss {
namespace {

/// How much deeper into a particle sphere than where it started a pose step lets Bullet's step
/// move a body, a share of the particle's radius [1]: it cannot pass a sphere in one step.
constexpr btScalar kPassShare = btScalar(0.5);
/// Halvings of a Bullet step's path that find how far a body may move along it [1].
constexpr int kPathHalvings = 10;

/// Whether the muscles collide with `object` (its broadphase proxy `proxy`): a rigid body or a
/// plain collision object that responds to contacts, not a bone, filters accepting both ways.
bool contactCandidate(const btCollisionObject& object, const btBroadphaseProxy& proxy,
                      const MuscleSystemAccess::Impl& impl, const WorldCoupling& coupling) {
  const int type = object.getInternalType();
  if ((type != btCollisionObject::CO_RIGID_BODY &&
       type != btCollisionObject::CO_COLLISION_OBJECT) ||
      !object.hasContactResponse())
    return false;
  if (!(proxy.m_collisionFilterGroup & coupling.contactMask) ||
      !(coupling.contactGroup & proxy.m_collisionFilterMask))
    return false;
  for (uint32_t slot : impl.bones.order)
    if (impl.bones.states[slot]->body == &object) return false;
  return true;
}

/// The union of the unfrozen muscles' tree bounds grown by `reach`; false when there are none.
bool muscleBounds(const MuscleSystemAccess::Impl& impl, btScalar reach, btDbvtVolume& bounds) {
  bool any = false;
  for (uint32_t slot : impl.muscles.order) {
    const MuscleState& muscle = *impl.muscles.states[slot];
    if (muscle.frozen || muscle.tree.empty()) continue;
    if (any)
      Merge(bounds, muscle.tree.bounds(0), bounds);
    else
      bounds = muscle.tree.bounds(0);
    any = true;
  }
  if (any) bounds.Expand(btVector3(reach, reach, reach));
  return any;
}

/// Collects the candidates among the leaves of a btDbvtBroadphase's trees.
struct ProxyCollector : btDbvt::ICollide {
  const MuscleSystemAccess::Impl& impl;
  const WorldCoupling& coupling;
  std::vector<const btCollisionObject*>& bodies;
  ProxyCollector(const MuscleSystemAccess::Impl& i, const WorldCoupling& c,
                 std::vector<const btCollisionObject*>& b)
      : impl(i), coupling(c), bodies(b) {}
  void Process(const btDbvtNode* leaf) override {
    const auto* proxy = static_cast<const btBroadphaseProxy*>(leaf->data);
    const auto* object = static_cast<const btCollisionObject*>(proxy->m_clientObject);
    if (object && contactCandidate(*object, *proxy, impl, coupling)) bodies.push_back(object);
  }
};

/// How fast, along `n`, the bones' motion over the last step moved the point `p` at most [m/s]:
/// the speed at which the pose change can carry the muscles between them and a body (0 when no
/// bone moved towards n).
btScalar poseSpeed(const MuscleSystemAccess::Impl& impl, const btVector3& p, const btVector3& n,
                   btScalar timeStep) {
  btScalar fastest = 0;
  for (uint32_t slot : impl.bones.order) {
    const BoneState& bone = *impl.bones.states[slot];
    const btVector3 moved = bone.target * (bone.goodLast.inverse() * p) - p;
    fastest = std::max(fastest, moved.dot(n) / timeStep);
  }
  return fastest;
}

/// The share of `impulse` a pose step of Bullet's `timeStep` hands `body`: at most what brings
/// the body's velocity along the impulse to `speed` (the pose change's), plus the gravity it
/// gains against the impulse over the next step (so that it can rest on a muscle). The muscles'
/// own time is not Bullet's: their mean force times Bullet's dt can be any impulse, and a pose
/// step may stop and carry a body but not throw it.
btScalar suppliedShare(const btRigidBody& body, const btVector3& impulse, btScalar speed,
                       btScalar timeStep) {
  const btScalar length = impulse.length();
  if (!(length > 0)) return 1;
  const btVector3 n = impulse / length;
  const btScalar sinking = std::max<btScalar>(0, -body.getGravity().dot(n)) * timeStep;
  const btScalar reach = speed + sinking - body.getLinearVelocity().dot(n);
  return std::clamp(reach / (body.getInvMass() * length), btScalar(0), btScalar(1));
}

/// The impulse a pose step of Bullet's `timeStep` dt hands `body` [N·s]: the muscles' static
/// reaction F (contact.support) as springs of stiffness K (supportStiffness) over the next step,
/// implicit: v' = (I + dt²·K/m)⁻¹·(v + dt·(g + F/m)) (the muscles hold what weight F carries, the
/// body's motion against the contacts is damped), less the gravity Bullet adds next step; no
/// pull against F (muscles only push), at most what the pose change can supply.
btVector3 supportImpulse(const MuscleSystemAccess::Impl& impl, const btRigidBody& body,
                         const BodyContact& contact, btScalar timeStep) {
  if (contact.support.isZero()) return btVector3(0, 0, 0);
  const btScalar inverseMass = body.getInvMass();
  const btVector3& g = body.getGravity();
  const btVector3& v = body.getLinearVelocity();
  const btMatrix3x3 damping =
      btMatrix3x3::getIdentity() +
      contact.supportStiffness.scaled(btVector3(1, 1, 1) * (timeStep * timeStep * inverseMass));
  const btVector3 next = damping.inverse() * (v + (g + contact.support * inverseMass) * timeStep);
  btVector3 impulse = (next - g * timeStep - v) / inverseMass;
  const btVector3 n = contact.support.normalized();
  impulse -= n * std::min<btScalar>(impulse.dot(n), 0);
  const btVector3 along = impulse.length2() > 0 ? impulse.normalized() : n;
  const btScalar speed = poseSpeed(impl, body.getCenterOfMassPosition(), along, timeStep);
  return impulse * suppliedShare(body, impulse, speed, timeStep);
}

/// The deepest overlap of `body`'s shape placed at `transform` with a free particle sphere of the
/// unfrozen muscles, a share of that particle's radius [1].
btScalar overlapAt(const MuscleSystemAccess::Impl& impl, const btCollisionObject& body,
                   const btTransform& transform) {
  btScalar deepest = 0;
  for (uint32_t slot : impl.muscles.order) {
    const MuscleState& muscle = *impl.muscles.states[slot];
    if (!muscle.frozen)
      deepest = std::max(deepest, deepestOverlap(muscle.colliding(), *body.getCollisionShape(),
                                                 transform, impl.queryStack));
  }
  return deepest;
}

/// Moves a dynamic `body` that Bullet's step of `timeStep` moved deeper than kPassShare into a
/// particle sphere beyond where it started back along its path (its velocities) to that depth.
void holdBackBody(const MuscleSystemAccess::Impl& impl, btRigidBody& body, btScalar timeStep) {
  const btTransform end = body.getWorldTransform();
  const auto along = [&](btScalar share) {
    btTransform at;
    btTransformUtil::integrateTransform(end, body.getLinearVelocity(), body.getAngularVelocity(),
                                        (share - 1) * timeStep, at);
    return at;
  };
  const btScalar allowed = overlapAt(impl, body, along(0)) + kPassShare;
  if (overlapAt(impl, body, end) <= allowed) return;
  btScalar reached = 0, blocked = 1;
  for (int k = 0; k < kPathHalvings; ++k) {
    const btScalar share = (reached + blocked) / 2;
    (overlapAt(impl, body, along(share)) <= allowed ? reached : blocked) = share;
  }
  const btTransform held = along(reached);
  body.setWorldTransform(held);
  body.setInterpolationWorldTransform(held);
}

}  // namespace

void checkCoupling(const WorldCoupling& coupling, const char* call) {
  if (!(coupling.reach >= 0) || !std::isfinite(coupling.reach))
    throw InputError(call, "WorldCoupling::reach", "expected a finite distance ≥ 0 m");
}

void RigidCoupling::gather(btCollisionWorld& world, MuscleSystem& muscles,
                           const WorldCoupling& coupling) {
  bodies_.clear();
  const MuscleSystemAccess::Impl& impl = MuscleSystemAccess::impl(muscles);
  btDbvtVolume bounds = btDbvtVolume::FromMM(btVector3(0, 0, 0), btVector3(0, 0, 0));
  if (coupling.rigidContact && muscleBounds(impl, coupling.reach, bounds)) {
    if (auto* broadphase = dynamic_cast<btDbvtBroadphase*>(world.getBroadphase())) {
      ProxyCollector collector(impl, coupling, bodies_);
      for (const btDbvt& set : broadphase->m_sets)
        set.collideTVNoStackAlloc(set.m_root, bounds, stack_, collector);
    } else {
      const btCollisionObjectArray& objects = world.getCollisionObjectArray();
      for (int k = 0; k < objects.size(); ++k) {
        const btBroadphaseProxy* proxy = objects[k]->getBroadphaseHandle();
        if (proxy && Intersect(bounds, btDbvtVolume::FromMM(proxy->m_aabbMin, proxy->m_aabbMax)) &&
            contactCandidate(*objects[k], *proxy, impl, coupling))
          bodies_.push_back(objects[k]);
      }
    }
    // The world's order, whatever the broadphase's tree looks like.
    std::sort(bodies_.begin(), bodies_.end(),
              [](const btCollisionObject* a, const btCollisionObject* b) {
                return a->getWorldArrayIndex() < b->getWorldArrayIndex();
              });
  }
  muscles.setContactBodies(bodies_);
}

void RigidCoupling::apply(const MuscleSystem& muscles, btScalar scale, btScalar poseStep) const {
  const MuscleSystemAccess::Impl& impl = MuscleSystemAccess::impl(muscles);
  for (const btCollisionObject* object : bodies_) {
    auto* body = const_cast<btRigidBody*>(btRigidBody::upcast(object));
    if (!body || body->isStaticOrKinematicObject()) continue;
    const BodyContact contact = muscles.bodyContact(object);
    if (contact.impulse.isZero() && contact.angularImpulse.isZero() && contact.support.isZero())
      continue;
    body->activate();
    if (poseStep > 0) {
      // The static reaction moves it; its turn is the step's, up to what the pose can supply.
      const btVector3 impulse = contact.impulse * scale;
      const btVector3 n = impulse.length2() > 0 ? impulse.normalized() : impulse;
      const btScalar speed = poseSpeed(impl, body->getCenterOfMassPosition(), n, poseStep);
      body->applyCentralImpulse(supportImpulse(impl, *body, contact, poseStep));
      body->applyTorqueImpulse(contact.angularImpulse * scale *
                               suppliedShare(*body, impulse, speed, poseStep));
      continue;
    }
    body->setWorldTransform(contact.transform);
    body->setInterpolationWorldTransform(contact.transform);
    body->applyCentralImpulse(contact.impulse * scale);
    body->applyTorqueImpulse(contact.angularImpulse * scale);
  }
}

void RigidCoupling::holdBack(const MuscleSystem& muscles, btScalar timeStep) const {
  const MuscleSystemAccess::Impl& impl = MuscleSystemAccess::impl(muscles);
  for (const btCollisionObject* object : bodies_) {
    auto* body = const_cast<btRigidBody*>(btRigidBody::upcast(object));
    if (body && !body->isStaticOrKinematicObject() && touchableShape(*body->getCollisionShape()))
      holdBackBody(impl, *body, timeStep);
  }
}

void RigidCoupling::step(btCollisionWorld& world, MuscleSystem& muscles,
                         const WorldCoupling& coupling, btScalar timeStep) {
  gather(world, muscles, coupling);
  if (coupling.time == MuscleTime::Dynamic) {
    muscles.step(timeStep);
    apply(muscles, 1, 0);
    return;
  }
  holdBack(muscles, timeStep);
  muscles.step();
  // The pose step ran the muscles' own time: the body takes their static reaction, and its turn
  // as their mean torque over Bullet's dt, up to what the pose change can supply.
  const double time = muscles.lastStep().simulatedTime;
  apply(muscles, time > 0 ? static_cast<btScalar>(timeStep / time) : btScalar(0), timeStep);
}

void RigidCoupling::forget(const btCollisionObject* object, MuscleSystem& muscles) {
  const auto it = std::find(bodies_.begin(), bodies_.end(), object);
  if (it == bodies_.end()) return;
  bodies_.erase(it);
  muscles.setContactBodies(bodies_);
}

}  // namespace fibremss
