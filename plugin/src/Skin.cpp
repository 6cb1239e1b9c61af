#include "Skin.h"

#include "MuscleSystemPretransform.h"

namespace fibremss {

void deformSurface(const MuscleSettings& settings, std::span<const btVector3> positions,
                   std::span<const btTransform> boneTransforms, bool blended,
                   std::span<btVector3> surface) {
  const auto& rest = settings.restSurface.vertices;
  const size_t n = static_cast<size_t>(settings.skinNeighbours);
  for (size_t v = 0; v < rest.size(); ++v) {
    btVector3 moved(0, 0, 0);
    for (size_t j = v * n; j < (v + 1) * n; ++j) {
      const uint32_t particle = settings.skinParticles[j];
      const btVector3 displacement =
          positions[particle] - pretransformPoint(settings, boneTransforms, particle,
                                                  settings.restPositions[particle], blended);
      moved +=
          (pretransformPoint(settings, boneTransforms, particle, rest[v], blended) + displacement) *
          settings.skinWeights[j];
    }
    surface[v] = moved;
  }
}

}  // namespace fibremss
