#pragma once
// A bone as a Bullet rigid body: kinematic, with the bone's rest mesh as a triangle mesh shape,
// so the body's world transform maps rest coordinates to current ones (the convention of
// BoneSettings). Hand it to MuscleWorld::addBone or MuscleSystem::addBone.
#include <BulletCollision/CollisionShapes/btBvhTriangleMeshShape.h>
#include <BulletCollision/CollisionShapes/btTriangleIndexVertexArray.h>
#include <BulletDynamics/Dynamics/btRigidBody.h>
#include <LinearMath/btDefaultMotionState.h>

#include <memory>
#include <vector>

#include "fibremss/MuscleSettings.h"

namespace fibremss {

/// How a BoneBody's shape is built; the defaults keep the mesh as given.
struct BoneBodyOptions {
  btScalar scale = 1;    ///< every vertex is multiplied by it (a world in other length units)
  btScalar padding = 0;  ///< the shape's broadphase bounds reach this far beyond the mesh
                         ///< (scaled units), so that pairs with it never end
};

class BoneBody {
 public:
  /// Builds the shape from `settings->mesh` (throws InputError when it has no triangles) and a
  /// kinematic body placed at `transform` (rest → current, in scaled units).
  explicit BoneBody(std::shared_ptr<const BoneSettings> settings,
                    const btTransform& transform = btTransform::getIdentity(),
                    const BoneBodyOptions& options = {});
  ~BoneBody();
  BoneBody(const BoneBody&) = delete;
  BoneBody& operator=(const BoneBody&) = delete;

  /// Moves the bone (body and motion state, so Bullet derives its velocity for contacts).
  void setTransform(const btTransform& transform);
  btTransform transform() const { return body_->getWorldTransform(); }

  btRigidBody* body() { return body_.get(); }
  const btRigidBody* body() const { return body_.get(); }
  const std::shared_ptr<const BoneSettings>& settings() const { return settings_; }

 private:
  std::shared_ptr<const BoneSettings> settings_;  ///< the bone, shared read-only
  std::vector<btScalar> vertices_;                ///< xyz per vertex, read by the shape
  std::vector<int> indices_;                      ///< three per triangle
  std::unique_ptr<btTriangleIndexVertexArray> meshInterface_;  ///< views vertices_, indices_
  std::unique_ptr<btBvhTriangleMeshShape> shape_;              ///< the rest mesh with its BVH
  std::unique_ptr<btDefaultMotionState> motionState_;          ///< where Bullet reads the pose
  std::unique_ptr<btRigidBody> body_;                          ///< the kinematic body
};

}  // namespace fibremss
