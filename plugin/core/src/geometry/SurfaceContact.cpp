#include "SurfaceContact.h"

#include <LinearMath/btAabbUtil2.h>

namespace fibremss {

ContactMesh::ContactMesh(const TriangleMesh& mesh) : distance(mesh) {
  pointBounds(mesh.vertices, lower, upper);
}

size_t liftOutOfBone(const ContactMesh& bone, const btTransform& boneToWorld,
                     std::span<const btScalar> reach, const btVector3& lower,
                     const btVector3& upper, std::span<btVector3> surface) {
  btVector3 boneLower, boneUpper;
  btTransformAabb(bone.lower, bone.upper, 0, boneToWorld, boneLower, boneUpper);
  if (!TestAabbAgainstAabb2(lower, upper, boneLower, boneUpper)) return 0;
  const btTransform toBone = boneToWorld.inverse();
  size_t moved = 0;
  for (size_t v = 0; v < surface.size(); ++v) {
    btVector3& vertex = surface[v];
    const MeshDistance::Closest closest = bone.distance.closest(toBone * vertex, reach[v]);
    if (!closest.inside) continue;
    vertex = boneToWorld * closest.point;
    ++moved;
  }
  return moved;
}

}  // namespace fibremss
