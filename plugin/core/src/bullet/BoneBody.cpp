#include "fibremss/BoneBody.h"

#include <string>

#include "fibremss/Error.h"

namespace fibremss {
namespace {

/// A btBvhTriangleMeshShape whose broadphase bounds reach `padding` beyond the mesh.
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
  btScalar padding_;  ///< added on every side
};

}  // namespace

BoneBody::BoneBody(std::shared_ptr<const BoneSettings> settings, const btTransform& transform,
                   const BoneBodyOptions& options)
    : settings_(std::move(settings)) {
  const TriangleMesh& mesh = settings_->mesh;
  if (mesh.triangles.empty())
    throw InputError("bone '" + settings_->name + "'", "mesh", "has no triangles");
  vertices_.reserve(mesh.vertices.size() * 3);
  for (const btVector3& v : mesh.vertices) {
    vertices_.insert(vertices_.end(),
                     {v.x() * options.scale, v.y() * options.scale, v.z() * options.scale});
  }
  indices_.reserve(mesh.triangles.size() * 3);
  for (const auto& t : mesh.triangles) {
    for (uint32_t corner : t) {
      if (corner >= mesh.vertices.size())
        throw InputError("bone '" + settings_->name + "'", "mesh",
                         "triangle index " + std::to_string(corner) + " out of range");
      indices_.push_back(static_cast<int>(corner));
    }
  }

  btIndexedMesh part;
  part.m_numTriangles = static_cast<int>(mesh.triangles.size());
  part.m_triangleIndexBase = reinterpret_cast<const unsigned char*>(indices_.data());
  part.m_triangleIndexStride = 3 * sizeof(int);
  part.m_numVertices = static_cast<int>(mesh.vertices.size());
  part.m_vertexBase = reinterpret_cast<const unsigned char*>(vertices_.data());
  part.m_vertexStride = 3 * sizeof(btScalar);
  part.m_indexType = PHY_INTEGER;
  // Bullet reads the vertex array in the precision it is told, which must match btScalar.
  part.m_vertexType = sizeof(btScalar) == sizeof(double) ? PHY_DOUBLE : PHY_FLOAT;
  meshInterface_ = std::make_unique<btTriangleIndexVertexArray>();
  meshInterface_->addIndexedMesh(part, PHY_INTEGER);
  if (options.padding > 0) {
    shape_ = std::make_unique<PaddedTriangleMeshShape>(meshInterface_.get(), options.padding);
  } else {
    shape_ = std::make_unique<btBvhTriangleMeshShape>(meshInterface_.get(), true);
  }

  motionState_ = std::make_unique<btDefaultMotionState>(transform);
  btRigidBody::btRigidBodyConstructionInfo info(0, motionState_.get(), shape_.get());
  body_ = std::make_unique<btRigidBody>(info);
  body_->setCollisionFlags(body_->getCollisionFlags() | btCollisionObject::CF_KINEMATIC_OBJECT);
  body_->setActivationState(DISABLE_DEACTIVATION);
}

BoneBody::~BoneBody() = default;

void BoneBody::setTransform(const btTransform& transform) {
  motionState_->setWorldTransform(transform);
  body_->setWorldTransform(transform);
}

}  // namespace fibremss
