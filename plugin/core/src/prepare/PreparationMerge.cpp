// Merging near-coincident particles before springs are built. Fibres generated from a surface
// converge into narrow tendons, so particles of neighbouring fibres end up a fraction of a
// millimetre apart; the springs between them have rest lengths far below the sample spacing
// and trip the 3×-rest-length explosion test after sub-millimetre motion (real-hip beyond
// 25°: rest lengths down to 0.02 mm). One particle standing for such a cluster removes them.
#include <algorithm>

#include "PreparationInternal.h"

namespace fibremss::detail {

btScalar medianSampleSpacing(const MuscleSettings& muscle) {
  std::vector<btScalar> spacing;
  for (size_t f = 0; f < muscle.fibreCount(); ++f) {
    const uint32_t first = muscle.fibreOffsets[f], last = muscle.fibreOffsets[f + 1] - 1;
    // The second particle sits at a random offset; from it on the steps are regular.
    if (last >= first + 2)
      spacing.push_back(muscle.restPositions[muscle.fibreParticles[last]].distance(
                            muscle.restPositions[muscle.fibreParticles[first + 1]]) /
                        btScalar(last - first - 1));
  }
  if (spacing.empty()) return 0;
  std::nth_element(spacing.begin(), spacing.begin() + spacing.size() / 2, spacing.end());
  return spacing[spacing.size() / 2];
}

size_t mergeCloseParticles(MuscleSettings& muscle, btScalar distance) {
  const size_t n = muscle.particleCount();
  if (!(distance > 0) || n == 0) return 0;
  constexpr uint32_t kUnassigned = UINT32_MAX;
  std::vector<uint32_t> keptAs(n, kUnassigned);
  std::vector<btVector3> kept;
  std::vector<uint32_t> fibreOf(n, 0);
  for (uint32_t f = 0; f < muscle.fibreCount(); ++f)
    for (uint32_t k = muscle.fibreOffsets[f]; k < muscle.fibreOffsets[f + 1]; ++k)
      fibreOf[muscle.fibreParticles[k]] = f;
  {
    const KdTree particles(muscle.restPositions);
    std::vector<std::pair<uint32_t, btScalar>> found;
    // Greedy in index order: a particle not yet taken keeps its place and takes every untaken
    // particle of another fibre strictly closer than `distance`. Kept particles of different
    // fibres are therefore at least `distance` apart, and the result does not depend on the
    // tree's traversal order. Along one fibre the spacing is the sampling's (its jittered
    // second particle stays, method.md §2).
    for (uint32_t i = 0; i < n; ++i) {
      if (keptAs[i] != kUnassigned) continue;
      keptAs[i] = static_cast<uint32_t>(kept.size());
      kept.push_back(muscle.restPositions[i]);
      particles.within(muscle.restPositions[i], distance, found);
      for (const auto& [j, distance2] : found)
        if (keptAs[j] == kUnassigned && fibreOf[j] != fibreOf[i] && distance2 < distance * distance)
          keptAs[j] = keptAs[i];
    }
  }
  const size_t merged = n - kept.size();
  if (merged == 0) return 0;
  muscle.restPositions = std::move(kept);
  // Renumber the fibres; a fibre passing twice through the same particle in a row keeps one.
  std::vector<uint32_t> fibreParticles;
  std::vector<uint32_t> fibreOffsets{0};
  for (size_t f = 0; f < muscle.fibreCount(); ++f) {
    const size_t start = fibreParticles.size();
    for (uint32_t k = muscle.fibreOffsets[f]; k < muscle.fibreOffsets[f + 1]; ++k) {
      const uint32_t particle = keptAs[muscle.fibreParticles[k]];
      if (fibreParticles.size() == start || fibreParticles.back() != particle)
        fibreParticles.push_back(particle);
    }
    fibreOffsets.push_back(static_cast<uint32_t>(fibreParticles.size()));
  }
  muscle.fibreParticles = std::move(fibreParticles);
  muscle.fibreOffsets = std::move(fibreOffsets);
  return merged;
}

}  // namespace fibremss::detail
