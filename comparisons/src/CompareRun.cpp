#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <functional>

#include "fibremss/Analytic.h"
#include "fibremss/Compare.h"
#include "fibremss/Error.h"
#include "fibremss/FibreRun.h"
#include "fibremss/Measures.h"
#include "fibremss/Messages.h"
#include "fibremss/Methods.h"
#include "fibremss/SceneSystem.h"

namespace fibremss {
namespace {

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

double median(std::vector<double> values) {
  if (values.empty()) return RunMetrics::kNone;
  std::sort(values.begin(), values.end());
  const size_t middle = values.size() / 2;
  return values.size() % 2 ? values[middle] : 0.5 * (values[middle - 1] + values[middle]);
}

/// Peak resident set of the process so far (getrusage), in MB.
double peakMemoryMb() {
  rusage usage{};
  if (getrusage(RUSAGE_SELF, &usage) != 0) return RunMetrics::kNone;
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // Linux: kilobytes
}

bool allFinite(std::span<const btVector3> points) {
  return std::all_of(points.begin(), points.end(), [](const btVector3& p) {
    return std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z());
  });
}

std::vector<btTransform> posesAt(const LoadedScene& scene, int pose) {
  std::vector<btTransform> transforms;
  for (size_t b = 0; b < scene.bones.size(); ++b) transforms.push_back(scene.bonePose(b, pose));
  return transforms;
}

/// A run of `method` on the scene, named and not yet measured.
RunMetrics namedRun(const LoadedScene& scene, const std::string& method) {
  RunMetrics metrics;
  metrics.scene = scene.name;
  metrics.method = method;
  return metrics;
}

/// Mean rest length of each muscle's pairs (0 for a muscle without pairs).
std::vector<double> meanRestLengths(std::span<const std::vector<NodePair>> muscles) {
  std::vector<double> means;
  for (const std::vector<NodePair>& pairs : muscles) {
    double restSum = 0;
    for (const NodePair& pair : pairs) restSum += pair.restLength;
    means.push_back(pairs.empty() ? 0 : restSum / static_cast<double>(pairs.size()));
  }
  return means;
}

/// True when some pair counts as exploded by FibreMSS's guard rule (springExploded: past 3× its
/// rest length and longer than it by more than its muscle's mean rest length, `meanRest`).
bool exploded(const BaselineScene& sim, std::span<const std::vector<NodePair>> pairs,
              std::span<const double> meanRest) {
  for (size_t m = 0; m < pairs.size(); ++m) {
    const std::span<const btVector3> positions = sim.nodePositions(m);
    for (const NodePair& pair : pairs[m])
      if (springExploded((positions[pair.a] - positions[pair.b]).length(), pair.restLength,
                         meanRest[m]))
        return true;
  }
  return false;
}

/// Runs every pose and measures it the way runFibreMSS does: surface penetration into the
/// bones' true meshes over all steps, volume change at the last intact step and spring
/// deviation at the last step.
void runPoses(const LoadedScene& scene, const PreparedScene& prepared, BaselineScene& sim,
              const MethodRunOptions& options, Clock::time_point start, RunMetrics& metrics) {
  std::vector<MeshDistance> boneDistances;
  for (const auto& bone : prepared.bones) boneDistances.emplace_back(bone->mesh);
  std::vector<const MeshDistance*> bones;
  for (const MeshDistance& d : boneDistances) bones.push_back(&d);

  const int steps = std::max(scene.poseCount, 1);
  std::vector<std::vector<NodePair>> pairs;
  for (size_t m = 0; m < sim.muscleCount(); ++m) pairs.push_back(sim.nodePairs(m));
  const std::vector<double> meanRest = meanRestLengths(pairs);
  // The budget is checked between substeps too: one FEM pose can outlast a whole budget.
  const auto outOfTime = [&] {
    return (options.cancel && options.cancel->load()) ||
           (options.budgetSeconds > 0 && secondsSince(start) > options.budgetSeconds);
  };
  std::vector<double> msPerStep;
  Penetration penetration;
  std::vector<btVector3> poseSurface, muscleSurface;
  for (int s = 0; s < steps; ++s) {
    if (options.cancel && options.cancel->load()) {
      metrics.interrupted = true;
      break;
    }
    const std::vector<btTransform> transforms = posesAt(scene, s);
    const auto stepStart = Clock::now();
    if (!sim.stepPose(transforms, outOfTime)) {
      metrics.interrupted = true;
      break;
    }
    msPerStep.push_back(secondsSince(stepStart) * 1000);
    metrics.steps = s + 1;
    metrics.iterations += sim.iterationsPerPose();

    poseSurface.clear();
    for (size_t m = 0; m < prepared.muscles.size(); ++m) {
      sim.surface(m, muscleSurface);
      poseSurface.insert(poseSurface.end(), muscleSurface.begin(), muscleSurface.end());
    }
    metrics.nan = !allFinite(poseSurface);
    metrics.exploded = !metrics.nan && exploded(sim, pairs, meanRest);
    // A failed pose's surface says nothing about the method: it enters no penetration or RMS.
    if (!metrics.nan && !metrics.exploded) {
      penetration = combine(penetration, measurePenetration(poseSurface, bones, transforms));
      metrics.poseSurfaces.push_back(poseSurface);
    }
    if (options.progress) {
      options.progress({metrics.method, s + 1, steps, metrics.iterations, secondsSince(start)});
    }
    if (metrics.nan || metrics.exploded) {
      metrics.failedStep = s;
      break;
    }
  }
  metrics.msPerStep = median(msPerStep);
  metrics.msPerIteration = metrics.msPerStep / static_cast<double>(sim.iterationsPerPose());
  metrics.msPerTimeStep = metrics.msPerStep / static_cast<double>(sim.substepsPerPose());
  if (metrics.steps > 0 && !metrics.nan) {
    metrics.maxPenetrationMm = penetration.maxMm;
    metrics.meanPenetrationMm = penetration.meanMm;
    if (!metrics.poseSurfaces.empty())
      metrics.volumeChangePct = volumeChangePct(prepared, metrics.poseSurfaces.back());
    if (!prepared.muscles.empty() && !metrics.poseSurfaces.empty())
      metrics.analytic =
          measureAnalyticPoses(scene, prepared.muscles[0]->restSurface, metrics.poseSurfaces);
    metrics.springDeviationRatio = sim.springDeviation();
  }
  metrics.peakMemoryMb = peakMemoryMb();
  metrics.wallSeconds = secondsSince(start);
}

/// The first "step_deg" of a sweep motion anywhere in the scene JSON (NaN if none).
double sweepStep(const nlohmann::json& node) {
  if (node.is_object()) {
    if (auto it = node.find("step_deg"); it != node.end() && it->is_number()) {
      return it->get<double>();
    }
  }
  if (node.is_object() || node.is_array()) {
    for (const auto& child : node) {
      const double step = sweepStep(child);
      if (!std::isnan(step)) return step;
    }
  }
  return RunMetrics::kNone;
}

}  // namespace

double volumeChangePct(const PreparedScene& prepared, std::span<const btVector3> surfaces) {
  double restVolume = 0, change = 0;
  size_t offset = 0;
  for (const auto& muscle : prepared.muscles) {
    const TriangleMesh& rest = muscle->restSurface;
    const size_t count = rest.vertices.size();
    if (!rest.empty() && offset + count <= surfaces.size()) {
      const double volume = meshVolume(rest);
      change += volume * volumeChangePercent(rest, surfaces.subspan(offset, count));
      restVolume += volume;
    }
    offset += count;
  }
  return restVolume != 0 ? change / restVolume : RunMetrics::kNone;
}

double poseDuration(const StepSettings& step) {
  const int iterations = step.stopRule == StopRule::Iterations
                             ? step.iterations
                             : std::min(step.iterations, kPoseIterationsCap);
  return static_cast<double>(step.timeStep) * iterations;
}

RunMetrics runBaseline(
    const LoadedScene& scene, const std::string& method, const PreparedScene& prepared,
    const MethodRunOptions& options,
    const std::function<std::unique_ptr<BaselineScene>(std::span<const btTransform>)>& build) {
  const auto start = Clock::now();
  const std::unique_ptr<BaselineScene> sim = build(posesAt(scene, 0));
  RunMetrics metrics = namedRun(scene, method);
  metrics.threads = 1;  // Debian's Bullet steps soft bodies on the calling thread only
  metrics.particles = sim->nodeCount();
  metrics.springs = sim->elementCount();
  metrics.boundaryParticles = sim->boundaryNodeCount();
  runPoses(scene, prepared, *sim, options, start, metrics);
  metrics.integrator = sim->settings();
  return metrics;
}

int sharedPoses(const RunMetrics& a, const RunMetrics& b) {
  return static_cast<int>(std::min(a.poseSurfaces.size(), b.poseSurfaces.size()));
}

namespace {

/// Whether the vertices from `first` count at pose `p` between the runs: no surface limit of
/// either (RunMetrics::surfaceLimits) that starts there ends before `p`.
bool counts(const RunMetrics& a, const RunMetrics& b, size_t first, size_t p) {
  for (const RunMetrics* run : {&a, &b})
    for (const SurfaceLimit& limit : run->surfaceLimits)
      if (limit.first == first && static_cast<int>(p) >= limit.poses) return false;
  return true;
}

/// The vertex RMS between the runs at pose `p` over the vertices that count there [mm] (NaN
/// where none), their number into `counted`.
double poseRmsMm(const RunMetrics& a, const RunMetrics& b, size_t p, size_t& counted) {
  const std::span<const btVector3> from = a.poseSurfaces[p], to = b.poseSurfaces[p];
  std::vector<std::pair<size_t, size_t>> left;  // [first, end) not counted at p
  for (const RunMetrics* run : {&a, &b})
    for (const SurfaceLimit& limit : run->surfaceLimits)
      if (static_cast<int>(p) >= limit.poses)
        left.emplace_back(limit.first, limit.first + limit.count);
  counted = from.size();
  if (left.empty()) return rmsDistanceMm(from, to);
  std::sort(left.begin(), left.end());
  double squares = 0;
  size_t next = 0;
  counted = 0;
  const auto add = [&](size_t end) {
    if (end <= next) return;
    const double rms = rmsDistanceMm(from.subspan(next, end - next), to.subspan(next, end - next));
    squares += rms * rms * static_cast<double>(end - next);
    counted += end - next;
  };
  for (const auto& [first, end] : left) {
    add(std::min(first, from.size()));
    next = std::max(next, end);
  }
  add(from.size());
  return counted ? std::sqrt(squares / static_cast<double>(counted)) : RunMetrics::kNone;
}

}  // namespace

double rmsBetweenRuns(const RunMetrics& a, const RunMetrics& b, double* worstPose) {
  const size_t poses = static_cast<size_t>(sharedPoses(a, b));
  if (worstPose) *worstPose = RunMetrics::kNone;
  if (poses == 0) return RunMetrics::kNone;
  double sum = 0, worst = 0;
  size_t counted = 0;
  for (size_t p = 0; p < poses; ++p) {
    if (a.poseSurfaces[p].size() != b.poseSurfaces[p].size()) return RunMetrics::kNone;
    size_t vertices = 0;
    const double rms = poseRmsMm(a, b, p, vertices);
    if (vertices == 0) continue;
    sum += rms * rms * static_cast<double>(vertices);
    counted += vertices;
    worst = std::max(worst, rms);
  }
  if (worstPose) *worstPose = worst;
  return counted ? std::sqrt(sum / static_cast<double>(counted)) : RunMetrics::kNone;
}

MuscleSystemDef equilibriumSettings(const MuscleSystemDef& simulation, int cap) {
  MuscleSystemDef converged = simulation;
  const StepSettings& step = simulation.stepSettings;
  const int motion = std::max(
      1, static_cast<int>(std::lround(step.motionFraction * std::max(1, step.iterations))));
  // The projective step reaches a residual Verlet does not: fusiform 1e-5 mm in about 270
  // iterations per pose; Verlet stalled near 2e-5 mm after 60 000 (docs/performance.md,
  // "Distance to equilibrium").
  converged.integrator = Integrator::Projective;
  StepSettings& settled = converged.stepSettings;
  settled.stopRule = StopRule::Residual;
  settled.tolerance = static_cast<btScalar>(kEquilibriumResidual);
  settled.iterations = std::max(cap, motion);
  converged.projectiveRho = static_cast<btScalar>(kEquilibriumRho);
  // The over-relaxed fixed point: the L-BFGS step's pairs stall on float noise near 1e-5 mm.
  converged.projectiveHistory = 0;
  settled.motionFraction = static_cast<btScalar>(double(motion) / settled.iterations);
  // Persistent contacts, their particles held lighter (they slide to rest sooner): thigh13 R=20's
  // median pose left a residual about 7x below weight 10's at the cap (1.1e-4 against 7.2e-4 mm;
  // docs/decisions.md, "Solver").
  converged.projectiveContactWeight = 1;
  converged.persistentContacts = true;
  return converged;
}

void fillRms(std::vector<RunMetrics>& runs) {
  const RunMetrics* reference = nullptr;
  const RunMetrics* self = nullptr;
  const RunMetrics* equilibrium = nullptr;
  for (const RunMetrics& run : runs) {
    const MethodRole role = roleOf(run.method);
    if (role == MethodRole::Reference) reference = &run;
    if (role == MethodRole::SelfReference) self = &run;
    if (role == MethodRole::Equilibrium) equilibrium = &run;
  }
  for (RunMetrics& run : runs) {
    if (reference) {
      run.rmsToReferenceMm = rmsBetweenRuns(run, *reference);
      run.rmsToReferencePoses = std::isnan(run.rmsToReferenceMm) ? 0 : sharedPoses(run, *reference);
    }
    if (self) {
      run.rmsToSelfReferenceMm = rmsBetweenRuns(run, *self);
      run.rmsToSelfReferencePoses =
          std::isnan(run.rmsToSelfReferenceMm) ? 0 : sharedPoses(run, *self);
    }
    if (equilibrium) {
      run.rmsToEquilibriumMm = rmsBetweenRuns(run, *equilibrium, &run.worstPoseRmsToEquilibriumMm);
      run.rmsToEquilibriumPoses =
          std::isnan(run.rmsToEquilibriumMm) ? 0 : sharedPoses(run, *equilibrium);
    }
  }
}

std::vector<SurfaceBlock> surfaceBlocks(const PreparedScene& prepared) {
  std::vector<SurfaceBlock> blocks;
  for (const auto& muscle : prepared.muscles)
    blocks.push_back({muscle->name, muscle->restSurface.vertices.size()});
  return blocks;
}

namespace {

/// Each muscle's vertex RMS per shared pose of `run` against `equilibrium` into `muscles`, and
/// the whole surface's per pose into `perPose` (as rmsBetweenRuns takes it, so the worst pose
/// indexes its worst value); false when they share no pose or the blocks do not split a surface.
bool musclePoseRms(const RunMetrics& run, const RunMetrics& equilibrium,
                   std::span<const SurfaceBlock> blocks, std::vector<MuscleRms>& muscles,
                   std::vector<double>& perPose) {
  size_t total = 0;
  for (const SurfaceBlock& block : blocks) total += block.vertices;
  const size_t poses = static_cast<size_t>(sharedPoses(run, equilibrium));
  for (size_t p = 0; p < poses; ++p) {
    const std::span<const btVector3> a = run.poseSurfaces[p], b = equilibrium.poseSurfaces[p];
    if (total == 0 || a.size() != total || b.size() != total) return false;
    size_t offset = 0;
    for (size_t m = 0; m < blocks.size(); ++m) {
      const size_t count = blocks[m].vertices;
      if (counts(run, equilibrium, offset, p))
        muscles[m].perPoseMm.push_back(
            count ? rmsDistanceMm(a.subspan(offset, count), b.subspan(offset, count)) : 0.0);
      offset += count;
    }
    size_t counted = 0;
    perPose.push_back(poseRmsMm(run, equilibrium, p, counted));
  }
  return poses > 0;
}

/// Root mean square of `values` (each one pose's RMS over the same vertices; NaN for none).
double rmsOf(const std::vector<double>& values) {
  if (values.empty()) return RunMetrics::kNone;
  double squares = 0;
  for (double v : values) squares += v * v;
  return std::sqrt(squares / static_cast<double>(values.size()));
}

/// `run`'s per-pose and per-muscle distances to `equilibrium` and their worst pose and muscle.
void fillMuscles(RunMetrics& run, const RunMetrics& equilibrium,
                 std::span<const SurfaceBlock> blocks) {
  std::vector<MuscleRms> muscles(blocks.size());
  std::vector<double> perPose;
  if (!musclePoseRms(run, equilibrium, blocks, muscles, perPose)) return;
  run.worstPoseToEquilibrium =
      static_cast<int>(std::max_element(perPose.begin(), perPose.end()) - perPose.begin());
  run.rmsToEquilibriumPerPoseMm = std::move(perPose);
  run.worstMuscleRmsToEquilibriumMm = -1;
  run.worstMusclePoseToEquilibrium = {"", -1, -1.0};
  for (size_t m = 0; m < blocks.size(); ++m) {
    MuscleRms& muscle = muscles[m];
    muscle.muscle = blocks[m].muscle;
    muscle.rmsMm = rmsOf(muscle.perPoseMm);
    if (muscle.rmsMm > run.worstMuscleRmsToEquilibriumMm)
      run.worstMuscleToEquilibrium = muscle.muscle,
      run.worstMuscleRmsToEquilibriumMm = muscle.rmsMm;
    for (size_t p = 0; p < muscle.perPoseMm.size(); ++p)
      if (muscle.perPoseMm[p] > run.worstMusclePoseToEquilibrium.rmsMm)
        run.worstMusclePoseToEquilibrium = {muscle.muscle, static_cast<int>(p),
                                            muscle.perPoseMm[p]};
  }
  run.musclesToEquilibrium = std::move(muscles);
}

}  // namespace

void fillMusclesToEquilibrium(std::vector<RunMetrics>& runs, std::span<const SurfaceBlock> blocks) {
  const auto found = std::find_if(runs.begin(), runs.end(), [](const RunMetrics& r) {
    return roleOf(r.method) == MethodRole::Equilibrium;
  });
  if (found == runs.end()) return;
  const RunMetrics& equilibrium = *found;  // its poseSurfaces are not written below
  for (RunMetrics& run : runs) fillMuscles(run, equilibrium, blocks);
}

double shapeRmsMm(const TriangleMesh& a, const TriangleMesh& b) {
  double sum = 0;
  size_t count = 0;
  for (const auto& [from, to] : {std::pair{&a, &b}, std::pair{&b, &a}}) {
    const MeshDistance surface(*to);
    for (const btVector3& p : from->vertices) {
      const double d = 1000.0 * surface.closest(p).distance;
      sum += d * d;
      ++count;
    }
  }
  return count ? std::sqrt(sum / static_cast<double>(count)) : RunMetrics::kNone;
}

namespace {

/// Adds one muscle at one pose to the shape sum of squares; returns its vertex RMS [mm].
double addMusclePose(const TriangleMesh& rest, std::span<const btVector3> run,
                     std::span<const btVector3> reference, double& shapeSquares,
                     size_t& shapePoints) {
  TriangleMesh a{{run.begin(), run.end()}, rest.triangles};
  TriangleMesh b{{reference.begin(), reference.end()}, rest.triangles};
  const double shape = shapeRmsMm(a, b);
  shapeSquares += shape * shape * static_cast<double>(2 * run.size());
  shapePoints += 2 * run.size();
  return run.empty() ? 0.0 : rmsDistanceMm(run, reference);
}

}  // namespace

void fillReferenceShapes(std::vector<RunMetrics>& runs, const PreparedScene& prepared) {
  const auto found = std::find_if(runs.begin(), runs.end(), [](const RunMetrics& r) {
    return roleOf(r.method) == MethodRole::Reference;
  });
  if (found == runs.end()) return;
  const RunMetrics reference = *found;
  for (RunMetrics& run : runs) {
    const size_t poses = static_cast<size_t>(sharedPoses(run, reference));
    run.rmsToReferencePerPoseMm.clear();
    double shapeSquares = 0, worst = -1;
    size_t shapePoints = 0;
    std::vector<MuscleRms> muscles(prepared.muscles.size());
    for (size_t p = 0; p < poses; ++p) {
      if (run.poseSurfaces[p].size() != reference.poseSurfaces[p].size()) return;
      size_t counted = 0;
      run.rmsToReferencePerPoseMm.push_back(poseRmsMm(run, reference, p, counted));
      size_t offset = 0;
      for (size_t m = 0; m < prepared.muscles.size(); ++m) {
        const TriangleMesh& rest = prepared.muscles[m]->restSurface;
        const size_t count = rest.vertices.size();
        if (counts(run, reference, offset, p))
          muscles[m].perPoseMm.push_back(
              addMusclePose(rest, std::span(run.poseSurfaces[p]).subspan(offset, count),
                            std::span(reference.poseSurfaces[p]).subspan(offset, count),
                            shapeSquares, shapePoints));
        offset += count;
      }
    }
    if (poses == 0 || shapePoints == 0) continue;
    run.shapeRmsToReferenceMm = std::sqrt(shapeSquares / static_cast<double>(shapePoints));
    for (size_t m = 0; m < prepared.muscles.size(); ++m) {
      muscles[m].muscle = prepared.muscles[m]->name;
      muscles[m].rmsMm = rmsOf(muscles[m].perPoseMm);
      if (muscles[m].rmsMm > worst) {
        worst = muscles[m].rmsMm;
        run.worstMuscle = muscles[m].muscle;
        run.worstMuscleRmsMm = worst;
      }
    }
    run.musclesToReference = std::move(muscles);
  }
}

int knobValue(const std::string& value, int defaultValue) {
  char* end = nullptr;
  const bool factor = !value.empty() && value[0] == 'x';
  const double number = std::strtod(value.c_str() + (factor ? 1 : 0), &end);
  if (end == value.c_str() + (factor ? 1 : 0) || *end != '\0' || !(number > 0)) return 0;
  return std::max(1, static_cast<int>(std::lround(factor ? number * defaultValue : number)));
}

FibreKnob fibreCostKnob(const StepSettings& step) {
  switch (step.stopRule) {
    case StopRule::Iterations:
      return {"iterations", true};
    case StopRule::TimeBudget:
      return {"budget_ms", true};
    case StopRule::Converged:
      return {"epsilon", false};
    case StopRule::SpringDeviation:
      return {"deviation_epsilon", false};
    case StopRule::Equilibrium:
    case StopRule::Residual:
      break;
  }
  return {"tolerance", false};
}

void fillFinerResolution(std::vector<RunMetrics>& runs, int resolution) {
  const auto named = [&](const std::string& method) -> const RunMetrics* {
    for (const RunMetrics& run : runs)
      if (run.method == method) return &run;
    return nullptr;
  };
  const auto finerOf = [&](const std::string& method) -> const RunMetrics* {
    const std::string prefix = "fibremss:resolution=";
    const int r = method == "fibremss" ? resolution
                  : method.rfind(prefix, 0) == 0 && method.find('+') == std::string::npos
                      ? knobValue(method.substr(prefix.size()), 0)
                      : 0;
    if (r <= 0) return nullptr;
    const RunMetrics* finer = named(prefix + std::to_string(2 * r));
    return finer ? finer : 2 * r == resolution ? named("fibremss") : nullptr;
  };
  for (RunMetrics& run : runs)
    if (const RunMetrics* finer = finerOf(run.method))
      run.rmsToFinerResolutionMm = rmsBetweenRuns(run, *finer);
}

namespace {

/// The spec with "xF" knob values made absolute from the scene's and the baselines' defaults;
/// its name states the values used.
MethodSpec resolvedSpec(const MethodSpec& spec, const LoadedScene& scene,
                        const PreparedScene& prepared, const CompareOptions& options) {
  MethodSpec resolved = spec;
  if (spec.overrides.empty()) return resolved;
  resolved.name = spec.family;
  const Method& method = *findMethod(spec.family);
  const KnobBase base{scene, prepared, options};
  for (std::string& part : resolved.overrides) {
    const size_t equals = part.find('=');
    const std::string key = part.substr(0, equals), value = part.substr(equals + 1);
    if (!value.empty() && value[0] == 'x') {
      const std::string absolute = method.factorValue ? method.factorValue(key, value, base) : "";
      if (absolute.empty()) {
        throw InputError(
            "--methods", spec.name,
            "xF (a factor on the default) is not defined for " + key + " of " + spec.family);
      }
      part = key + "=" + absolute;
    }
    resolved.name += (resolved.name == spec.family ? ":" : "+") + part;
  }
  return resolved;
}

/// One method's run, stopped by the time budget after the current step, by the user's cancel
/// within it (FibreMSS) or after it (the baselines).
RunMetrics runMethod(const MethodSpec& spec, const std::string& sceneNameOrPath,
                     const std::vector<std::string>& overrides, const LoadedScene& scene,
                     const PreparedScene& prepared, const CompareOptions& options) {
  std::atomic<bool> stop{false};
  auto report = [&](MethodProgress p) {
    p.method = spec.name;  // the variant's name, not its family's
    if (options.progress) options.progress(p);
    if ((options.cancel && options.cancel->load()) ||
        (options.methodBudgetSeconds > 0 && p.seconds > options.methodBudgetSeconds)) {
      stop.store(true);
    }
  };
  const MethodRunOptions methodOptions{report, &stop, options.methodBudgetSeconds};
  FibreRunOptions fibreOptions;
  fibreOptions.method = spec.name;
  fibreOptions.cancel = &stop;
  fibreOptions.interrupt = options.cancel;
  fibreOptions.frameEvery = 0;
  fibreOptions.progress = [&](const RunProgress& p) {
    report({spec.name, p.step, p.steps, p.iterations, p.seconds});
  };
  return findMethod(spec.family)
      ->run({spec, sceneNameOrPath, overrides, scene, prepared, options, fibreOptions,
             methodOptions});
}

/// The scene and options the methods run with: the scene's own, except that muscle–muscle
/// contact is switched off in every method when a reference ranks them, since the reference
/// solves each muscle on its own (one problem for all). sceneOfTheMethods records that change in
/// the comparison (its overrides and muscleContactOff), where the report reads it.
struct MethodScene {
  LoadedScene scene;       ///< the scene as the methods run it
  CompareOptions options;  ///< the baselines' definitions as the methods run them
};

MethodScene sceneOfTheMethods(const LoadedScene& scene, Comparison& comparison,
                              const CompareOptions& options) {
  MethodScene methods{scene, options};
  const bool ranked = comparison.reference && !comparison.reference->missing;
  if (!ranked || scene.muscles.size() < 2 || !scene.simulation.muscleMuscle) return methods;
  methods.scene.simulation.muscleMuscle = false;
  methods.options.softBody.softSoftCollision = false;
  methods.options.fem.muscleContact = false;
  comparison.overrides.push_back(std::string(kNoMuscleContact));
  comparison.muscleContactOff = true;
  return methods;
}

}  // namespace

Comparison runComparison(const std::string& sceneNameOrPath,
                         const std::vector<std::string>& overrides, const CompareOptions& options) {
  auto log = [&](const std::string& line) {
    if (options.log) options.log(line);
  };
  const LoadedScene scene = loadScene(sceneNameOrPath, overrides);
  std::vector<MethodSpec> specs;
  for (const std::string& method :
       options.fronts ? frontMethods(options.methods, scene.simulation) : options.methods)
    specs.push_back(parseMethod(method));
  for (const std::string& warning : scene.warnings) log(warningLine(warning));
  for (const std::string& note : scene.notes) log(noteLine(note));
  log("preparing " + scene.name);
  const PreparedScene prepared = prepareScene(scene);
  for (const std::string& warning : prepared.report.warnings) log(warningLine(warning));
  for (const std::string& warning : attachmentWarnings(scene, prepared)) log(warningLine(warning));

  Comparison comparison;
  comparison.scene = scene.name;
  comparison.overrides = overrides;
  if (!scene.muscles.empty()) comparison.resolution = scene.muscles.front().parameters.resolution;
  comparison.stepDeg = sweepStep(nlohmann::json::parse(scene.json, nullptr, false));
  std::vector<RunMetrics>& runs = comparison.runs;
  if (options.withReference) {
    ReferenceOptions referenceOptions = options.reference;
    referenceOptions.log = options.log;
    referenceOptions.cancel = options.cancel;
    if (options.progress) {
      referenceOptions.progress = [&](const ReferenceProgress& p) {
        options.progress({"ccx " + p.muscle, p.step, p.steps, p.step, p.seconds});
      };
    }
    comparison.reference = computeReference(scene, prepared, referenceOptions);
    if (!comparison.reference->missing) runs.push_back(comparison.reference->metrics);
  }
  const MethodScene methodScene = sceneOfTheMethods(scene, comparison, options);
  for (const MethodSpec& given : specs) {
    if (options.cancel && options.cancel->load()) break;
    const MethodSpec spec = resolvedSpec(given, scene, prepared, options);
    runs.push_back(runMethod(spec, sceneNameOrPath, comparison.overrides, methodScene.scene,
                             prepared, methodScene.options));
    runs.back().method = spec.name;
    runs.back().poses = std::max(scene.poseCount, 1);
  }
  fillRms(runs);
  fillFinerResolution(runs, comparison.resolution);
  fillMusclesToEquilibrium(runs, surfaceBlocks(prepared));
  fillReferenceShapes(runs, prepared);
  if (comparison.reference && !comparison.reference->missing)
    comparison.reference->gates.spreadMm = methodSpreadMm(runs);
  return comparison;
}

}  // namespace fibremss
