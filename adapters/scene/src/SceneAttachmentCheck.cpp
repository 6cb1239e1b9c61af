// attachmentWarnings(): muscles whose fibres end next to a bone that moves relative to the bones
// they are fixed to, with no particle fixed to that bone (they do not follow it).
#include <algorithm>
#include <set>

#include "fibremss/Measures.h"
#include "fibremss/Scene.h"

namespace fibremss {
namespace {

/// Whether bones a and b are ever in different places relative to their rest poses.
bool movesRelative(const LoadedScene& scene, size_t a, size_t b) {
  constexpr btScalar kTolerance = btScalar(1e-6);
  for (int pose = 0; pose < scene.poseCount; ++pose) {
    const btTransform ta = scene.bonePose(a, pose), tb = scene.bonePose(b, pose);
    if (ta.getOrigin().distance(tb.getOrigin()) > kTolerance) return true;
    for (int row = 0; row < 3; ++row)
      if (ta.getBasis()[row].distance(tb.getBasis()[row]) > kTolerance) return true;
  }
  return false;
}

}  // namespace

std::vector<std::string> attachmentWarnings(const LoadedScene& scene,
                                            const PreparedScene& prepared) {
  std::vector<std::string> warnings;
  const size_t boneCount = prepared.bones.size();
  for (const auto& muscle : prepared.muscles) {
    const std::vector<size_t> fixed = fixedParticlesPerBone(*muscle, boneCount);
    // Fibre ends (first and last particles) per nearest bone.
    std::vector<size_t> ends(boneCount, 0);
    for (size_t f = 0; f < muscle->fibreCount(); ++f)
      for (uint32_t k : {muscle->fibreOffsets[f], muscle->fibreOffsets[f + 1] - 1}) {
        const int32_t bone = muscle->nearestBone[muscle->fibreParticles[k]];
        if (bone >= 0) ++ends[size_t(bone)];
      }
    for (size_t b = 0; b < boneCount; ++b) {
      if (ends[b] == 0 || fixed[b] > 0) continue;
      for (size_t c = 0; c < boneCount; ++c) {
        if (fixed[c] == 0 || !movesRelative(scene, b, c)) continue;
        warnings.push_back("muscle '" + muscle->name + "': " + std::to_string(ends[b]) +
                           " fibre ends lie next to bone '" + prepared.bones[b]->name +
                           "', which moves relative to bone '" + prepared.bones[c]->name +
                           "' (where it is fixed), but no particle is fixed to it: the muscle "
                           "will not follow it (declare an origin or insertion on it)");
        break;
      }
    }
  }
  return warnings;
}

}  // namespace fibremss
