#include "Skin.h"

#include <algorithm>
#include <cmath>

#include "ParticleSimd.h"
#include "fibremss/Pretransform.h"

namespace fibremss {
namespace {

/// d·Dᵀ.
btMatrix3x3 outer(const btVector3& d, const btVector3& e) {
  return btMatrix3x3(d.x() * e.x(), d.x() * e.y(), d.x() * e.z(), d.y() * e.x(), d.y() * e.y(),
                     d.y() * e.z(), d.z() * e.x(), d.z() * e.y(), d.z() * e.z());
}

#if FIBREMSS_SSE_PARTICLES
/// m·u as btMatrix3x3's product gives it (each row's dot with u summed (x + y) + z), w 0.
inline __m128 transform(const btMatrix3x3& m, __m128 u) {
  __m128 r0 = _mm_mul_ps(loadVector(m[0]), u), r1 = _mm_mul_ps(loadVector(m[1]), u);
  __m128 r2 = _mm_mul_ps(loadVector(m[2]), u), r3 = _mm_setzero_ps();
  _MM_TRANSPOSE4_PS(r0, r1, r2, r3);
  return _mm_add_ps(_mm_add_ps(r0, r1), r2);
}

/// `rows` added to m's rows.
inline void addRows(btMatrix3x3& m, const __m128 (&rows)[3]) {
  for (int i = 0; i < 3; ++i)
    _mm_store_ps(m[i].m_floats, _mm_add_ps(_mm_load_ps(m[i].m_floats), rows[i]));
}
#endif

/// Σ over the springs with a used end of outer(x_b − x_a, X_b − X_a), into that end's entry of
/// `sums` (which starts at zero). With SSE a row of the outer product per instruction (each
/// entry's product and sum as btMatrix3x3's, w kept 0): the same bits.
void sumMoments(const MuscleSettings& settings, std::span<const btVector3> positions,
                std::span<const uint8_t> used, std::span<btMatrix3x3> sums) {
  for (btMatrix3x3& m : sums) m.setValue(0, 0, 0, 0, 0, 0, 0, 0, 0);
  const std::span<const btVector3> rest = settings.restPositions;
  for (const Spring& spring : settings.springs) {
    if (!used[spring.a] && !used[spring.b]) continue;
#if FIBREMSS_SSE_PARTICLES
    const __m128 xyz = xyzMask();
    const __m128 d = _mm_sub_ps(loadVector(positions[spring.b]), loadVector(positions[spring.a]));
    const __m128 e = _mm_sub_ps(loadVector(rest[spring.b]), loadVector(rest[spring.a]));
    const __m128 rows[3] = {_mm_and_ps(_mm_mul_ps(_mm_shuffle_ps(d, d, 0x00), e), xyz),
                            _mm_and_ps(_mm_mul_ps(_mm_shuffle_ps(d, d, 0x55), e), xyz),
                            _mm_and_ps(_mm_mul_ps(_mm_shuffle_ps(d, d, 0xaa), e), xyz)};
    if (used[spring.a]) addRows(sums[spring.a], rows);
    if (used[spring.b]) addRows(sums[spring.b], rows);
#else
    const btMatrix3x3 m =
        outer(positions[spring.b] - positions[spring.a], rest[spring.b] - rest[spring.a]);
    if (used[spring.a]) sums[spring.a] += m;
    if (used[spring.b]) sums[spring.b] += m;
#endif
  }
}

/// The rotation part of particle i's rigid pre-transform, as a matrix.
btMatrix3x3 boneRotation(const MuscleSettings& settings,
                         std::span<const btTransform> boneTransforms, uint32_t i, bool blended,
                         PretransformBlend blend) {
  btVector3 columns[3];
  for (int c = 0; c < 3; ++c) {
    btVector3 axis(0, 0, 0);
    axis[c] = 1;
    columns[c] = pretransformDirection(settings, boneTransforms, i, axis, blended, blend);
  }
  return btMatrix3x3(columns[0].x(), columns[1].x(), columns[2].x(), columns[0].y(), columns[1].y(),
                     columns[2].y(), columns[0].z(), columns[1].z(), columns[2].z());
}

/// Particle i's F from its spring moment Σ dx·dXᵀ: moment·(Σ dX·dXᵀ)⁻¹, or its bone rotation
/// where it has no frame or F is inverted (deformSurface).
btMatrix3x3 frameOf(const MuscleSettings& settings, std::span<const btTransform> boneTransforms,
                    bool blended, PretransformBlend blend, const SkinFrames& frames, uint32_t i,
                    const btMatrix3x3& moment) {
  const btMatrix3x3 deformation = moment * frames.restInverse[i];
  return frames.hasFrame[i] && deformation.determinant() > 0
             ? deformation
             : boneRotation(settings, boneTransforms, i, blended, blend);
}

/// Each surface vertex v from its particles p (weights w) and their deformations F_p:
/// Σ w·(x_p + F_p·(v − p)). With SSE a vector per instruction, each sum and product as
/// btVector3's and btMatrix3x3's: the same bits.
void bindSurface(const MuscleSettings& settings, std::span<const btVector3> positions,
                 std::span<const btMatrix3x3> deformations, std::span<btVector3> surface) {
  const auto& rest = settings.restSurface.vertices;
#if FIBREMSS_SSE_PARTICLES
  const size_t n = static_cast<size_t>(settings.skinNeighbours);
  for (size_t v = 0; v < rest.size(); ++v) {
    const __m128 vertex = loadVector(rest[v]);
    __m128 moved = _mm_setzero_ps();
    for (size_t j = v * n; j < (v + 1) * n; ++j) {
      const uint32_t particle = settings.skinParticles[j];
      const __m128 offset = transform(
          deformations[particle], _mm_sub_ps(vertex, loadVector(settings.restPositions[particle])));
      moved = _mm_add_ps(moved, _mm_mul_ps(_mm_add_ps(loadVector(positions[particle]), offset),
                                           _mm_set1_ps(settings.skinWeights[j])));
    }
    _mm_store_ps(surface[v].m_floats, _mm_and_ps(moved, xyzMask()));
  }
#else
  for (size_t v = 0; v < rest.size(); ++v)
    surface[v] = skinnedVertex(settings, positions, deformations, v);
#endif
}

}  // namespace

btVector3 skinnedVertex(const MuscleSettings& settings, std::span<const btVector3> positions,
                        std::span<const btMatrix3x3> deformations, size_t v) {
  const btVector3& vertex = settings.restSurface.vertices[v];
  const size_t n = static_cast<size_t>(settings.skinNeighbours);
  btVector3 moved(0, 0, 0);
  for (size_t j = v * n; j < (v + 1) * n; ++j) {
    const uint32_t particle = settings.skinParticles[j];
    const btVector3 offset = deformations[particle] * (vertex - settings.restPositions[particle]);
    moved += (positions[particle] + offset) * settings.skinWeights[j];
  }
  return moved;
}

btMatrix3x3 particleDeformation(const MuscleSettings& settings,
                                std::span<const btVector3> positions,
                                std::span<const btTransform> boneTransforms, bool blended,
                                PretransformBlend blend, const SkinFrames& frames, uint32_t i,
                                std::span<const uint32_t> springs) {
  btMatrix3x3 moment(0, 0, 0, 0, 0, 0, 0, 0, 0);
  const std::span<const btVector3> rest = settings.restPositions;
  for (uint32_t s : springs) {
    const Spring& spring = settings.springs[s];
    moment += outer(positions[spring.b] - positions[spring.a], rest[spring.b] - rest[spring.a]);
  }
  return frameOf(settings, boneTransforms, blended, blend, frames, i, moment);
}

void prepareSkinFrames(const MuscleSettings& settings, SkinFrames& frames) {
  const size_t n = settings.particleCount();
  frames.used.assign(n, 0);
  for (uint32_t p : settings.skinParticles) frames.used[p] = 1;
  frames.restInverse.assign(n, btMatrix3x3::getIdentity());
  frames.hasFrame.assign(n, 0);
  frames.moments.assign(n, btMatrix3x3::getIdentity());
  frames.deformations.assign(n, btMatrix3x3::getIdentity());
  frames.layer.assign(settings.restSurface.vertices.size(), 0);
  sumMoments(settings, settings.restPositions, frames.used, frames.moments);
  for (uint32_t i = 0; i < n; ++i) {
    if (!frames.used[i]) continue;
    const btMatrix3x3& m = frames.moments[i];
    const btScalar mean = (m[0][0] + m[1][1] + m[2][2]) / 3;
    // Neighbours nearly on a plane or a line give no rotation out of it.
    if (!(m.determinant() > btScalar(1e-3) * mean * mean * mean)) continue;
    frames.restInverse[i] = m.inverse();
    frames.hasFrame[i] = 1;
  }
}

void deformSurface(const MuscleSettings& settings, std::span<const btVector3> positions,
                   std::span<const btTransform> boneTransforms, bool blended,
                   PretransformBlend blend, SkinFrames& frames, std::span<btVector3> surface) {
  sumMoments(settings, positions, frames.used, frames.moments);
  for (uint32_t i = 0; i < frames.used.size(); ++i)
    if (frames.used[i])
      frames.deformations[i] =
          frameOf(settings, boneTransforms, blended, blend, frames, i, frames.moments[i]);
  bindSurface(settings, positions, frames.deformations, surface);
}

void measureLayer(const MuscleSettings& settings, std::span<const btVector3> positions,
                  std::span<const btVector3> surface, SkinFrames& frames) {
  const size_t n = static_cast<size_t>(settings.skinNeighbours);
  for (size_t v = 0; v < surface.size(); ++v) {
    btScalar nearest2 = SIMD_INFINITY;
    for (size_t j = v * n; j < (v + 1) * n; ++j)
      nearest2 = std::min(nearest2, surface[v].distance2(positions[settings.skinParticles[j]]));
    frames.layer[v] = std::sqrt(nearest2);
  }
}

}  // namespace fibremss
