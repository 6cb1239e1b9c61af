#pragma once
// Bone poses and Bullet world parts shared by the btSoftBody baseline and the FEM reference
// (internal to the adapters).
#include <BulletCollision/BroadphaseCollision/btDbvtBroadphase.h>
#include <BulletCollision/CollisionDispatch/btCollisionDispatcher.h>
#include <BulletSoftBody/btSoftBody.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>
#include <LinearMath/btTransform.h>

#include <memory>
#include <span>
#include <vector>

#include "fibremss/Pretransform.h"

namespace fibremss {

/// A transform in units `scale` times smaller (the translation scaled).
inline btTransform scaledTransform(const btTransform& transform, btScalar scale) {
  return btTransform(transform.getBasis(), transform.getOrigin() * scale);
}

/// The collision parts a soft-body world is built on, made in the order Bullet needs them.
struct SoftWorldParts {
  std::unique_ptr<btSoftBodyRigidBodyCollisionConfiguration> configuration =
      std::make_unique<btSoftBodyRigidBodyCollisionConfiguration>();  ///< soft–rigid algorithms
  std::unique_ptr<btCollisionDispatcher> dispatcher =
      std::make_unique<btCollisionDispatcher>(configuration.get());  ///< narrow phase
  std::unique_ptr<btDbvtBroadphase> broadphase = std::make_unique<btDbvtBroadphase>();  ///< pairs
};

/// Sparse SDF hash buckets and cell limit: Bullet's 2383 buckets make every lookup walk long
/// chains once thousands of bone triangles have cells.
inline constexpr int kSdfBuckets = 499979;
inline constexpr int kSdfMaxCells = 1 << 20;

/// The transform a fraction t of the way from `from` to `to` (slerp of the rotation).
inline btTransform interpolateTransform(const btTransform& from, const btTransform& to,
                                        btScalar t) {
  return btTransform(from.getRotation().slerp(to.getRotation(), t),
                     from.getOrigin().lerp(to.getOrigin(), t));
}

/// Moves the bones a fraction t of the way from `from` to `targets`: `current` becomes the new
/// transforms and `deltas` the motion since the previous ones (new · old⁻¹), one per bone.
inline void advanceBones(std::span<const btTransform> from, std::span<const btTransform> targets,
                         btScalar t, std::vector<btTransform>& current,
                         std::vector<btTransform>& deltas) {
  deltas.resize(current.size());
  for (size_t b = 0; b < current.size(); ++b) {
    const btTransform before = current[b];
    current[b] = interpolateTransform(from[b], targets[b], t);
    deltas[b] = current[b] * before.inverse();
  }
}

/// Moves a free node (position and previous position, in Bullet units `scale` per metre) by
/// the bone motion `deltas` blended (by `blend`) as FibreMSS pre-transforms `particle`
/// (method.md §4), and turns its velocity with the blend's rotation: the node keeps its motion
/// relative to its bones instead of being dragged after them by the pinned nodes alone.
inline void moveNodeWithBones(const MuscleSettings& settings, std::span<const btTransform> deltas,
                              PretransformBlend blend, uint32_t particle, btScalar scale,
                              btSoftBody::Node& node) {
  node.m_x = pretransformPoint(settings, deltas, particle, node.m_x / scale, true, blend) * scale;
  node.m_q = pretransformPoint(settings, deltas, particle, node.m_q / scale, true, blend) * scale;
  node.m_v = pretransformDirection(settings, deltas, particle, node.m_v, true, blend);
}

}  // namespace fibremss
