#pragma once
// The packed (SSE/AVX2) forms of the rigid pre-transform in fibremss/Pretransform.h, internal.
#include <LinearMath/btTransform.h>

#include <span>

#include "ParticleSimd.h"
#include "fibremss/MuscleSettings.h"
#include "fibremss/Pretransform.h"

#define FIBREMSS_SSE_PRETRANSFORM FIBREMSS_SSE_PARTICLES

namespace fibremss {

#if FIBREMSS_SSE_PRETRANSFORM
/// Bones a muscle may have for the packed (SSE) pre-transform; more take the scalar path.
constexpr size_t kPackedBones = 8;

/// A rigid transform in SSE registers: its basis' columns and its origin (w lanes 0).
struct PackedTransform {
  __m128 columns[3];  ///< basis columns
  __m128 origin;      ///< translation
};

inline PackedTransform packTransform(const btTransform& t) {
  const btMatrix3x3& r = t.getBasis();
  PackedTransform packed;
  for (int c = 0; c < 3; ++c) packed.columns[c] = _mm_setr_ps(r[0][c], r[1][c], r[2][c], 0);
  const btVector3& o = t.getOrigin();
  packed.origin = _mm_setr_ps(o.x(), o.y(), o.z(), 0);
  return packed;
}

/// The basis of t times d with btMatrix3x3's rounding: per row (r0·x + r1·y) + r2·z.
inline __m128 rotatePacked(const PackedTransform& t, __m128 d) {
  const __m128 x = _mm_shuffle_ps(d, d, 0x00), y = _mm_shuffle_ps(d, d, 0x55),
               z = _mm_shuffle_ps(d, d, 0xaa);
  return _mm_add_ps(_mm_add_ps(_mm_mul_ps(t.columns[0], x), _mm_mul_ps(t.columns[1], y)),
                    _mm_mul_ps(t.columns[2], z));
}

/// t·p with btTransform's rounding: the rotated point plus the origin.
inline __m128 transformPacked(const PackedTransform& t, __m128 p) {
  return _mm_add_ps(rotatePacked(t, p), t.origin);
}

/// pretransformDirection's blend (blended settings) with packed transforms of `count` bones:
/// the same operations in the same order on x, y, z, so the same bits.
inline __m128 turnPacked(const MuscleSettings& settings, const PackedTransform* packed,
                         size_t count, uint32_t i, __m128 d) {
  const btScalar w = settings.blendWeight[i];
  const int32_t a = settings.blendBoneA[i], b = settings.blendBoneB[i];
  __m128 turned = d;
  if (a >= 0 && static_cast<size_t>(a) < count && w < 1)
    turned = _mm_add_ps(turned,
                        _mm_mul_ps(_mm_sub_ps(rotatePacked(packed[a], d), d), _mm_set1_ps(1 - w)));
  if (b >= 0 && static_cast<size_t>(b) < count && w > 0)
    turned =
        _mm_add_ps(turned, _mm_mul_ps(_mm_sub_ps(rotatePacked(packed[b], d), d), _mm_set1_ps(w)));
  return turned;
}

/// pretransformPoint's blend (blended settings) applied to both `x` and `y` with packed
/// transforms of `count` bones: the same operations in the same order on x, y, z, so the same
/// bits; w lanes are kept.
inline void pretransformPacked(const MuscleSettings& settings, const PackedTransform* packed,
                               size_t count, uint32_t i, btVector3& x, btVector3& y) {
  const btScalar w = settings.blendWeight[i];
  const int32_t a = settings.blendBoneA[i], b = settings.blendBoneB[i];
  const bool useA = a >= 0 && static_cast<size_t>(a) < count && w < 1;
  const bool useB = b >= 0 && static_cast<size_t>(b) < count && w > 0;
  const __m128 shareA = _mm_set1_ps(1 - w), shareB = _mm_set1_ps(w);
  const __m128 xyz = xyzMask();
  for (btVector3* point : {&x, &y}) {
    const __m128 p = _mm_load_ps(point->m_floats);
    __m128 moved = p;
    if (useA)
      moved = _mm_add_ps(moved, _mm_mul_ps(_mm_sub_ps(transformPacked(packed[a], p), p), shareA));
    if (useB)
      moved = _mm_add_ps(moved, _mm_mul_ps(_mm_sub_ps(transformPacked(packed[b], p), p), shareB));
    _mm_store_ps(point->m_floats, _mm_or_ps(_mm_and_ps(xyz, moved), _mm_andnot_ps(xyz, p)));
  }
}
#endif

#if FIBREMSS_AVX2_PARTICLES
/// A PackedTransform in both halves of AVX registers, for two points at once.
struct PackedTransformPair {
  __m256 columns[3];  ///< basis columns, twice
  __m256 origin;      ///< translation, twice
};

/// t·p of the two points in p's halves, with transformPacked's rounding (AVX without FMA).
FIBREMSS_AVX2_PASS inline __m256 transformPair(const PackedTransformPair& t, __m256 p) {
  const __m256 x = _mm256_permute_ps(p, 0x00), y = _mm256_permute_ps(p, 0x55),
               z = _mm256_permute_ps(p, 0xaa);
  return _mm256_add_ps(
      _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(t.columns[0], x), _mm256_mul_ps(t.columns[1], y)),
                    _mm256_mul_ps(t.columns[2], z)),
      t.origin);
}

/// pretransformPacked for each of `particles` with its x and y in the two halves of one
/// register: half the operations, each lane the same as pretransformPacked's, so the same bits.
FIBREMSS_AVX2_PASS inline void pretransformPackedAvx2(const MuscleSettings& settings,
                                                      const PackedTransform* packed, size_t count,
                                                      std::span<const uint32_t> particles,
                                                      btVector3* x, btVector3* y) {
  PackedTransformPair pairs[kPackedBones];
  for (size_t b = 0; b < count; ++b) {
    for (int c = 0; c < 3; ++c) pairs[b].columns[c] = _mm256_broadcast_ps(&packed[b].columns[c]);
    pairs[b].origin = _mm256_broadcast_ps(&packed[b].origin);
  }
  const __m256 xyz = xyzMask8();
  for (uint32_t i : particles) {
    const btScalar w = settings.blendWeight[i];
    const int32_t a = settings.blendBoneA[i], b = settings.blendBoneB[i];
    const __m256 p = loadPair(x[i], y[i]);
    __m256 moved = p;
    if (a >= 0 && static_cast<size_t>(a) < count && w < 1)
      moved = _mm256_add_ps(moved, _mm256_mul_ps(_mm256_sub_ps(transformPair(pairs[a], p), p),
                                                 _mm256_set1_ps(1 - w)));
    if (b >= 0 && static_cast<size_t>(b) < count && w > 0)
      moved = _mm256_add_ps(
          moved, _mm256_mul_ps(_mm256_sub_ps(transformPair(pairs[b], p), p), _mm256_set1_ps(w)));
    moved = _mm256_blendv_ps(p, moved, xyz);  // w lanes kept
    _mm_store_ps(x[i].m_floats, _mm256_castps256_ps128(moved));
    _mm_store_ps(y[i].m_floats, _mm256_extractf128_ps(moved, 1));
  }
}
#endif

}  // namespace fibremss
