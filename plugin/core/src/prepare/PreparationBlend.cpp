// Muscles between bones (method.md §4, §5.3 Fig 5.8): which springs carry no force once
// particles are fixed, and the per-particle blend of two bones' motions that replaces the
// nearest-bone pre-transform, so muscles spanning a joint are not torn apart where the nearest
// bone changes. Measured on thigh13 (resolution 20, walking): weights from the position along
// the fibre between its attachments, and inverse-distance weights between the attachment bones,
// both pushed mid-shaft particles into the bone they lie on (up to 780 springs beyond 3×);
// inverse-square weights between the two nearest bones keep every spring below 2.4× (the
// nearest bone alone: 3.1×).
#include <algorithm>
#include <limits>

#include "PreparationInternal.h"

namespace fibremss::detail {

size_t dropFixedSprings(MuscleSettings& muscle) {
  // Both ends fixed: never integrated, so the spring moves nothing. On one bone it keeps its
  // length; across two bones its length follows the joint and says nothing about the muscle
  // (so it can trip the 3× explosion test at a joint while the muscle itself is whole).
  const size_t before = muscle.springs.size();
  std::erase_if(muscle.springs, [&](const Spring& spring) {
    return muscle.isFixed(spring.a) && muscle.isFixed(spring.b);
  });
  return before - muscle.springs.size();
}

void blendAttachments(MuscleSettings& muscle, size_t boneCount, const BoneDistance& distance) {
  const size_t n = muscle.particleCount();
  constexpr btScalar kInfinity = std::numeric_limits<btScalar>::infinity();
  // Distances below this count as touching (no division by zero for points on a bone) [m].
  constexpr double kTouching = 1e-6;
  muscle.blendBoneA = muscle.nearestBone;
  muscle.blendBoneB = muscle.nearestBone;
  muscle.blendWeight.assign(n, 0);
  if (boneCount < 2) return;
  for (uint32_t p = 0; p < n; ++p) {
    const int32_t nearest = muscle.nearestBone[p];
    if (nearest < 0) continue;
    const btVector3& x = muscle.restPositions[p];
    int32_t second = -1;
    btScalar secondDistance = kInfinity;
    for (int32_t b = 0; b < static_cast<int32_t>(boneCount); ++b) {
      if (b == nearest) continue;
      const btScalar d = distance(x, b, secondDistance);
      if (d < secondDistance) {
        secondDistance = d;
        second = b;
      }
    }
    if (second < 0) continue;
    // Inverse-square distance weights: w = d1² / (d1² + d2²); 0 on the nearest bone, ½ where
    // the nearest bone changes (so the pre-transform is continuous there).
    const double d1 = std::max<double>(distance(x, nearest, kInfinity), kTouching);
    const double d2 = std::max<double>(secondDistance, kTouching);
    muscle.blendBoneB[p] = second;
    muscle.blendWeight[p] = static_cast<btScalar>(d1 * d1 / (d1 * d1 + d2 * d2));
  }
}

}  // namespace fibremss::detail
