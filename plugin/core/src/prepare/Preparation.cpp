// prepareScene(): bones first (distance trees and spheres), then every muscle on its own
// (particles, springs, fixed and boundary particles, radii, skinning), then the scene-wide
// radius shrinking. Bones and muscles are prepared in parallel; every random choice comes
// from a generator seeded by (seed, body), so the result does not depend on the threads.
#include "fibremss/Preparation.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <limits>
#include <optional>
#include <system_error>
#include <thread>
#include <utility>

#include "PreparationInternal.h"
#include "PreparationReorder.h"
#include "fibremss/DeclaredAreas.h"
#include "fibremss/Error.h"
#include "fibremss/TaskPool.h"

namespace fibremss {
namespace {

using detail::KdTree;

enum RandomStream : uint32_t { kFibreJitter = 1, kSphereThinning = 2 };

/// Particles of different fibres closer than this share of the median sample spacing merge when
/// the input asks for it (lattice layouts excepted: their springs follow the grid's indices).
constexpr btScalar kMergeFraction = btScalar(0.25);
/// Particles of one fibre closer than this fraction of the median sample spacing coincide.
constexpr btScalar kCoincidentFraction = btScalar(1e-6);
/// Surface vertices inside a bone at rest move this share of the spacing beyond its surface.
constexpr btScalar kSurfaceMarginFraction = btScalar(0.01);

/// Who runs preparation's tasks: the host's scheduler when present, else up to `threads`
/// threads started for each batch (TaskPool::resolve: 0 is the hardware threads).
struct Workers {
  int threads = 0;            ///< MuscleSystemDef::threads
  const TaskScheduler& host;  ///< MuscleSystemDef::scheduler
};

/// Runs task(i) for i in [0, count) on `workers`; rethrows the exception of the lowest failing i.
template <typename Task>
void parallelFor(size_t count, const Workers& workers, Task task) {
  std::vector<std::exception_ptr> errors(count);
  const auto run = [&](size_t i) {
    try {
      task(i);
    } catch (...) {
      errors[i] = std::current_exception();
    }
  };
  if (workers.host.present()) {
    TaskPool(1, workers.host).run(count, [&](size_t i, unsigned) { run(i); });
  } else {
    std::atomic<size_t> next{0};
    auto worker = [&] {
      for (size_t i = next++; i < count; i = next++) run(i);
    };
    const size_t used = std::min<size_t>(count, TaskPool::resolve(workers.threads));
    std::vector<std::thread> pool;
    try {
      for (size_t t = 1; t < used; ++t) pool.emplace_back(worker);
    } catch (const std::system_error&) {
      // The system allows no more threads: those started do the work (the same results).
    }
    worker();
    for (auto& thread : pool) thread.join();
  }
  for (const auto& error : errors)
    if (error) std::rethrow_exception(error);
}

btScalar boxDistance(const btVector3& p, const btVector3& lower, const btVector3& upper) {
  const btVector3 below = lower - p, above = p - upper;
  btVector3 outside(0, 0, 0);
  outside.setMax(below);
  outside.setMax(above);
  return outside.length();
}

/// A bone as preparation sees it: its distance tree and bounds.
struct BoneShape {
  std::unique_ptr<MeshDistance> distance;
  btVector3 lower{0, 0, 0}, upper{0, 0, 0};
};

/// The closest bone surface point: which bone, how far, and whether p is inside that bone.
struct NearestBone {
  int32_t bone = -1;
  btScalar distance = std::numeric_limits<btScalar>::infinity();
  bool inside = false;
};

/// Bones are tried nearest-box first so that the distance limit prunes the others at their root.
NearestBone nearestBone(const btVector3& p, const std::vector<BoneShape>& bones,
                        std::vector<std::pair<btScalar, uint32_t>>& order) {
  order.clear();
  for (uint32_t b = 0; b < bones.size(); ++b)
    order.emplace_back(boxDistance(p, bones[b].lower, bones[b].upper), b);
  std::sort(order.begin(), order.end());
  NearestBone best;
  for (const auto& [boxDistanceToBone, b] : order) {
    if (boxDistanceToBone > best.distance) break;
    const MeshDistance::Closest closest = bones[b].distance->closest(p, best.distance);
    if (closest.triangle != UINT32_MAX && (best.bone < 0 || closest.distance < best.distance))
      best = {static_cast<int32_t>(b), closest.distance, closest.inside};
  }
  return best;
}

/// Indices in range and finite coordinates: what every later stage relies on.
/// What checkMesh and checkFibres expect of a point.
const char* const kWithinWorld =
    "coordinates must be finite numbers within 1e6 m (1000 km) of the origin; are the units "
    "right?";

void checkMesh(const std::string& source, const std::string& field, const TriangleMesh& mesh) {
  if (mesh.empty()) throw InputError(source, field, "the mesh has no triangles");
  for (size_t v = 0; v < mesh.vertices.size(); ++v)
    if (!withinWorld(mesh.vertices[v]))
      throw InputError(source, field + " vertex " + std::to_string(v), kWithinWorld);
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    for (uint32_t index : mesh.triangles[t])
      if (index >= mesh.vertices.size())
        throw InputError(source, field + " triangle " + std::to_string(t),
                         "vertex index " + std::to_string(index) + " is out of range (" +
                             std::to_string(mesh.vertices.size()) + " vertices)");
}

void checkFibres(const std::string& source, const FibreSet& fibres) {
  if (fibres.offsets.empty() || fibres.offsets.front() != 0 ||
      fibres.offsets.back() != fibres.points.size() ||
      !std::is_sorted(fibres.offsets.begin(), fibres.offsets.end()))
    throw InputError(source, "fibres", "fibre offsets do not match the fibre points");
  for (size_t i = 0; i < fibres.points.size(); ++i)
    if (!withinWorld(fibres.points[i]))
      throw InputError(source, "fibre point " + std::to_string(i), kWithinWorld);
}

/// Whether bone b may fix particles of the muscle: any bone, or with declared attachments only
/// the bones they name.
bool mayFix(const MuscleInput& input, size_t b) {
  if (input.attachments.empty()) return true;
  return std::any_of(
      input.attachments.begin(), input.attachments.end(), [b](const DeclaredAttachment& area) {
        return std::find(area.bones.begin(), area.bones.end(), b) != area.bones.end();
      });
}

/// A length for messages, "1.23 mm".
std::string mm(btScalar metres) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g mm", double(metres) * 1000);
  return std::string(text);
}

/// One sentence per repair preparation made to a muscle (empty counts are left out).
void describeRepairs(const MuscleInput& muscle, const MusclePreparationReport& report,
                     const std::vector<BoneInput>& bones, const std::vector<MuscleInput>& muscles,
                     std::vector<std::string>& repairs) {
  const std::string source = detail::muscleSource(muscle);
  if (report.mergedParticles > 0)
    repairs.push_back(source + ": " + std::to_string(report.mergedParticles) + " of " +
                      std::to_string(report.sampledParticles) +
                      " particles merged into a particle of another fibre closer than " +
                      mm(report.mergeDistance) + " (converging fibres); shortest spring " +
                      mm(report.shortestSpring));
  for (size_t other = 0; other < report.pushedOutOfMuscles.size(); ++other)
    if (report.pushedOutOfMuscles[other] > 0)
      repairs.push_back(source + ": " + std::to_string(report.pushedOutOfMuscles[other]) +
                        " particles inside muscle '" + muscles[other].name +
                        "' at rest moved out along its normal (the surfaces overlap)");
  for (size_t b = 0; b < bones.size(); ++b) {
    if (report.pushedOutOfBones[b] > 0)
      repairs.push_back(source + ": " + std::to_string(report.pushedOutOfBones[b]) +
                        " free particles inside bone '" + bones[b].name +
                        "' at rest (the deepest " + mm(report.pushedOutOfBonesDepth[b]) +
                        ") moved out along its normal" +
                        (muscle.attachments.empty() ? " (now fixed to it)"
                         : mayFix(muscle, b)        ? " (fixed to it when in an attachment area)"
                                                    : " (free: they meet it through collision)"));
    if (report.surfaceVerticesPushedOut[b] > 0)
      repairs.push_back(source + ": " + std::to_string(report.surfaceVerticesPushedOut[b]) +
                        " surface vertices inside bone '" + bones[b].name +
                        "' at rest moved out along its normal");
  }
}

std::string join(const std::vector<std::string>& parts) {
  std::string joined;
  for (const auto& part : parts) joined += (joined.empty() ? "" : "; ") + part;
  return joined;
}

/// A muscle's declared attachment areas (MuscleInput::attachments): which bone, if any, fixes a
/// particle (declaredAreaBones).
class DeclaredAreas {
 public:
  DeclaredAreas(const std::vector<DeclaredAttachment>& areas, btScalar attachmentDistance,
                const std::vector<btVector3>& surface, std::vector<const MeshDistance*> bones)
      : declared_(areas),
        attachment_(attachmentDistance),
        bones_(std::move(bones)),
        surface_(surface) {
    for (const DeclaredAttachment& area : areas) {
      std::vector<btVector3> points;
      for (uint32_t v : area.surfaceVertices) points.push_back(surface[v]);
      areaPoints_.push_back(std::move(points));
    }
    for (const auto& points : areaPoints_) areas_.push_back(std::make_unique<KdTree>(points));
    fixedCount_.assign(areas_.size(), 0);
  }

  /// The bone that fixes particle position `p` (-1: free): the nearest bone of the areas it
  /// belongs to.
  int32_t boneFor(const btVector3& p) {
    const btScalar toSurface = nearestDistance(surface_, p);
    int32_t best = -1, bestArea = -1;
    btScalar bestDistance = attachment_;
    for (size_t a = 0; a < areas_.size(); ++a) {
      if (nearestDistance(*areas_[a], p) - toSurface > attachment_) continue;
      for (uint32_t b : declared_[a].bones) {
        const btScalar d = bones_[b]->closest(p, bestDistance).distance;
        if (d < bestDistance) {
          bestDistance = d;
          best = static_cast<int32_t>(b);
          bestArea = static_cast<int32_t>(a);
        }
      }
    }
    if (bestArea >= 0) ++fixedCount_[size_t(bestArea)];
    return best;
  }

  /// A warning per area of `input` that fixed no particle.
  void warnEmpty(const MuscleInput& input, const std::vector<BoneInput>& boneInputs,
                 std::vector<std::string>& warnings) const {
    for (size_t a = 0; a < areas_.size(); ++a) {
      if (fixedCount_[a] > 0) continue;
      const DeclaredAttachment& area = declared_[a];
      std::string names;
      for (uint32_t b : area.bones)
        names += (names.empty() ? "'" : ", '") + boneInputs[b].name + "'";
      warnings.push_back(detail::muscleSource(input) + ": the " + area.name +
                         " fixes no particle: none lies within the attachment distance of " +
                         names +
                         " where the area meets the surface (raise attachment_distance "
                         "or move the area)");
    }
  }

 private:
  static btScalar nearestDistance(const KdTree& tree, const btVector3& p) {
    uint32_t index = 0;
    btScalar distance2 = 0;
    if (tree.nearest(p, 1, &index, &distance2) == 0)
      return std::numeric_limits<btScalar>::infinity();
    return std::sqrt(distance2);
  }

  const std::vector<DeclaredAttachment>& declared_;
  btScalar attachment_;
  std::vector<const MeshDistance*> bones_;
  KdTree surface_;
  std::vector<std::vector<btVector3>> areaPoints_;  ///< per area, its vertices (trees' storage)
  std::vector<std::unique_ptr<KdTree>> areas_;
  std::vector<size_t> fixedCount_;  ///< per area, particles it fixed
};

/// The bones' distance trees in the bones' order.
std::vector<const MeshDistance*> distances(const std::vector<BoneShape>& bones) {
  std::vector<const MeshDistance*> trees;
  for (const BoneShape& bone : bones) trees.push_back(bone.distance.get());
  return trees;
}

/// Whether some fibre holds a fixed particle in its first half (the origin) and in its last half
/// (the insertion).
std::pair<bool, bool> fixedEnds(const MuscleSettings& muscle) {
  bool origin = false, insertion = false;
  for (size_t f = 0; f < muscle.fibreCount(); ++f) {
    const uint32_t first = muscle.fibreOffsets[f], count = muscle.fibreOffsets[f + 1] - first;
    for (uint32_t k = 0; k < count; ++k)
      if (muscle.isFixed(muscle.fibreParticles[first + k]))
        (2 * k < count ? origin : insertion) = true;
  }
  return {origin, insertion};
}

/// An end that holds no fixed particle and is not declared free is an InputError naming it.
void requireFixedEnds(const MuscleInput& input, const MuscleSettings& muscle) {
  const FreeEnds free = input.parameters.freeEnds;
  if (free == FreeEnds::Both) return;
  const auto [origin, insertion] = fixedEnds(muscle);
  const bool originMissing = !origin && free != FreeEnds::Origin;
  if (!originMissing && (insertion || free == FreeEnds::Insertion)) return;
  const std::string end = originMissing ? "origin" : "insertion";
  const std::string where = input.attachments.empty()
                                ? "within the attachment distance of a bone"
                                : "in the declared " + end + " area within the attachment distance";
  throw InputError(detail::muscleSource(input), "free_end",
                   "no particle is fixed at its " + end + " (the fibres' " +
                       (originMissing ? "first" : "last") + " half): none lies " + where + " (" +
                       mm(input.parameters.attachmentDistance) +
                       "); raise attachment_distance, move the area, or declare the end free "
                       "(\"free_end\": \"" +
                       end + "\")");
}

/// Fibres ending within `attachment` of a bone whose last particle (ΔL − δ short of the end)
/// stays free; none where declared areas choose the fixed particles.
size_t looseFibreEnds(const MuscleInput& input, const std::vector<BoneShape>& bones,
                      const MuscleSettings& muscle,
                      std::vector<std::pair<btScalar, uint32_t>>& order) {
  const btScalar attachment = input.parameters.attachmentDistance;
  size_t loose = 0;
  for (size_t f = 0; input.attachments.empty() && f < muscle.fibreCount(); ++f) {
    const auto fibre = input.fibres.fibre(f);
    const uint32_t last = muscle.fibreParticles[muscle.fibreOffsets[f + 1] - 1];
    if (!muscle.isFixed(last) && nearestBone(fibre.back(), bones, order).distance < attachment)
      ++loose;
  }
  return loose;
}

/// Fixed particles, nearest bones and the warnings about attachments; returns the loose fibre
/// ends (looseFibreEnds).
size_t attachToBones(const MuscleInput& input, const std::vector<BoneShape>& bones,
                     const std::vector<BoneInput>& boneInputs, MuscleSettings& muscle,
                     std::vector<std::string>& warnings) {
  const size_t n = muscle.particleCount();
  const btScalar attachment = input.parameters.attachmentDistance;
  muscle.fixedBone.assign(n, -1);
  muscle.nearestBone.assign(n, -1);
  muscle.fixedParticles.clear();
  if (bones.empty()) return 0;
  std::optional<DeclaredAreas> declared;
  if (!input.attachments.empty())
    declared.emplace(input.attachments, attachment, muscle.restSurface.vertices, distances(bones));
  std::vector<std::pair<btScalar, uint32_t>> order;
  std::vector<size_t> insideCount(bones.size(), 0);
  for (uint32_t i = 0; i < n; ++i) {
    const btVector3& p = muscle.restPositions[i];
    const NearestBone nearest = nearestBone(p, bones, order);
    muscle.nearestBone[i] = nearest.bone;
    if (nearest.bone < 0) continue;
    const int32_t fixedTo = declared                        ? declared->boneFor(p)
                            : nearest.distance < attachment ? nearest.bone
                                                            : -1;
    if (fixedTo >= 0) {
      muscle.fixedBone[i] = fixedTo;
      muscle.flags[i] |= kFixed;
      muscle.fixedParticles.push_back(i);
    }
    // Fibre ends reaching into their bone are normal; a free particle inside is not.
    if (nearest.inside && !muscle.isFixed(i)) ++insideCount[nearest.bone];
  }
  for (size_t b = 0; b < bones.size(); ++b)
    if (insideCount[b] > 0)
      warnings.push_back(detail::muscleSource(input) + ": " + std::to_string(insideCount[b]) +
                         " free (not fixed) particles lie inside bone '" + boneInputs[b].name +
                         "' at rest that preparation could not move out (they lie inside "
                         "another body too); collisions push them when they can");
  requireFixedEnds(input, muscle);
  if (declared) declared->warnEmpty(input, boneInputs, warnings);
  return looseFibreEnds(input, bones, muscle, order);
}

/// Declared areas must name surface vertices and bones that exist.
void checkAttachments(const MuscleInput& input, size_t boneCount) {
  const std::string source = detail::muscleSource(input);
  for (const DeclaredAttachment& area : input.attachments) {
    if (area.surfaceVertices.empty())
      throw InputError(source, area.name, "the attachment area holds no surface vertex");
    if (area.bones.empty())
      throw InputError(source, area.name, "names no bone to fix its particles to");
    for (uint32_t v : area.surfaceVertices)
      if (v >= input.surface.vertices.size())
        throw InputError(source, area.name,
                         "surface vertex " + std::to_string(v) + " is out of range (" +
                             std::to_string(input.surface.vertices.size()) + " vertices)");
    for (uint32_t b : area.bones)
      if (b >= boneCount)
        throw InputError(source, area.name,
                         "bone " + std::to_string(b) + " is out of range (" +
                             std::to_string(boneCount) + " bones)");
  }
}

/// The first stage of a muscle: checks its input, samples its fibres.
MuscleSettings sampleMuscle(const MuscleInput& input, size_t index, size_t boneCount,
                            uint32_t seed) {
  const std::string source = detail::muscleSource(input);
  checkMesh(source, "surface", input.surface);
  checkFibres(source, input.fibres);
  checkAttachments(input, boneCount);
  const MuscleParameters& parameters = input.parameters;
  if (!(parameters.attachmentDistance >= 0))
    throw InputError(source, "attachment_distance", "must not be negative");
  if (!(parameters.springs.density > 0))
    throw InputError(source, "springs.density", "must be positive");
  if (parameters.springs.volumeStiffness < 0 &&
      !(parameters.springs.poissonRatio >= btScalar(0.25) && parameters.springs.poissonRatio < 0.5))
    throw InputError(source, "springs.poissonRatio",
                     "must lie in [0.25, 0.5) to set the volume multiple");
  if (parameters.skinNeighbours < 1)
    throw InputError(source, "skin_neighbours", "must be at least 1");
  MuscleSettings muscle;
  muscle.name = input.name;
  muscle.restSurface = input.surface;
  std::mt19937 random = detail::bodyRandom(seed, kFibreJitter, index);
  detail::sampleFibres(input, random, muscle);
  return muscle;
}

/// Two particles of one fibre that the push out of the bones put on the same point, up to
/// `tolerance` [m] (a muscle reaching into a bone deeper than the attachment distance, along its
/// fibres) are an InputError naming attachment_distance, not the zero-length (or, in double,
/// rounding-length) spring the springs would make of them.
void requireDistinctPushedParticles(const MuscleInput& input, const MuscleSettings& muscle,
                                    const MusclePreparationReport& report, btScalar tolerance) {
  const auto deepest =
      std::max_element(report.pushedOutOfBonesDepth.begin(), report.pushedOutOfBonesDepth.end());
  if (deepest == report.pushedOutOfBonesDepth.end() || !(*deepest > 0)) return;
  for (size_t f = 0; f < muscle.fibreCount(); ++f)
    for (uint32_t k = muscle.fibreOffsets[f] + 1; k < muscle.fibreOffsets[f + 1]; ++k) {
      const uint32_t a = muscle.fibreParticles[k - 1], b = muscle.fibreParticles[k];
      if (a == b ||
          muscle.restPositions[a].distance2(muscle.restPositions[b]) > tolerance * tolerance)
        continue;
      throw InputError(
          detail::muscleSource(input), "attachment_distance",
          "particles " + std::to_string(a) + " and " + std::to_string(b) + " of fibre " +
              std::to_string(f) + " lie inside a bone deeper than the attachment distance (" +
              mm(input.parameters.attachmentDistance) +
              ") and were pushed out onto the same point; raise attachment_distance above the "
              "muscle's depth in the bone (the deepest particle: " +
              mm(*deepest) +
              ") so that the bone fixes them where they lie, or move the muscle "
              "out of the bone");
    }
}

/// The second stage: rest-pose overlaps moved out (free particles deep in a bone, particles
/// inside an earlier muscle, surface vertices inside a bone), then near-coincident particles
/// merged. `surfaces` holds every muscle's surface distance tree.
void separateMuscle(const MuscleInput& input, size_t index, const std::vector<BoneShape>& bones,
                    const std::vector<std::unique_ptr<MeshDistance>>& surfaces,
                    MuscleSettings& muscle, MusclePreparationReport& report) {
  report.sampledParticles = muscle.particleCount();
  const btScalar spacing = detail::medianSampleSpacing(muscle);
  const btScalar margin = kMergeFraction * spacing;
  report.pushedOutOfMuscles.assign(surfaces.size(), 0);
  for (size_t other = 0; other < index; ++other)
    report.pushedOutOfMuscles[other] =
        detail::pushOutOf(muscle.restPositions, *surfaces[other], 0, margin).count;
  report.pushedOutOfBones.assign(bones.size(), 0);
  report.pushedOutOfBonesDepth.assign(bones.size(), 0);
  report.surfaceVerticesPushedOut.assign(bones.size(), 0);
  for (size_t b = 0; b < bones.size(); ++b)
    report.surfaceVerticesPushedOut[b] =
        detail::pushOutOf(muscle.restSurface.vertices, *bones[b].distance, 0,
                          kSurfaceMarginFraction * spacing)
            .count;
  // Declared areas as attachToBones will see them (on the surface as moved out).
  std::optional<DeclaredAreas> declared;
  if (!input.attachments.empty())
    declared.emplace(input.attachments, input.parameters.attachmentDistance,
                     muscle.restSurface.vertices, distances(bones));
  for (size_t b = 0; b < bones.size(); ++b) {
    // Particles within the attachment distance that the bone fixes may stay inside it.
    const btScalar depth = mayFix(input, b) ? input.parameters.attachmentDistance : btScalar(0);
    const auto fixedHere = [&](const btVector3& p) {
      return !declared || declared->boneFor(p) == static_cast<int32_t>(b);
    };
    const detail::PushedOut pushed =
        detail::pushOutOf(muscle.restPositions, *bones[b].distance, depth, margin, fixedHere);
    report.pushedOutOfBones[b] = pushed.count;
    report.pushedOutOfBonesDepth[b] = pushed.deepest;
  }
  const SpringLayout layout = input.parameters.springs.layout;
  if (input.mergeConverging && layout != SpringLayout::Lattice6 &&
      layout != SpringLayout::Lattice26) {
    report.mergeDistance = margin;
    report.mergedParticles = detail::mergeCloseParticles(muscle, report.mergeDistance);
  }
  requireDistinctPushedParticles(input, muscle, report, kCoincidentFraction * spacing);
}

/// Σ k·L0² over the springs [N·m]: the network's modulus times 3V.
double springNetworkModulus(std::span<const Spring> springs) {
  double network = 0;
  for (const Spring& spring : springs)
    network += double(spring.stiffness) * spring.restLength * spring.restLength;
  return network;
}

/// The last stage: springs, attachments, tendons, damping, blend weights, skinning.
void finishMuscle(const MuscleInput& input, const std::vector<BoneShape>& bones,
                  const std::vector<BoneInput>& boneInputs, std::vector<std::string>& warnings,
                  MuscleSettings& muscle, MusclePreparationReport& report) {
  const std::string source = detail::muscleSource(input);
  const MuscleParameters& parameters = input.parameters;
  const size_t n = muscle.particleCount();
  muscle.flags.assign(n, 0);

  const btScalar volume = meshVolume(input.surface);
  if (!(std::abs(volume) > 0))
    throw InputError(source, "surface", "encloses no volume (open or flat surface?)");
  if (volume < 0)
    warnings.push_back(source + ": the surface's normals point inward (negative volume)");
  muscle.particleMass = parameters.springs.density * std::abs(volume) / btScalar(n);

  const KdTree particles(muscle.restPositions);
  muscle.springs =
      detail::buildSprings(input, muscle.restPositions, particles, detail::fibreDirections(muscle));
  const bool byVolume = parameters.springs.stiffness == SpringStiffness::Volume;
  // The Delaunay only where the springs or a volume term use it.
  std::vector<detail::Tetrahedron> interior;
  const double multiple = volumeMultiple(parameters.springs);
  if (byVolume || multiple > 0 || parameters.springs.enclosedVolumeStiffness > 0)
    interior = detail::interiorTetrahedra(input, muscle.restPositions, muscle.restSurface);
  if (byVolume && !detail::shareStiffnessByVolume(muscle.restPositions, interior, muscle.springs))
    warnings.push_back(source +
                       ": the particles enclose no volume to share the springs' stiffness by; "
                       "they keep k = κ/L0 (spring_stiffness \"length\")");
  // The local volume terms' tetrahedra: the interior ones, or a coarser set's.
  std::vector<detail::Tetrahedron> coarse;
  const bool coarsened = multiple > 0 && parameters.springs.volumeCoarsening > 1;
  if (coarsened)
    coarse = detail::coarseTetrahedra(input, muscle.restPositions, particles, muscle.restSurface,
                                      parameters.springs.volumeCoarsening);
  report.looseFibreEnds = attachToBones(input, bones, boneInputs, muscle, warnings);
  if (detail::dropFixedSprings(muscle) > 0 && muscle.springs.empty())
    warnings.push_back(source + ": every spring links two fixed particles, nothing moves");
  muscle.damping = parameters.springs.damping >= 0
                       ? parameters.springs.damping
                       : parameters.springs.dampingScale *
                             detail::zelenyDamping(muscle.springs, muscle.particleMass);
  muscle.strainLimit = parameters.springs.strainLimit;
  muscle.breakStretch = parameters.springs.breakStretch;
  // The belly's material sets the damping and the volume terms' modulus; tendons are stiffer.
  const double network = springNetworkModulus(muscle.springs);
  report.tendonSprings =
      detail::stiffenTendons(muscle, parameters.tendonFraction, parameters.tendonStiffness);
  report.tendonParticles = size_t(std::count_if(muscle.flags.begin(), muscle.flags.end(),
                                                [](uint8_t f) { return f & kTendon; }));
  detail::blendAttachments(
      muscle, bones.size(), [&](const btVector3& p, int32_t bone, btScalar limit) {
        return bones[static_cast<size_t>(bone)].distance->closest(p, limit).distance;
      });
  detail::bindSurface(muscle, particles, parameters.skinNeighbours);
  const std::vector<uint32_t> order = detail::mortonOrder(muscle.restPositions);
  detail::reorderParticles(muscle, order);
  detail::renumberTetrahedra(interior, order);
  detail::renumberTetrahedra(coarse, order);
  muscle.restVolume = meshVolume(muscle.restSurface);
  // The bulk modulus as a multiple of the network's Young's modulus E = Σk·L0² / 3V.
  const double youngs = muscle.restVolume != 0 ? network / (3 * std::abs(muscle.restVolume)) : 0;
  muscle.volumeModulus = static_cast<btScalar>(multiple * youngs);
  detail::buildVolumeTetrahedra(muscle, coarsened ? coarse : interior);
  muscle.enclosedModulus =
      static_cast<btScalar>(parameters.springs.enclosedVolumeStiffness * youngs);
  detail::buildEnclosedVolume(muscle, interior);
  report.shortestSpring = muscle.springs.empty() ? 0 : muscle.springs.front().restLength;
  for (const Spring& spring : muscle.springs)
    report.shortestSpring = std::min(report.shortestSpring, spring.restLength);
}

/// Each bone's sphere generation in `report`: a warning naming what it ignored, capped or
/// dropped, a repair for centres pulled back inside a thin part (no fault of the mesh).
void reportBoneSpheres(const std::vector<BoneInput>& bones,
                       const std::vector<BoneSettings>& boneSettings,
                       const std::vector<detail::BoneSphereReport>& sphereReports,
                       PreparationReport& report) {
  for (size_t b = 0; b < bones.size(); ++b) {
    const detail::BoneSphereReport& r = sphereReports[b];
    std::vector<std::string> notes;
    if (r.degenerateTriangles)
      notes.push_back(std::to_string(r.degenerateTriangles) + " zero-area triangles ignored");
    // Long triangles and thin parts (a plate, a coarse box, a pelvic wing) are no fault of the
    // mesh: repairs.
    if (r.capped)
      report.repairs.push_back("bone '" + bones[b].name + "': " + std::to_string(r.capped) +
                               " spheres capped (longest edge over 3 mean edge lengths)");
    if (r.pulledBack)
      report.repairs.push_back("bone '" + bones[b].name + "': " + std::to_string(r.pulledBack) +
                               " sphere centres pulled back inside a thin part");
    if (r.dropped) notes.push_back(std::to_string(r.dropped) + " spheres dropped");
    if (boneSettings[b].sphereCentres.empty()) notes.push_back("no collision spheres at all");
    if (!notes.empty()) report.warnings.push_back("bone '" + bones[b].name + "': " + join(notes));
  }
}

/// Shrinks the spheres so that no two bodies overlap at rest, with a repair in `report` saying
/// how many.
void shrinkAndReport(std::vector<MuscleSettings>& muscleSettings,
                     std::vector<BoneSettings>& boneSettings, PreparationReport& report) {
  const detail::ShrinkReport shrink = detail::shrinkRadii(muscleSettings, boneSettings);
  size_t sphereCount = 0;
  for (const auto& muscle : muscleSettings) sphereCount += muscle.boundaryParticles.size();
  if (shrink.muscleSpheresShrunk > 0 || shrink.boneSpheresShrunk > 0)
    report.repairs.push_back("radii: " + std::to_string(shrink.muscleSpheresShrunk) + " of " +
                             std::to_string(sphereCount) +
                             " muscle spheres shrunk so that no two bodies overlap at rest (" +
                             std::to_string(shrink.muscleSpheresZeroed) + " to radius 0, " +
                             std::to_string(shrink.muscleSpheresCapped) +
                             " capped at the sample spacing near another muscle); " +
                             std::to_string(shrink.boneSpheresShrunk) +
                             " bone spheres shrunk around muscle particles inside them");
}

}  // namespace

PreparedScene prepareScene(const std::vector<BoneInput>& bones,
                           const std::vector<MuscleInput>& muscles, uint32_t seed, int threads) {
  return prepareScene(bones, muscles, seed, threads, TaskScheduler{});
}

PreparedScene prepareScene(const std::vector<BoneInput>& bones,
                           const std::vector<MuscleInput>& muscles, uint32_t seed, int threads,
                           const TaskScheduler& scheduler) {
  const Workers workers{threads, scheduler};
  const auto start = std::chrono::steady_clock::now();
  requirePreparationMemory(bones, muscles);
  PreparedScene scene;

  std::vector<BoneShape> shapes(bones.size());
  std::vector<BoneSettings> boneSettings(bones.size());
  std::vector<detail::BoneSphereReport> sphereReports(bones.size());
  parallelFor(bones.size(), workers, [&](size_t b) {
    checkMesh("bone '" + bones[b].name + "'", "mesh", bones[b].mesh);
    shapes[b].distance = std::make_unique<MeshDistance>(bones[b].mesh);
    pointBounds(bones[b].mesh.vertices, shapes[b].lower, shapes[b].upper);
    boneSettings[b].name = bones[b].name;
    boneSettings[b].mesh = bones[b].mesh;
    std::mt19937 random = detail::bodyRandom(seed, kSphereThinning, b);
    sphereReports[b] =
        detail::makeBoneSpheres(bones[b], *shapes[b].distance, random, boneSettings[b]);
  });

  std::vector<MuscleSettings> muscleSettings(muscles.size());
  std::vector<std::vector<std::string>> muscleWarnings(muscles.size());
  std::vector<MusclePreparationReport>& muscleReports = scene.report.muscles;
  muscleReports.resize(muscles.size());
  std::vector<std::unique_ptr<MeshDistance>> surfaces(muscles.size());
  parallelFor(muscles.size(), workers, [&](size_t m) {
    muscleSettings[m] = sampleMuscle(muscles[m], m, bones.size(), seed);
    surfaces[m] = std::make_unique<MeshDistance>(muscles[m].surface);
  });
  parallelFor(muscles.size(), workers, [&](size_t m) {
    separateMuscle(muscles[m], m, shapes, surfaces, muscleSettings[m], muscleReports[m]);
  });
  parallelFor(muscles.size(), workers, [&](size_t m) {
    finishMuscle(muscles[m], shapes, bones, muscleWarnings[m], muscleSettings[m], muscleReports[m]);
  });

  std::vector<std::string>& warnings = scene.report.warnings;
  reportBoneSpheres(bones, boneSettings, sphereReports, scene.report);
  for (const auto& list : muscleWarnings) warnings.insert(warnings.end(), list.begin(), list.end());
  for (size_t m = 0; m < muscles.size(); ++m)
    describeRepairs(muscles[m], muscleReports[m], bones, muscles, scene.report.repairs);

  shrinkAndReport(muscleSettings, boneSettings, scene.report);

  scene.report.surfaceCoverage.assign(muscles.size(), 0);
  parallelFor(muscles.size(), workers, [&](size_t m) {
    scene.report.surfaceCoverage[m] = detail::surfaceCoverage(muscleSettings[m]);
  });
  for (auto& bone : boneSettings)
    scene.bones.push_back(std::make_shared<const BoneSettings>(std::move(bone)));
  for (auto& muscle : muscleSettings)
    scene.muscles.push_back(std::make_shared<const MuscleSettings>(std::move(muscle)));
  scene.report.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return scene;
}

std::vector<int32_t> declaredAreaBones(const std::vector<DeclaredAttachment>& areas,
                                       btScalar attachmentDistance,
                                       const std::vector<btVector3>& restSurface,
                                       const std::vector<const MeshDistance*>& bones,
                                       const std::vector<btVector3>& points) {
  DeclaredAreas declared(areas, attachmentDistance, restSurface, bones);
  std::vector<int32_t> fixedTo;
  fixedTo.reserve(points.size());
  for (const btVector3& p : points) fixedTo.push_back(declared.boneFor(p));
  return fixedTo;
}

}  // namespace fibremss
