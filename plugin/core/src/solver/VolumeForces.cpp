#include "VolumeForces.h"

#include <cmath>

#include "Skin.h"

namespace fibremss {

bool hasVolumeTerm(const MuscleSettings& settings) {
  return settings.volumeModulus > 0 && settings.restVolume != 0 &&
         !settings.restSurface.triangles.empty() && !settings.skinParticles.empty();
}

void updateVolumeOffsets(MuscleState& muscle, bool blended) {
  // The skin is linear in the positions: with every particle at the origin it gives the offsets.
  deformSurface(*muscle.settings, muscle.volumeOrigins, muscle.boneTransforms, blended,
                muscle.volumeOffsets);
}

double addVolumeForces(MuscleState& muscle, std::span<const btVector3> positions,
                       std::span<btVector3> forces) {
  const MuscleSettings& settings = *muscle.settings;
  const size_t n = static_cast<size_t>(settings.skinNeighbours);
  std::vector<btVector3>& surface = muscle.volumeSurface;
  std::vector<btVector3>& gradient = muscle.volumeGradient;
  // Skinned surface relative to its first vertex (small numbers: the volume in float).
  btVector3 origin(0, 0, 0);
  for (size_t v = 0; v < surface.size(); ++v) {
    btVector3 s = muscle.volumeOffsets[v];
    for (size_t j = v * n; j < (v + 1) * n; ++j)
      s += positions[settings.skinParticles[j]] * settings.skinWeights[j];
    if (v == 0) origin = s;
    surface[v] = s - origin;
    gradient[v].setZero();
  }
  double volume = 0;
  for (const auto& t : settings.restSurface.triangles) {
    const btVector3 &a = surface[t[0]], &b = surface[t[1]], &c = surface[t[2]];
    const btVector3 bc = b.cross(c);
    volume += double(a.dot(bc));
    gradient[t[0]] += bc;
    gradient[t[1]] += c.cross(a);
    gradient[t[2]] += a.cross(b);
  }
  volume /= 6;
  const double rest = settings.restVolume;
  // ∂V/∂s is a sixth of the summed cross products.
  const btScalar pressure =
      static_cast<btScalar>(settings.volumeModulus * (rest - volume) / std::abs(rest) / 6);
  for (size_t v = 0; v < surface.size(); ++v) {
    const btVector3 force = gradient[v] * pressure;
    for (size_t j = v * n; j < (v + 1) * n; ++j)
      forces[settings.skinParticles[j]] += force * settings.skinWeights[j];
  }
  return volume;
}

}  // namespace fibremss
