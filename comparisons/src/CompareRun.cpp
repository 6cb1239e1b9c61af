#include <sys/resource.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <map>
#include <tuple>

#include "fibremss/Analytic.h"
#include "fibremss/Compare.h"
#include "fibremss/Error.h"
#include "fibremss/FibreRun.h"
#include "fibremss/Measures.h"
#include "fibremss/Messages.h"

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

/// Point pairs (a, b, rest length) of one muscle, checked against 3× their rest length.
using PairList = std::vector<std::tuple<uint32_t, uint32_t, btScalar>>;

/// What the pose loop needs from a simulated method.
struct Simulated {
  std::function<bool(std::span<const btTransform>)> step;        ///< one pose; false: stopped
  std::function<void(size_t, std::vector<btVector3>&)> surface;  ///< muscle's surface
  std::function<std::span<const btVector3>(size_t)> points;      ///< muscle's simulated points
  std::vector<PairList> pairs;              ///< per muscle, indices into points(muscle)
  std::function<double()> springDeviation;  ///< at the end
  long iterationsPerStep = 1;               ///< for ms/iteration
  long timeStepsPerStep = 1;                ///< world substeps per pose, for ms/time step
};

/// A run of `method` on the scene, named and not yet measured.
RunMetrics namedRun(const LoadedScene& scene, const char* method, const char* integrator) {
  RunMetrics metrics;
  metrics.scene = scene.name;
  metrics.method = method;
  metrics.integrator = integrator;
  return metrics;
}

/// Mean rest length of each muscle's pairs (0 for a muscle without pairs).
std::vector<double> meanRestLengths(const Simulated& sim) {
  std::vector<double> means;
  for (const PairList& pairs : sim.pairs) {
    double restSum = 0;
    for (const auto& pair : pairs) restSum += std::get<2>(pair);
    means.push_back(pairs.empty() ? 0 : restSum / static_cast<double>(pairs.size()));
  }
  return means;
}

/// True when some pair counts as exploded by FibreMSS's guard rule (springExploded: past 3× its
/// rest length and longer than it by more than its muscle's mean rest length, `meanRest`).
bool exploded(const Simulated& sim, std::span<const double> meanRest) {
  for (size_t m = 0; m < sim.pairs.size(); ++m) {
    const std::span<const btVector3> positions = sim.points(m);
    for (const auto& [a, b, rest] : sim.pairs[m])
      if (springExploded((positions[a] - positions[b]).length(), rest, meanRest[m])) return true;
  }
  return false;
}

/// Runs every pose and measures it the way runFibreMSS does: surface penetration into the
/// bones' true meshes over all steps, volume change at the last intact step and spring
/// deviation at the last step.
void runPoses(const LoadedScene& scene, const PreparedScene& prepared, const Simulated& sim,
              const MethodRunOptions& options, Clock::time_point start, RunMetrics& metrics) {
  std::vector<MeshDistance> boneDistances;
  for (const auto& bone : prepared.bones) boneDistances.emplace_back(bone->mesh);
  std::vector<const MeshDistance*> bones;
  for (const MeshDistance& d : boneDistances) bones.push_back(&d);

  const int steps = std::max(scene.poseCount, 1);
  const std::vector<double> meanRest = meanRestLengths(sim);
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
    if (!sim.step(transforms)) {
      metrics.interrupted = true;
      break;
    }
    msPerStep.push_back(secondsSince(stepStart) * 1000);
    metrics.steps = s + 1;
    metrics.iterations += sim.iterationsPerStep;

    poseSurface.clear();
    for (size_t m = 0; m < prepared.muscles.size(); ++m) {
      sim.surface(m, muscleSurface);
      poseSurface.insert(poseSurface.end(), muscleSurface.begin(), muscleSurface.end());
    }
    metrics.nan = !allFinite(poseSurface);
    metrics.exploded = !metrics.nan && exploded(sim, meanRest);
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
  metrics.msPerIteration = metrics.msPerStep / static_cast<double>(sim.iterationsPerStep);
  metrics.msPerTimeStep = metrics.msPerStep / static_cast<double>(sim.timeStepsPerStep);
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

std::vector<std::string> split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  size_t start = 0;
  for (size_t end; (end = text.find(separator, start)) != std::string::npos; start = end + 1) {
    parts.push_back(text.substr(start, end - start));
  }
  parts.push_back(text.substr(start));
  return parts;
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

double poseDuration(const SimulationParameters& simulation) {
  const int iterations = simulation.stopRule == StopRule::Iterations
                             ? simulation.iterations
                             : std::min(simulation.iterations, kPoseIterationsCap);
  return static_cast<double>(simulation.timeStep) * iterations;
}

RunMetrics runSoftBody(const LoadedScene& scene, const PreparedScene& prepared,
                       const SoftBodyDefinition& definition, const MethodRunOptions& options) {
  const auto start = Clock::now();
  SoftBodyScene sim(prepared, posesAt(scene, 0), definition);
  const SoftBodyDefinition& used = sim.definition();
  char integrator[200];
  std::snprintf(integrator, sizeof integrator,
                "btSoftBody position solver (%d substeps × %d link iterations per pose, links "
                "softest first, %d clusters per muscle × %d iterations)",
                used.substepsPerPose, used.positionIterations, used.clustersPerMuscle,
                used.clusterIterations);
  RunMetrics metrics = namedRun(scene, "btsoftbody", integrator);
  metrics.threads = 1;  // Debian's Bullet steps soft bodies on the calling thread only
  metrics.particles = sim.nodeCount();
  metrics.springs = sim.linkCount();
  for (const auto& muscle : prepared.muscles)
    metrics.boundaryParticles += muscle->boundaryParticles.size();

  Simulated simulated;
  double restLengths = 0;
  for (const auto& muscle : prepared.muscles) {
    simulated.pairs.emplace_back();
    for (const Spring& s : muscle->springs) {
      simulated.pairs.back().emplace_back(s.a, s.b, s.restLength);
      restLengths += s.restLength;
    }
  }
  simulated.step = [&](std::span<const btTransform> t) {
    sim.stepPose(t);
    return true;
  };
  simulated.surface = [&](size_t m, std::vector<btVector3>& out) { sim.surface(m, out); };
  simulated.points = [&](size_t m) { return sim.positions(m); };
  simulated.springDeviation = [&] {
    double deviation = 0;
    for (size_t m = 0; m < prepared.muscles.size(); ++m) {
      double lengths = 0;
      for (const Spring& s : prepared.muscles[m]->springs) lengths += s.restLength;
      if (lengths > 0) {
        deviation += lengths * springDeviationRatio(prepared.muscles[m]->springs, sim.positions(m));
      }
    }
    return restLengths > 0 ? deviation / restLengths : RunMetrics::kNone;
  };
  simulated.iterationsPerStep = static_cast<long>(used.substepsPerPose) * used.positionIterations;
  simulated.timeStepsPerStep = used.substepsPerPose;
  runPoses(scene, prepared, simulated, options, start, metrics);
  return metrics;
}

RunMetrics runFem(const LoadedScene& scene, const PreparedScene& prepared,
                  const FemDefinition& definition, const MethodRunOptions& options) {
  const auto start = Clock::now();
  FemScene sim(prepared, posesAt(scene, 0), definition);
  char integrator[320];
  std::snprintf(integrator, sizeof integrator,
                "Neo-Hookean FEM, btDeformableBodySolver (explicit elasticity, implicit damping, "
                "%d substeps per pose, then settling until no node is faster than %.3g mm/s (at "
                "most %d substeps), mass scaling +%.0f %%, at least %d pins per bone (fewest: "
                "%zu))",
                definition.substepsPerPose, 1e3 * double(definition.settleSpeed),
                definition.settleSubsteps, 100 * sim.addedMassShare(), definition.minPinsPerBone,
                sim.fewestPinsPerBone());
  RunMetrics metrics = namedRun(scene, "fem", integrator);
  metrics.threads = 1;
  metrics.particles = sim.nodeCount();
  metrics.springs = sim.tetrahedronCount();

  // Tetrahedron edges with their rest lengths, for the explosion criterion.
  Simulated simulated;
  simulated.pairs.resize(sim.muscleCount());
  for (size_t m = 0; m < sim.muscleCount(); ++m) {
    const TetMesh& mesh = sim.tetMesh(m);
    for (const auto& t : mesh.tetrahedra) {
      for (int a = 0; a < 4; ++a) {
        for (int b = a + 1; b < 4; ++b) {
          simulated.pairs[m].emplace_back(t[a], t[b], mesh.nodes[t[a]].distance(mesh.nodes[t[b]]));
        }
      }
    }
  }
  // The budget is checked between substeps too: one FEM pose can outlast a whole budget.
  const auto outOfTime = [&] {
    return (options.cancel && options.cancel->load()) ||
           (options.budgetSeconds > 0 && secondsSince(start) > options.budgetSeconds);
  };
  int unsettled = 0;  // poses that did not settle within settleSubsteps
  simulated.step = [&](std::span<const btTransform> t) {
    const bool done = sim.stepPose(t, outOfTime);
    unsettled += done && sim.lastSettleSubsteps() > definition.settleSubsteps;
    return done;
  };
  simulated.surface = [&](size_t m, std::vector<btVector3>& out) { sim.surface(m, out); };
  simulated.points = [&](size_t m) { return sim.nodePositions(m); };
  simulated.springDeviation = [] { return RunMetrics::kNone; };  // not a spring model
  simulated.iterationsPerStep = simulated.timeStepsPerStep = definition.substepsPerPose;
  runPoses(scene, prepared, simulated, options, start, metrics);
  if (unsettled > 0)
    metrics.integrator += "; " + std::to_string(unsettled) + " pose(s) did not settle";
  return metrics;
}

int sharedPoses(const RunMetrics& a, const RunMetrics& b) {
  return static_cast<int>(std::min(a.poseSurfaces.size(), b.poseSurfaces.size()));
}

double rmsBetweenRuns(const RunMetrics& a, const RunMetrics& b, double* worstPose) {
  const size_t poses = static_cast<size_t>(sharedPoses(a, b));
  if (worstPose) *worstPose = RunMetrics::kNone;
  if (poses == 0) return RunMetrics::kNone;
  double sum = 0, worst = 0;
  for (size_t p = 0; p < poses; ++p) {
    if (a.poseSurfaces[p].size() != b.poseSurfaces[p].size()) return RunMetrics::kNone;
    const double rms = rmsDistanceMm(a.poseSurfaces[p], b.poseSurfaces[p]);
    sum += rms * rms;
    worst = std::max(worst, rms);
  }
  if (worstPose) *worstPose = worst;
  return std::sqrt(sum / static_cast<double>(poses));
}

SimulationParameters equilibriumSettings(const SimulationParameters& simulation, int cap) {
  SimulationParameters converged = simulation;
  const int motion = std::max(1, static_cast<int>(std::lround(simulation.motionFraction *
                                                              std::max(1, simulation.iterations))));
  // The projective step reaches a residual Verlet does not: fusiform 1e-5 mm in about 270
  // iterations per pose; Verlet stalled near 2e-5 mm after 60 000 (docs/performance.md,
  // "Distance to equilibrium").
  converged.integrator = Integrator::Projective;
  converged.stopRule = StopRule::Residual;
  converged.tolerance = static_cast<btScalar>(kEquilibriumResidual);
  converged.iterations = std::max(cap, motion);
  converged.projectiveRho = static_cast<btScalar>(kEquilibriumRho);
  // The over-relaxed fixed point: the L-BFGS step's pairs stall on float noise near 1e-5 mm.
  converged.projectiveHistory = 0;
  converged.motionFraction = static_cast<btScalar>(double(motion) / converged.iterations);
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
    if (run.method == "calculix") reference = &run;
    if (run.method == "self-reference") self = &run;
    if (run.method == "equilibrium") equilibrium = &run;
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
                   std::span<const SurfaceBlock> blocks, std::vector<MuscleToEquilibrium>& muscles,
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
      muscles[m].perPoseMm.push_back(
          count ? rmsDistanceMm(a.subspan(offset, count), b.subspan(offset, count)) : 0.0);
      offset += count;
    }
    perPose.push_back(rmsDistanceMm(a, b));
  }
  return poses > 0;
}

/// Root mean square of `values` (each one pose's RMS over the same vertices).
double rmsOf(const std::vector<double>& values) {
  double squares = 0;
  for (double v : values) squares += v * v;
  return std::sqrt(squares / static_cast<double>(values.size()));
}

/// `run`'s per-pose and per-muscle distances to `equilibrium` and their worst pose and muscle.
void fillMuscles(RunMetrics& run, const RunMetrics& equilibrium,
                 std::span<const SurfaceBlock> blocks) {
  std::vector<MuscleToEquilibrium> muscles(blocks.size());
  std::vector<double> perPose;
  if (!musclePoseRms(run, equilibrium, blocks, muscles, perPose)) return;
  run.worstPoseToEquilibrium =
      static_cast<int>(std::max_element(perPose.begin(), perPose.end()) - perPose.begin());
  run.rmsToEquilibriumPerPoseMm = std::move(perPose);
  run.worstMuscleRmsToEquilibriumMm = -1;
  run.worstMusclePoseToEquilibrium = {"", -1, -1.0};
  for (size_t m = 0; m < blocks.size(); ++m) {
    MuscleToEquilibrium& muscle = muscles[m];
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
  const auto found = std::find_if(runs.begin(), runs.end(),
                                  [](const RunMetrics& r) { return r.method == "equilibrium"; });
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

/// Shape sum of squares and vertex sum of squares of one muscle at one pose.
void addMusclePose(const TriangleMesh& rest, std::span<const btVector3> run,
                   std::span<const btVector3> reference, double& shapeSquares, size_t& shapePoints,
                   double& vertexSquares) {
  TriangleMesh a{{run.begin(), run.end()}, rest.triangles};
  TriangleMesh b{{reference.begin(), reference.end()}, rest.triangles};
  const double shape = shapeRmsMm(a, b);
  shapeSquares += shape * shape * static_cast<double>(2 * run.size());
  shapePoints += 2 * run.size();
  const double rms = rmsDistanceMm(run, reference);
  vertexSquares += rms * rms * static_cast<double>(run.size());
}

}  // namespace

void fillReferenceShapes(std::vector<RunMetrics>& runs, const PreparedScene& prepared) {
  const auto found = std::find_if(runs.begin(), runs.end(),
                                  [](const RunMetrics& r) { return r.method == "calculix"; });
  if (found == runs.end()) return;
  const RunMetrics reference = *found;
  for (RunMetrics& run : runs) {
    const size_t poses = static_cast<size_t>(sharedPoses(run, reference));
    run.rmsToReferencePerPoseMm.clear();
    double shapeSquares = 0, worst = -1;
    size_t shapePoints = 0;
    std::vector<double> muscleSquares(prepared.muscles.size(), 0);
    for (size_t p = 0; p < poses; ++p) {
      if (run.poseSurfaces[p].size() != reference.poseSurfaces[p].size()) return;
      run.rmsToReferencePerPoseMm.push_back(
          rmsDistanceMm(run.poseSurfaces[p], reference.poseSurfaces[p]));
      size_t offset = 0;
      for (size_t m = 0; m < prepared.muscles.size(); ++m) {
        const TriangleMesh& rest = prepared.muscles[m]->restSurface;
        const size_t count = rest.vertices.size();
        addMusclePose(rest, std::span(run.poseSurfaces[p]).subspan(offset, count),
                      std::span(reference.poseSurfaces[p]).subspan(offset, count), shapeSquares,
                      shapePoints, muscleSquares[m]);
        offset += count;
      }
    }
    if (poses == 0 || shapePoints == 0) continue;
    run.shapeRmsToReferenceMm = std::sqrt(shapeSquares / static_cast<double>(shapePoints));
    for (size_t m = 0; m < prepared.muscles.size(); ++m) {
      const size_t count = prepared.muscles[m]->restSurface.vertices.size();
      const double rms =
          count ? std::sqrt(muscleSquares[m] / static_cast<double>(count * poses)) : 0;
      if (rms > worst) {
        worst = rms;
        run.worstMuscle = prepared.muscles[m]->name;
        run.worstMuscleRmsMm = rms;
      }
    }
  }
}

MethodSpec parseMethod(const std::string& name) {
  MethodSpec spec;
  spec.name = name;
  const size_t colon = name.find(':');
  spec.family = name.substr(0, colon);
  if (spec.family != "fibremss" && spec.family != "self-reference" &&
      spec.family != "equilibrium" && spec.family != "btsoftbody" && spec.family != "fem") {
    throw InputError("--methods", name,
                     "unknown method; expected fibremss, self-reference, equilibrium, btsoftbody, "
                     "fem, fibremss:<key>=<value>[+<key>=<value>...], "
                     "btsoftbody:iterations|substeps=N or fem:substeps|cells=N (N or xF, F times "
                     "the default)");
  }
  if (colon == std::string::npos) return spec;
  if (spec.family == "self-reference" || spec.family == "equilibrium") {
    throw InputError("--methods", name, spec.family + " takes no variants");
  }
  for (const std::string& part : split(name.substr(colon + 1), '+')) {
    const size_t equals = part.find('=');
    if (equals == std::string::npos || equals == 0) {
      throw InputError("--methods", name,
                       "variant part '" + part + "' is not <key>=<value> (parts joined by '+')");
    }
    if (spec.family != "fibremss") {
      const std::string key = part.substr(0, equals);
      const bool known = spec.family == "btsoftbody" ? key == "iterations" || key == "substeps"
                                                     : key == "substeps" || key == "cells";
      if (!known || !(knobValue(part.substr(equals + 1), 1) > 0)) {
        throw InputError("--methods", name,
                         spec.family == "btsoftbody"
                             ? "btsoftbody takes iterations=N or substeps=N (N > 0, or xF)"
                             : "fem takes substeps=N or cells=N (N > 0, or xF)");
      }
    }
    spec.overrides.push_back(part);
  }
  return spec;
}

int knobValue(const std::string& value, int defaultValue) {
  char* end = nullptr;
  const bool factor = !value.empty() && value[0] == 'x';
  const double number = std::strtod(value.c_str() + (factor ? 1 : 0), &end);
  if (end == value.c_str() + (factor ? 1 : 0) || *end != '\0' || !(number > 0)) return 0;
  return std::max(1, static_cast<int>(std::lround(factor ? number * defaultValue : number)));
}

FibreKnob fibreCostKnob(const SimulationParameters& simulation) {
  switch (simulation.stopRule) {
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

std::vector<std::string> frontMethods(const std::vector<std::string>& methods,
                                      const SimulationParameters& simulation) {
  const FibreKnob knob = fibreCostKnob(simulation);
  // Cheapest first: fewer iterations (a smaller budget), or a looser threshold.
  const std::array<const char*, 3> factors =
      knob.costGrows ? std::array{"x0.5", "x2", "x4"} : std::array{"x2", "x0.5", "x0.25"};
  const std::string at = "fibremss:" + knob.key + "=";
  std::vector<std::string> expanded;
  for (const std::string& method : methods) {
    if (method == "fibremss") {
      expanded.insert(expanded.end(),
                      {at + factors[0], "fibremss", at + factors[1], at + factors[2],
                       "fibremss:resolution=x0.5", "fibremss:resolution=x2"});
    } else if (method == "btsoftbody") {
      expanded.insert(expanded.end(),
                      {"btsoftbody:iterations=x0.5", "btsoftbody", "btsoftbody:iterations=x2"});
    } else if (method == "fem") {
      expanded.insert(expanded.end(), {"fem:substeps=x0.5", "fem", "fem:substeps=x2"});
    } else {
      expanded.push_back(method);
    }
  }
  return expanded;
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

/// The scene's value of a FibreMSS knob that takes any positive number (a stop rule's threshold,
/// lengths in the scene's units), as `--set` reads it; NaN for the other keys.
double realKnobBase(const std::string& key, const LoadedScene& scene) {
  const SimulationParameters& simulation = scene.simulation;
  if (key == "tolerance") return simulation.tolerance / scene.unitScale;
  if (key == "epsilon") return simulation.epsilon / scene.unitScale;
  if (key == "budget_ms") return simulation.budgetMs;
  if (key == "deviation_epsilon") return simulation.deviationEpsilon;
  return NAN;
}

/// A number as `--set` takes it, with 6 significant digits.
std::string shortNumber(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.6g", value);
  return text;
}

/// The spec with "xF" knob values made absolute from the scene's and the baselines' defaults;
/// its name states the values used.
MethodSpec resolvedSpec(const MethodSpec& spec, const LoadedScene& scene,
                        const PreparedScene& prepared, const CompareOptions& options) {
  MethodSpec resolved = spec;
  if (spec.overrides.empty()) return resolved;
  resolved.name = spec.family;
  for (std::string& part : resolved.overrides) {
    const size_t equals = part.find('=');
    const std::string key = part.substr(0, equals), value = part.substr(equals + 1);
    if (!value.empty() && value[0] == 'x' && spec.family == "fibremss" &&
        std::isfinite(realKnobBase(key, scene))) {
      part = key + "=" +
             shortNumber(std::strtod(value.c_str() + 1, nullptr) * realKnobBase(key, scene));
    } else if (!value.empty() && value[0] == 'x') {
      int base = 0;
      if (spec.family == "fibremss" && key == "iterations") base = scene.simulation.iterations;
      if (spec.family == "fibremss" && key == "resolution" && !scene.muscles.empty())
        base = scene.muscles.front().parameters.resolution;
      if (spec.family == "btsoftbody")
        base = key == "iterations"
                   ? (options.softBody.positionIterations > 0 ? options.softBody.positionIterations
                                                              : iterationsFor(prepared))
                   : (options.softBody.substepsPerPose > 0 ? options.softBody.substepsPerPose
                                                           : substepsFor(prepared));
      if (spec.family == "fem")
        base = key == "substeps" ? options.fem.substepsPerPose : options.fem.mesher.targetCells;
      if (base == 0) {
        throw InputError("--methods", spec.name,
                         "xF (a factor on the default) is for fibremss iterations/resolution, "
                         "btsoftbody iterations/substeps and fem substeps/cells");
      }
      part = key + "=" + std::to_string(knobValue(value, base));
    }
    resolved.name += (resolved.name == spec.family ? ":" : "+") + part;
  }
  return resolved;
}

/// The integer value of a resolved "key=N" knob of a baseline spec, or `fallback`.
int knob(const MethodSpec& spec, const std::string& key, int fallback) {
  for (const std::string& part : spec.overrides)
    if (part.rfind(key + "=", 0) == 0) return knobValue(part.substr(key.size() + 1), fallback);
  return fallback;
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
  const double duration = poseDuration(scene.simulation);
  if (spec.family == "fibremss" && spec.overrides.empty()) {
    return runFibreMSS(scene, prepared, fibreOptions);
  } else if (spec.family == "fibremss") {
    std::vector<std::string> all = overrides;
    all.insert(all.end(), spec.overrides.begin(), spec.overrides.end());
    const LoadedScene variant = loadScene(sceneNameOrPath, all);
    const PreparedScene variantPrepared = prepareScene(
        variant.bones, variant.muscles, variant.simulation.seed, variant.simulation.threads);
    return runFibreMSS(variant, variantPrepared, fibreOptions);
  } else if (spec.family == "self-reference") {
    LoadedScene reference = scene;
    const int f = std::max(1, options.selfReferenceFactor);
    reference.simulation.timeStep /= static_cast<btScalar>(f);
    reference.simulation.minTimeStep /= static_cast<btScalar>(f);
    reference.simulation.iterations *= f;
    return runFibreMSS(reference, prepared, fibreOptions);
  } else if (spec.family == "equilibrium") {
    LoadedScene converged = scene;
    converged.simulation = equilibriumSettings(scene.simulation, options.equilibriumIterations);
    FibreRunOptions equilibriumOptions = fibreOptions;
    int unconverged = 0;
    equilibriumOptions.progress = [&](const RunProgress& p) {
      unconverged += p.lastStep->iterations >= converged.simulation.iterations ? 1 : 0;
      fibreOptions.progress(p);
    };
    RunMetrics metrics = runFibreMSS(converged, prepared, equilibriumOptions);
    metrics.unconvergedPoses = unconverged;
    if (unconverged > 0 && options.log)
      options.log("equilibrium: " + std::to_string(unconverged) +
                  " pose(s) reached the iteration cap before converging");
    return metrics;
  } else if (spec.family == "btsoftbody") {
    SoftBodyDefinition definition = options.softBody;
    definition.poseDuration = static_cast<btScalar>(duration);
    definition.pretransformBlend = scene.simulation.pretransformBlend;
    definition.positionIterations = knob(spec, "iterations", definition.positionIterations);
    definition.substepsPerPose = knob(spec, "substeps", definition.substepsPerPose);
    return runSoftBody(scene, prepared, definition, methodOptions);
  }
  FemDefinition definition = options.fem;
  definition.poseDuration = static_cast<btScalar>(duration);
  definition.pretransformBlend = scene.simulation.pretransformBlend;
  definition.substepsPerPose = knob(spec, "substeps", definition.substepsPerPose);
  definition.mesher.targetCells = knob(spec, "cells", definition.mesher.targetCells);
  return runFem(scene, prepared, definition, methodOptions);
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
  const PreparedScene prepared =
      prepareScene(scene.bones, scene.muscles, scene.simulation.seed, scene.simulation.threads);
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
  for (const MethodSpec& given : specs) {
    if (options.cancel && options.cancel->load()) break;
    const MethodSpec spec = resolvedSpec(given, scene, prepared, options);
    runs.push_back(runMethod(spec, sceneNameOrPath, overrides, scene, prepared, options));
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
