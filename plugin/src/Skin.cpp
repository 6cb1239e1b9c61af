#include "Skin.h"

namespace fibremss {

void deformSurface(const MuscleSettings& settings, std::span<const btVector3> positions,
                   std::span<const btTransform> boneTransforms, std::span<btVector3> surface) {
  const auto& rest = settings.restSurface.vertices;
  const size_t n = static_cast<size_t>(settings.skinNeighbours);
  const btTransform identity = btTransform::getIdentity();
  for (size_t v = 0; v < rest.size(); ++v) {
    btVector3 moved(0, 0, 0);
    for (size_t j = v * n; j < (v + 1) * n; ++j) {
      const uint32_t particle = settings.skinParticles[j];
      const int32_t bone = settings.nearestBone[particle];
      const btTransform& transform = bone >= 0 && static_cast<size_t>(bone) < boneTransforms.size()
                                         ? boneTransforms[bone]
                                         : identity;
      const btVector3 displacement =
          positions[particle] - transform * settings.restPositions[particle];
      moved += (transform * rest[v] + displacement) * settings.skinWeights[j];
    }
    surface[v] = moved;
  }
}

}  // namespace fibremss
