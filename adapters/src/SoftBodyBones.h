#pragma once
// Bones as kinematic rigid bodies with their true triangle meshes, shared by the btSoftBody
// baseline and the FEM reference (internal to the adapters).
#include <BulletCollision/CollisionShapes/btBvhTriangleMeshShape.h>
#include <BulletCollision/CollisionShapes/btTriangleMesh.h>
#include <BulletDynamics/Dynamics/btRigidBody.h>

#include <memory>

#include "fibremss/MuscleSettings.h"

namespace fibremss {

/// A btBvhTriangleMeshShape whose broadphase bounds reach `padding` beyond the mesh, so that
/// muscle–bone pairs live for the whole run: when a pair ends, Bullet's
/// btSoftBodyTriangleCallback::clearCache scans every sparse-SDF cell once per cached triangle,
/// minutes per pose on thigh13. Triangles are still culled by the muscle's own bounds.
class PaddedTriangleMeshShape : public btBvhTriangleMeshShape {
 public:
  PaddedTriangleMeshShape(btStridingMeshInterface* mesh, btScalar padding)
      : btBvhTriangleMeshShape(mesh, true), padding_(padding) {}
  void getAabb(const btTransform& transform, btVector3& aabbMin,
               btVector3& aabbMax) const override {
    btBvhTriangleMeshShape::getAabb(transform, aabbMin, aabbMax);
    aabbMin -= btVector3(padding_, padding_, padding_);
    aabbMax += btVector3(padding_, padding_, padding_);
  }

 private:
  btScalar padding_;
};

/// A bone's mesh as a btBvhTriangleMeshShape on a kinematic btRigidBody whose world
/// transform maps rest to current coordinates; `scale` multiplies every length (Bullet units
/// per metre).
struct KinematicBone {
  std::unique_ptr<btTriangleMesh> triangles;       ///< copy of the rest mesh
  std::unique_ptr<PaddedTriangleMeshShape> shape;  ///< BVH over it
  std::unique_ptr<btRigidBody> body;               ///< kinematic, never deactivated

  static constexpr btScalar kPadding = 2;  ///< [m] beyond any muscle's reach

  KinematicBone(const BoneSettings& settings, const btTransform& transform, btScalar scale = 1)
      : triangles(std::make_unique<btTriangleMesh>()) {
    const auto& v = settings.mesh.vertices;
    for (const auto& t : settings.mesh.triangles) {
      triangles->addTriangle(v[t[0]] * scale, v[t[1]] * scale, v[t[2]] * scale);
    }
    shape = std::make_unique<PaddedTriangleMeshShape>(triangles.get(), kPadding * scale);
    shape->setMargin(0);
    btRigidBody::btRigidBodyConstructionInfo info(0, nullptr, shape.get());
    info.m_startWorldTransform = transform;
    body = std::make_unique<btRigidBody>(info);
    body->setCollisionFlags(body->getCollisionFlags() | btCollisionObject::CF_KINEMATIC_OBJECT);
    body->setActivationState(DISABLE_DEACTIVATION);
  }
};

/// A transform in units `scale` times smaller (the translation scaled).
inline btTransform scaledTransform(const btTransform& transform, btScalar scale) {
  return btTransform(transform.getBasis(), transform.getOrigin() * scale);
}

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
