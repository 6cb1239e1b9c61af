#include "SurfaceContact.h"

namespace fibremss {

size_t liftOutOfBone(const MeshDistance& bone, const btTransform& boneToWorld,
                     std::span<const btScalar> reach, std::span<btVector3> surface) {
  const btTransform toBone = boneToWorld.inverse();
  size_t moved = 0;
  for (size_t v = 0; v < surface.size(); ++v) {
    btVector3& vertex = surface[v];
    const MeshDistance::Closest closest = bone.closest(toBone * vertex, reach[v]);
    if (!closest.inside) continue;
    vertex = boneToWorld * closest.point;
    ++moved;
  }
  return moved;
}

}  // namespace fibremss
