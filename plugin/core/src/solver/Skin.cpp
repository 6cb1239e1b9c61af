#include "Skin.h"

#include "MuscleSystemPretransform.h"

namespace fibremss {

void deformSurface(const MuscleSettings& settings, std::span<const btVector3> positions,
                   std::span<const btTransform> boneTransforms, bool blended,
                   std::span<btVector3> surface) {
  const auto& rest = settings.restSurface.vertices;
  const size_t n = static_cast<size_t>(settings.skinNeighbours);
  // The pre-transform is affine per particle: P(v) − P(p) = P's rotation part applied to v − p,
  // so each binding costs one blended rotation instead of two blended transforms.
#if FIBREMSS_SSE_PRETRANSFORM
  const size_t count = boneTransforms.size();
  if (blended && !settings.blendWeight.empty() && count <= kPackedBones) {
    PackedTransform packed[kPackedBones];
    for (size_t b = 0; b < count; ++b) packed[b] = packTransform(boneTransforms[b]);
    const __m128 xyz = _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0));
    for (size_t v = 0; v < rest.size(); ++v) {
      const __m128 vertex = _mm_load_ps(rest[v].m_floats);
      __m128 moved = _mm_setzero_ps();
      for (size_t j = v * n; j < (v + 1) * n; ++j) {
        const uint32_t particle = settings.skinParticles[j];
        const __m128 offset =
            turnPacked(settings, packed, count, particle,
                       _mm_sub_ps(vertex, _mm_load_ps(settings.restPositions[particle].m_floats)));
        moved = _mm_add_ps(moved,
                           _mm_mul_ps(_mm_add_ps(_mm_load_ps(positions[particle].m_floats), offset),
                                      _mm_set1_ps(settings.skinWeights[j])));
      }
      _mm_store_ps(surface[v].m_floats, _mm_and_ps(moved, xyz));
    }
    return;
  }
#endif
  for (size_t v = 0; v < rest.size(); ++v) {
    btVector3 moved(0, 0, 0);
    for (size_t j = v * n; j < (v + 1) * n; ++j) {
      const uint32_t particle = settings.skinParticles[j];
      const btVector3 offset = pretransformDirection(
          settings, boneTransforms, particle, rest[v] - settings.restPositions[particle], blended);
      moved += (positions[particle] + offset) * settings.skinWeights[j];
    }
    surface[v] = moved;
  }
}

}  // namespace fibremss
