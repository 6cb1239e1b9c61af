// Where two bones close across a muscle: the poses a static continuum reference cannot have.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "fibremss/CalculixReference.h"

namespace fibremss {
namespace {

constexpr double kMaxGridPoints = 1e5;  ///< per muscle's bounding box
constexpr btScalar kFar = std::numeric_limits<btScalar>::infinity();

/// Grid points inside the muscle's surface, spaced half its attachment distance (or wider, so
/// that its bounding box holds at most kMaxGridPoints).
std::vector<btVector3> volumeSamples(const TriangleMesh& surface, btScalar attachment) {
  btVector3 low, high;
  pointBounds(surface.vertices, low, high);
  const btVector3 size = high - low;
  const double box = double(size.x()) * double(size.y()) * double(size.z());
  const btScalar spacing =
      std::max(attachment / 2, btScalar(std::cbrt(std::max(box, 0.0) / kMaxGridPoints)));
  const MeshDistance inside(surface);
  std::vector<btVector3> samples;
  for (btScalar x = low.x() + spacing / 2; x < high.x(); x += spacing)
    for (btScalar y = low.y() + spacing / 2; y < high.y(); y += spacing)
      for (btScalar z = low.z() + spacing / 2; z < high.z(); z += spacing)
        if (inside.inside({x, y, z})) samples.emplace_back(x, y, z);
  return samples;
}

/// Per pair of bones (a < b, row-major), the smallest d_a + d_b over the samples with both
/// within `bound` [m] (kFar where none); inside a bone counts as 0. `transforms`: each bone's.
std::vector<btScalar> pairGaps(const std::vector<btVector3>& samples,
                               const std::vector<MeshDistance>& bones,
                               const std::vector<btTransform>& transforms, btScalar bound) {
  const size_t n = bones.size();
  std::vector<btScalar> gaps(n * n, kFar), distance(n);
  std::vector<btTransform> inverse;
  for (const btTransform& t : transforms) inverse.push_back(t.inverse());
  for (const btVector3& x : samples) {
    for (size_t b = 0; b < n; ++b) {
      const MeshDistance::Closest c = bones[b].closest(inverse[b] * x, bound);
      distance[b] = c.inside ? 0 : c.distance;
    }
    for (size_t a = 0; a < n; ++a)
      for (size_t b = a + 1; b < n && distance[a] < bound; ++b)
        gaps[a * n + b] = std::min(gaps[a * n + b], distance[a] + distance[b]);
  }
  return gaps;
}

/// Why pose's pair (a, b) cuts the muscle; `scale`: × its attachment distance (said when not 1).
std::string reasonText(const LoadedScene& scene, size_t a, size_t b, size_t muscle, btScalar gap,
                       btScalar rest, btScalar bound, btScalar scale) {
  char times[32] = "";
  if (scale != 1) std::snprintf(times, sizeof times, "%gx ", double(scale));
  char text[512];
  std::snprintf(text, sizeof text,
                "no continuum equilibrium: bones %s and %s close to %.1f mm across muscle %s "
                "(%s at rest), below twice %sits attachment distance (%.1f mm): the material "
                "between them would move with both, so the muscle must be cut",
                scene.bones[a].name.c_str(), scene.bones[b].name.c_str(), 1000 * double(gap),
                scene.muscles[muscle].name.c_str(),
                std::isinf(rest)
                    ? "farther than that"
                    : (std::to_string(std::lround(1000 * double(rest))) + " mm").c_str(),
                times, 1000 * double(bound));
  return text;
}

}  // namespace

ContinuumSamples sampleContinuum(const LoadedScene& scene) {
  ContinuumSamples samples;
  for (const MuscleInput& muscle : scene.muscles) {
    const btScalar attachment = muscle.parameters.attachmentDistance;
    samples.muscles.push_back(muscle.surface.vertices.empty() || !(attachment > 0)
                                  ? std::vector<btVector3>()
                                  : volumeSamples(muscle.surface, attachment));
  }
  return samples;
}

ContinuumCut findContinuumCut(const LoadedScene& scene, const std::vector<MeshDistance>& bones,
                              const ContinuumSamples& samples, btScalar attachmentScale) {
  ContinuumCut cut;
  const size_t n = bones.size();
  if (n < 2) return cut;
  const int poses = std::max(scene.poseCount, 1);
  for (size_t m = 0; m < scene.muscles.size() && m < samples.muscles.size(); ++m) {
    const std::vector<btVector3>& inside = samples.muscles[m];
    const btScalar bound = 2 * scene.muscles[m].parameters.attachmentDistance * attachmentScale;
    if (inside.empty() || !(bound > 0)) continue;
    const std::vector<btScalar> rest =
        pairGaps(inside, bones, std::vector<btTransform>(n, btTransform::getIdentity()), bound);
    const int last = cut.pose < 0 ? poses : cut.pose;  // an earlier muscle's cut stands
    for (int p = 0; p < last; ++p) {
      std::vector<btTransform> transforms;
      for (size_t b = 0; b < n; ++b) transforms.push_back(scene.bonePose(b, p));
      const std::vector<btScalar> gaps = pairGaps(inside, bones, transforms, bound);
      for (size_t pair = 0; pair < gaps.size(); ++pair) {
        if (!(gaps[pair] < bound) || rest[pair] < bound) continue;  // closed already at rest
        cut = {p, 1000 * double(gaps[pair]),
               reasonText(scene, pair / n, pair % n, m, gaps[pair], rest[pair], bound,
                          attachmentScale)};
        break;
      }
      if (cut.pose == p) break;
    }
  }
  return cut;
}

}  // namespace fibremss
