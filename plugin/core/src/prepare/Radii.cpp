// Muscle sphere radii (method.md §6): every surface vertex chooses its closest particle; the
// chosen ones are the boundary particles, each with the mean distance to its vertices as
// radius. Then radii shrink until no two bodies overlap at rest.
#include <algorithm>
#include <cmath>

#include "PreparationInternal.h"

namespace fibremss::detail {
namespace {

/// Shrinking leaves this relative gap so that touching spheres stay apart after rounding.
constexpr btScalar kClearance = btScalar(1) - btScalar(1e-5);

/// One boundary particle of some muscle, in the scene-wide lists used for shrinking.
struct SphereRef {
  uint32_t muscle;
  uint32_t particle;
};

btScalar maxOf(std::span<const btScalar> values) {
  btScalar result = 0;
  for (btScalar v : values) result = std::max(result, v);
  return result;
}

/// Caps at its muscle's median sample spacing every sphere that another muscle's sphere
/// comes within that spacing of at rest. A contact pushes a sphere's centre by the overlap
/// depth, up to its radius: where the fibres leave the surface far away, boundary spheres
/// reach 10 mm on 2-6 mm springs, and one push of another muscle then stretches those springs
/// beyond 3× (real-hip, muscles 0 and 1 at 60°). Returns how many spheres were capped.
size_t capNearOtherMuscles(std::vector<MuscleSettings>& muscles, std::span<const SphereRef> spheres,
                           std::span<const btVector3> centres, const KdTree& tree) {
  std::vector<btScalar> spacing(muscles.size()), before(spheres.size());
  for (size_t m = 0; m < muscles.size(); ++m) spacing[m] = medianSampleSpacing(muscles[m]);
  for (size_t s = 0; s < spheres.size(); ++s)
    before[s] = muscles[spheres[s].muscle].radii[spheres[s].particle];
  const btScalar reach = maxOf(before) + maxOf(spacing);
  std::vector<std::pair<uint32_t, btScalar>> found;
  size_t capped = 0;
  for (size_t s = 0; s < spheres.size(); ++s) {
    const btScalar cap = spacing[spheres[s].muscle];
    if (!(cap > 0) || before[s] <= cap) continue;
    tree.within(centres[s], before[s] + reach, found);
    const bool near = std::any_of(found.begin(), found.end(), [&](const auto& hit) {
      const btScalar gap = std::sqrt(hit.second) - before[s] - before[hit.first];
      return spheres[hit.first].muscle != spheres[s].muscle && gap < cap;
    });
    if (!near) continue;
    muscles[spheres[s].muscle].radii[spheres[s].particle] = cap;
    ++capped;
  }
  return capped;
}

}  // namespace

void bindSurface(MuscleSettings& muscle, const KdTree& particles, int skinNeighbours) {
  const size_t particleCount = muscle.particleCount();
  const auto& vertices = muscle.restSurface.vertices;
  const size_t k = std::clamp<size_t>(skinNeighbours, 1, particleCount);
  muscle.skinNeighbours = static_cast<int>(k);
  muscle.skinParticles.assign(vertices.size() * k, 0);
  muscle.skinWeights.assign(vertices.size() * k, 0);
  std::vector<double> distanceSum(particleCount, 0.0);
  std::vector<uint32_t> chosenBy(particleCount, 0);
  std::vector<uint32_t> indices(k);
  std::vector<btScalar> distances2(k);
  std::vector<double> weights(k);
  for (size_t v = 0; v < vertices.size(); ++v) {
    const size_t found = particles.nearest(vertices[v], k, indices.data(), distances2.data());
    distanceSum[indices[0]] += std::sqrt(distances2[0]);
    ++chosenBy[indices[0]];
    // Inverse-distance weights; a vertex sitting on a particle follows that particle alone.
    double total = 0;
    for (size_t j = 0; j < found; ++j) {
      const double distance = std::sqrt(double(distances2[j]));
      weights[j] = distances2[0] > 0 ? 1.0 / distance : (j == 0 ? 1.0 : 0.0);
      total += weights[j];
    }
    for (size_t j = 0; j < found; ++j) {
      muscle.skinParticles[v * k + j] = indices[j];
      muscle.skinWeights[v * k + j] = static_cast<btScalar>(weights[j] / total);
    }
  }
  muscle.radii.assign(particleCount, 0);
  muscle.boundaryParticles.clear();
  for (uint32_t i = 0; i < particleCount; ++i) {
    if (chosenBy[i] == 0) continue;
    muscle.flags[i] |= kBoundary;
    muscle.radii[i] = static_cast<btScalar>(distanceSum[i] / chosenBy[i]);
    muscle.boundaryParticles.push_back(i);
  }
}

namespace {

/// Every muscle's boundary spheres in one list, with their centres.
struct MuscleSpheres {
  std::vector<MuscleSettings>& muscles;  ///< their radii are shrunk in place
  std::vector<SphereRef> spheres;        ///< (muscle, particle) of each sphere
  std::vector<btVector3> centres;        ///< each sphere's rest centre [m]

  btScalar& radius(size_t s) const { return muscles[spheres[s].muscle].radii[spheres[s].particle]; }
  /// Whether sphere s is fixed to `bone` (and so may overlap it).
  bool exempt(size_t s, uint32_t bone) const {
    return muscles[spheres[s].muscle].fixedBone[spheres[s].particle] == int32_t(bone);
  }
};

/// Every bone's spheres in one list, remembering their bone.
struct BoneSpheres {
  std::vector<BoneSettings>& bones;                ///< their radii are shrunk in place
  std::vector<btVector3> centres;                  ///< each sphere's centre [m]
  std::vector<std::pair<uint32_t, uint32_t>> ids;  ///< (bone, sphere) of each

  btScalar& radius(uint32_t k) const { return bones[ids[k].first].sphereRadii[ids[k].second]; }
  btScalar maxRadius() const {
    btScalar largest = 0;
    for (uint32_t k = 0; k < ids.size(); ++k) largest = std::max(largest, radius(k));
    return largest;
  }
};

/// 1. A muscle sphere whose centre lies inside a bone sphere cannot shrink out of it: the bone
/// sphere shrinks instead. Returns how many bone spheres shrank.
size_t shrinkBoneSpheres(const MuscleSpheres& muscle, const BoneSpheres& bone,
                         const KdTree& boneTree,
                         std::vector<std::pair<uint32_t, btScalar>>& found) {
  const btScalar maxBone = bone.maxRadius();
  std::vector<uint8_t> boneShrunk(bone.ids.size(), 0);
  for (size_t s = 0; s < muscle.spheres.size(); ++s) {
    boneTree.within(muscle.centres[s], maxBone, found);
    for (const auto& [k, distance2] : found) {
      if (muscle.exempt(s, bone.ids[k].first)) continue;
      const btScalar distance = std::sqrt(distance2);
      if (distance < bone.radius(k)) {
        bone.radius(k) = distance * kClearance;
        boneShrunk[k] = 1;
      }
    }
  }
  return static_cast<size_t>(std::count(boneShrunk.begin(), boneShrunk.end(), 1));
}

/// 2. Muscle spheres against bone spheres: bones do not give way.
void clearBones(const MuscleSpheres& muscle, const BoneSpheres& bone, const KdTree& boneTree,
                std::vector<std::pair<uint32_t, btScalar>>& found) {
  const btScalar maxBone = bone.maxRadius();
  for (size_t s = 0; s < muscle.spheres.size(); ++s) {
    btScalar& radius = muscle.radius(s);
    boneTree.within(muscle.centres[s], radius + maxBone, found);
    for (const auto& [k, distance2] : found) {
      if (muscle.exempt(s, bone.ids[k].first)) continue;
      const btScalar distance = std::sqrt(distance2);
      if (distance < radius + bone.radius(k))
        radius = std::max(btScalar(0), (distance - bone.radius(k)) * kClearance);
    }
  }
}

/// 3. Muscle against muscle: both spheres of an overlapping pair shrink by the same factor
/// d / (rA + rB), computed from the radii before this pass, so one pass clears all pairs.
void clearMuscles(const MuscleSpheres& muscle, const KdTree& muscleTree,
                  std::vector<std::pair<uint32_t, btScalar>>& found) {
  const std::vector<SphereRef>& spheres = muscle.spheres;
  std::vector<btScalar> before(spheres.size());
  for (size_t s = 0; s < spheres.size(); ++s) before[s] = muscle.radius(s);
  const btScalar maxMuscle = maxOf(before);
  for (size_t s = 0; s < spheres.size(); ++s) {
    if (before[s] <= 0) continue;
    muscleTree.within(muscle.centres[s], before[s] + maxMuscle, found);
    btScalar& radius = muscle.radius(s);
    for (const auto& [t, distance2] : found) {
      if (spheres[t].muscle == spheres[s].muscle) continue;
      const btScalar sum = before[s] + before[t];
      const btScalar distance = std::sqrt(distance2);
      if (distance < sum) radius = std::min(radius, before[s] * (distance / sum) * kClearance);
    }
  }
}

}  // namespace

ShrinkReport shrinkRadii(std::vector<MuscleSettings>& muscles, std::vector<BoneSettings>& bones) {
  ShrinkReport report;
  MuscleSpheres muscle{muscles, {}, {}};
  for (uint32_t m = 0; m < muscles.size(); ++m)
    for (uint32_t i : muscles[m].boundaryParticles) {
      muscle.spheres.push_back({m, i});
      muscle.centres.push_back(muscles[m].restPositions[i]);
    }
  std::vector<btScalar> original(muscle.spheres.size());
  for (size_t s = 0; s < muscle.spheres.size(); ++s) original[s] = muscle.radius(s);

  BoneSpheres bone{bones, {}, {}};
  for (uint32_t b = 0; b < bones.size(); ++b)
    for (uint32_t s = 0; s < bones[b].sphereCentres.size(); ++s) {
      bone.centres.push_back(bones[b].sphereCentres[s]);
      bone.ids.emplace_back(b, s);
    }
  std::vector<std::pair<uint32_t, btScalar>> found;
  if (!bone.centres.empty()) {
    const KdTree boneTree(bone.centres);
    report.boneSpheresShrunk = shrinkBoneSpheres(muscle, bone, boneTree, found);
    clearBones(muscle, bone, boneTree, found);
  }
  if (muscles.size() > 1 && !muscle.spheres.empty()) {
    const KdTree muscleTree(muscle.centres);
    report.muscleSpheresCapped =
        capNearOtherMuscles(muscles, muscle.spheres, muscle.centres, muscleTree);
    clearMuscles(muscle, muscleTree, found);
  }
  for (size_t s = 0; s < muscle.spheres.size(); ++s) {
    const btScalar radius = muscle.radius(s);
    if (radius < original[s]) ++report.muscleSpheresShrunk;
    if (radius <= 0 && original[s] > 0) ++report.muscleSpheresZeroed;
  }
  return report;
}

double surfaceCoverage(const MuscleSettings& muscle) {
  const auto& vertices = muscle.restSurface.vertices;
  if (vertices.empty()) return 0;
  std::vector<btVector3> centres;
  std::vector<btScalar> radii;
  for (uint32_t i : muscle.boundaryParticles) {
    centres.push_back(muscle.restPositions[i]);
    radii.push_back(muscle.radii[i]);
  }
  const KdTree tree(centres);
  const btScalar maxRadius = maxOf(radii);
  std::vector<std::pair<uint32_t, btScalar>> found;
  size_t covered = 0;
  for (const btVector3& v : vertices) {
    tree.within(v, maxRadius, found);
    covered += std::any_of(found.begin(), found.end(), [&](const auto& hit) {
      // On the sphere counts as inside: the vertex that set a radius lies exactly on it.
      return hit.second <= radii[hit.first] * radii[hit.first] * (1 + 1e-5f);
    });
  }
  return double(covered) / vertices.size();
}

}  // namespace fibremss::detail
