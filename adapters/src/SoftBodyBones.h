#pragma once
// Bone poses and Bullet world parts shared by the btSoftBody baseline and the FEM reference
// (internal to the adapters).
#include <BulletCollision/BroadphaseCollision/btDbvtBroadphase.h>
#include <BulletCollision/CollisionDispatch/btCollisionDispatcher.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>
#include <LinearMath/btTransform.h>

#include <memory>

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

}  // namespace fibremss
