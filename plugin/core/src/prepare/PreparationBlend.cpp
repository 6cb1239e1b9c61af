// Muscles between bones (method.md §4, §5.3 Fig 5.8): which springs carry no force once
// particles are fixed, and the per-particle blend of two bones' motions that replaces the
// nearest-bone pre-transform, so muscles spanning a joint are not torn apart where the nearest
// bone changes. Measured on thigh13 (resolution 20, walking): weights from the position along
// the fibre between its attachments, and inverse-distance weights between the attachment bones,
// both pushed mid-shaft particles into the bone they lie on (up to 780 springs beyond 3×);
// inverse-square weights between the two nearest bones keep every spring below 2.4× (the
// nearest bone alone: 3.1×). Less the third-nearest bone's inverse square, so that a particle's
// share of its second bone fades to 0 where that bone changes: with the plain inverse squares two
// neighbours whose second bones differed (patella and pelvis, each about 8 %) moved apart by
// millimetres when the knee turned in one iteration (thigh13 R=20, 1 iteration per pose: 7 steps
// rolled back; none with this blend).
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

/// The second-nearest bone's share w of a particle d1 ≤ d2 ≤ d3 from its three nearest bones [m]:
/// inverse-square weights less the third bone's, w = (1/d2² − 1/d3²) / (1/d1² + 1/d2² − 2/d3²),
/// written as (d1² − c) / (d1² + d2² − 2c) with c = d1²·d2²/d3², which with no third bone (d3 = ∞,
/// c = 0) is d1² / (d1² + d2²) to the bit. w is ½ where d1 = d2 (the nearest bone changes) and 0
/// where d2 = d3 (the second-nearest bone changes), so the pre-transform is continuous at both.
double blendWeight(double d1, double d2, double d3) {
  const double c = d1 * d1 * d2 * d2 / (d3 * d3);
  const double total = d1 * d1 + d2 * d2 - 2 * c;
  return total > 0 ? std::clamp((d1 * d1 - c) / total, 0.0, 1.0) : 0.5;
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
    btScalar secondDistance = kInfinity, thirdDistance = kInfinity;
    for (int32_t b = 0; b < static_cast<int32_t>(boneCount); ++b) {
      if (b == nearest) continue;
      const btScalar d = distance(x, b, thirdDistance);
      if (d < secondDistance) {
        thirdDistance = secondDistance;
        secondDistance = d;
        second = b;
      } else if (d < thirdDistance) {
        thirdDistance = d;
      }
    }
    if (second < 0) continue;
    muscle.blendBoneB[p] = second;
    muscle.blendWeight[p] = static_cast<btScalar>(
        blendWeight(std::max<double>(distance(x, nearest, kInfinity), kTouching),
                    std::max<double>(secondDistance, kTouching), thirdDistance));
  }
}

}  // namespace fibremss::detail
