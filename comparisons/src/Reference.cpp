// The CalculiX reference with its gates, and as a run among the methods.
#include "fibremss/Reference.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>

#include "TextList.h"
#include "fibremss/Analytic.h"
#include "fibremss/Compare.h"
#include "fibremss/Measures.h"
#include "fibremss/Methods.h"

namespace fibremss {
namespace {

/// What every solve of one scene shares: the bones' distance fields, the muscles' volume
/// samples (sampleContinuum, the costly part of a cut) and the continuum cut per attachment
/// scale, each found once.
class SceneCuts {
 public:
  SceneCuts(const LoadedScene& scene, const PreparedScene& prepared)
      : scene_(scene), samples_(sampleContinuum(scene)) {
    for (const auto& bone : prepared.bones) bones_.emplace_back(bone->mesh);
  }
  const ContinuumCut& at(btScalar attachmentScale) {
    auto [it, added] = cuts_.try_emplace(attachmentScale);
    if (added) it->second = findContinuumCut(scene_, bones_, samples_, attachmentScale);
    return it->second;
  }

 private:
  const LoadedScene& scene_;
  ContinuumSamples samples_;
  std::vector<MeshDistance> bones_;
  std::map<btScalar, ContinuumCut> cuts_;
};

/// A solve through the cache: its definition (the increments it took), key and solution.
struct Solve {
  CalculixDefinition definition;
  std::string key;
  CalculixSolution solution;
  bool fromCache = false;
  std::string shippedFrom;  ///< the shipped reference it was read from ("" : not shipped)
};

/// One solve of `solve.definition` through the cache, with a line of news saying which; false
/// when options.cachedOnly and it is not in the cache.
bool solveOnce(const LoadedScene& scene, const PreparedScene& prepared, SceneCuts& cuts,
               const ReferenceOptions& options, const std::string& what, Solve& solve) {
  const ContinuumCut& cut = cuts.at(solve.definition.attachmentScale);
  solve.key = referenceCacheKey(scene, prepared, solve.definition, cut);
  const bool stored =
      loadStoredSolution(options.cacheDir, solve.key, solve.solution, &solve.shippedFrom);
  if (options.log && !options.cachedOnly) options.log("reference (" + what + "): " + solve.key);
  if (stored && (options.cachedOnly || !solve.solution.hitMemoryLimit())) {
    solve.fromCache = true;
  } else if (options.cachedOnly) {
    // Parts of it solved as cells (`reference --cell`) are merged: that computes nothing.
    solve.fromCache = mergeCalculixParts(scene, prepared, solve.definition, cut, options.cacheDir,
                                         solve.solution);
    if (!solve.fromCache) {
      if (options.log)
        options.log("reference (" + what + "): " + solve.key + " not in the cache, not computed");
      return false;
    }
  } else {
    solve.shippedFrom.clear();  // one that hit the memory limit: solved again
    solve.solution =
        cachedCalculixReference(scene, prepared, solve.definition, cut, options.cacheDir,
                                options.progress, options.cancel, &solve.fromCache, options.jobs);
  }
  if (options.log) {
    std::ostringstream line;
    line << "reference (" << what << "): "
         << (!solve.shippedFrom.empty() ? "shipped (" + solve.shippedFrom + ")"
             : solve.fromCache          ? "from the cache"
                                        : "solved")
         << ", " << solve.solution.solvedPoses() << "/" << solve.solution.poseSurfaces.size()
         << " poses, " << solve.solution.nodes << " nodes, " << solve.solution.elements
         << " tetrahedra";
    options.log(line.str());
  }
  return true;
}

/// The retry of `definition`, whose solve `failed` had a pose ccx failed: every muscle at
/// kFinerIncrements where that solve is stored (whole, or a muscle's part: solved before a
/// retry kept muscles), so that none is solved again; else retryDefinition, with the parts of a
/// failed solve cached before they were kept read from its ccx files (recoverCalculixParts).
CalculixDefinition retryFor(const LoadedScene& scene, const PreparedScene& prepared,
                            SceneCuts& cuts, const CalculixDefinition& definition,
                            const std::string& cacheDir, CalculixSolution& failed) {
  const ContinuumCut& cut = cuts.at(definition.attachmentScale);
  const CalculixDefinition whole = retryDefinition(definition, CalculixSolution{});
  const std::string key = referenceCacheKey(scene, prepared, whole, cut);
  for (size_t m = 0; m < prepared.muscles.size(); ++m)
    if (referencePartStored(cacheDir, key, m)) return whole;
  recoverCalculixParts(scene, prepared, definition, cut, cacheDir, failed);
  return retryDefinition(definition, failed);
}

/// solveOnce of `definition`, and where ccx failed a pose or the return step
/// (ccxFailureToRetry), once more at kFinerIncrements of its increments (kept when that solve is
/// found or solved; with options.cachedOnly and not in the cache, the first solve's failures
/// stand). False when the first is not in the cache.
bool solveVariant(const LoadedScene& scene, const PreparedScene& prepared, SceneCuts& cuts,
                  const CalculixDefinition& definition, const ReferenceOptions& options,
                  const std::string& what, Solve& solve) {
  solve.definition = definition;
  if (!solveOnce(scene, prepared, cuts, options, what, solve)) return false;
  const std::string failure = ccxFailureToRetry(solve.solution);
  if (failure.empty() || (options.cancel && options.cancel->load())) return true;
  Solve finer;
  finer.definition = retryFor(scene, prepared, cuts, definition, options.cacheDir, solve.solution);
  if (options.log)
    options.log("reference (" + what + "): ccx failed (" + failure + "); again with increments " +
                incrementsText(finer.definition, prepared));
  if (solveOnce(scene, prepared, cuts, options, what, finer)) solve = std::move(finer);
  return true;
}

/// "pose k: reason" for every pose (and the return step) that did not solve.
std::string failures(const CalculixSolution& solution, const std::string& what) {
  std::string text;
  for (size_t p = 0; p < solution.poseFailures.size(); ++p)
    if (!solution.poseFailures[p].empty())
      appendItem(text, what + " pose " + std::to_string(p) + ": " + solution.poseFailures[p]);
  if (!solution.returnFailure.empty())
    appendItem(text, what + " return to rest: " + solution.returnFailure);
  return text;
}

/// "poses k to N-1 of N: why" for the poses past the solution's continuum cut; "" if none.
/// Whether a muscle of the scene declares its attachment areas (the reference then fixes only
/// their nodes of it).
bool declaresAreas(const LoadedScene& scene) {
  return std::any_of(scene.muscles.begin(), scene.muscles.end(),
                     [](const MuscleInput& muscle) { return !muscle.attachments.empty(); });
}

std::string excludedPoses(const CalculixSolution& solution) {
  const int cut = solution.cut.pose, poses = static_cast<int>(solution.poseSurfaces.size());
  if (cut < 0) return "";
  return (cut + 1 == poses ? "pose " + std::to_string(cut)
                           : "poses " + std::to_string(cut) + " to " + std::to_string(poses - 1)) +
         " of " + std::to_string(poses) + ": " + solution.cut.reason;
}

/// Whether the motion's last pose is the rest pose (every bone within 1 µm and 0.001°).
bool returnsToRest(const LoadedScene& scene) {
  const int last = std::max(scene.poseCount, 1) - 1;
  for (size_t b = 0; b < scene.bones.size(); ++b) {
    const btTransform t = scene.bonePose(b, last);
    const double w = std::min(1.0, std::abs(double(t.getRotation().w())));
    if (t.getOrigin().length() > 1e-6 || 2 * std::acos(w) > 1e-3 * M_PI / 180) return false;
  }
  return true;
}

/// The reference's own failures into `gates`. Where ccx stopped it at a pose after its retry
/// at kFinerIncrements (not interrupted nor on its memory limit), the stop is `stopped`, not a
/// failure, and the return gate does not apply (the motion's end was not reached); where the
/// motion does not return to rest and ccx failed only the steps added back to it, the return
/// gate does not apply; any other is a failure.
void referenceFailures(const LoadedScene& scene, const CalculixSolution& solution, bool retried,
                       ReferenceGates& gates) {
  const size_t stop = static_cast<size_t>(solution.solvedPoses());
  CalculixSolution failed = solution;  // what is left of its failures
  if (retried && stop < solution.poseFailures.size() && !solution.poseFailures[stop].empty() &&
      !ccxFailureToRetry(solution).empty()) {
    gates.stopped = solution.poseFailures[stop];
    gates.returnNotApplicable =
        "ccx stopped the reference at pose " + std::to_string(stop) + ", before the motion's end";
    failed.poseFailures.assign(solution.poseFailures.size(), "");
    failed.returnFailure.clear();
  } else if (solution.returnSurface.empty() && !solution.returnFailure.empty() &&
             !returnsToRest(scene)) {
    gates.returnNotApplicable =
        "the motion does not return to rest, and ccx did not solve the steps added back to it (" +
        solution.returnFailure + ")";
    failed.returnFailure.clear();
  }
  gates.failures = failures(failed, "reference");
}

std::vector<btVector3> restSurfaces(const PreparedScene& prepared) {
  std::vector<btVector3> rest;
  for (const auto& muscle : prepared.muscles)
    rest.insert(rest.end(), muscle->restSurface.vertices.begin(),
                muscle->restSurface.vertices.end());
  return rest;
}

/// Each muscle's surface vertices, in scene order (a pose surface's muscles, one after another).
std::vector<size_t> muscleVertices(const PreparedScene& prepared) {
  std::vector<size_t> vertices;
  for (const auto& muscle : prepared.muscles)
    vertices.push_back(muscle->restSurface.vertices.size());
  return vertices;
}

/// The vertices of the muscles `gates` cover over fewer than `poses` (ReferenceGates::limited):
/// no RMS counts them from their covered poses on.
std::vector<SurfaceLimit> surfaceLimits(const PreparedScene& prepared, const ReferenceGates& gates,
                                        int poses) {
  std::vector<SurfaceLimit> limits;
  size_t first = 0;
  const std::vector<size_t> vertices = muscleVertices(prepared);
  for (size_t m = 0; m < vertices.size(); first += vertices[m++])
    if (gates.coveredPoses(m) < poses)
      limits.push_back({first, vertices[m], gates.coveredPoses(m)});
  return limits;
}

/// The reference as a run: its solved poses' surfaces up to the gateable ones, the muscles the
/// gates cover over fewer poses limited to those (RunMetrics::surfaceLimits), penetration into
/// the bones' true meshes (it has no contact), volume change at the last of those poses.
RunMetrics referenceMetrics(const LoadedScene& scene, const PreparedScene& prepared,
                            const CalculixSolution& solution, const CalculixDefinition& definition,
                            const ReferenceGates& gates) {
  RunMetrics metrics;
  metrics.scene = scene.name;
  metrics.method = kReferenceMethod;
  metrics.integrator = std::string("static Neo-Hookean equilibrium, ccx *STATIC NLGEOM, ") +
                       toString(definition.element);
  metrics.threads = 1;
  metrics.particles = solution.nodes;
  metrics.springs = solution.elements;
  metrics.poses = static_cast<int>(solution.poseSurfaces.size());
  metrics.steps = std::min(solution.solvedPoses(), gates.gateablePoses());
  metrics.surfaceLimits = surfaceLimits(prepared, gates, metrics.steps);
  metrics.iterations = solution.newtonIterations;
  metrics.wallSeconds = solution.seconds;
  if (metrics.steps > 0) metrics.msPerStep = 1000 * solution.seconds / metrics.poses;
  std::vector<MeshDistance> bones;
  for (const auto& bone : prepared.bones) bones.emplace_back(bone->mesh);
  std::vector<const MeshDistance*> pointers;
  for (const MeshDistance& bone : bones) pointers.push_back(&bone);
  Penetration penetration;
  for (int p = 0; p < metrics.steps; ++p) {
    std::vector<btTransform> transforms;
    for (size_t b = 0; b < bones.size(); ++b) transforms.push_back(scene.bonePose(b, p));
    metrics.poseSurfaces.push_back(solution.poseSurfaces[static_cast<size_t>(p)]);
    penetration =
        combine(penetration, measurePenetration(metrics.poseSurfaces.back(), pointers, transforms));
  }
  if (metrics.steps > 0) {
    metrics.maxPenetrationMm = penetration.maxMm;
    metrics.meanPenetrationMm = penetration.meanMm;
    metrics.volumeChangePct = volumeChangePct(prepared, metrics.poseSurfaces.back());
    if (!prepared.muscles.empty() && !metrics.poseSurfaces.empty())
      metrics.analytic =
          measureAnalyticPoses(scene, prepared.muscles[0]->restSurface, metrics.poseSurfaces);
  }
  const int solvable = solution.cut.pose >= 0 ? solution.cut.pose : metrics.poses;
  if (metrics.steps < solvable) metrics.failedStep = metrics.steps;
  metrics.excludedFrom = solution.cut.pose;
  metrics.exclusion = solution.cut.reason;
  return metrics;
}

/// The gates' solves by name, cheapest first (GateDefinitions' order).
std::vector<std::pair<std::string, CalculixDefinition>> gateSolves(const GateDefinitions& gates) {
  return {{"attachment distance x0.5", gates.attachmentLow},
          {"attachment distance x1.5", gates.attachmentHigh},
          {"increments halved", gates.increments},
          {"one level finer", gates.finer}};
}

/// With options.jobs > 1, every gate's cells solved at once before solveGates takes (merges)
/// them in its order: the costliest solves first (one level finer), so that the last cells
/// running are short ones.
void solveGateCells(const LoadedScene& scene, const PreparedScene& prepared, SceneCuts& cuts,
                    const ReferenceOptions& options, const GateDefinitions& gates) {
  if (options.jobs <= 1 || options.cachedOnly) return;
  const auto solves = gateSolves(gates);
  std::vector<ReferenceCell> cells;
  for (auto solve = solves.rbegin(); solve != solves.rend(); ++solve)
    for (size_t m = 0; m < prepared.muscles.size(); ++m)
      cells.push_back({solve->second, cuts.at(solve->second.attachmentScale), m});
  solveCalculixCells(scene, prepared, cells, options.cacheDir, options.progress, options.cancel,
                     options.jobs);
}

/// ": k of M muscles' cells stored" for the solve `key` of M muscles of which k are stored as
/// cells (in the cache or shipped); "" where none is.
std::string storedCellsText(const std::string& cacheDir, const std::string& key, size_t muscles) {
  size_t stored = 0;
  for (size_t m = 0; m < muscles; ++m) stored += referencePartStored(cacheDir, key, m) ? 1 : 0;
  if (stored == 0) return "";
  return ": " + std::to_string(stored) + " of " + std::to_string(muscles) +
         " muscles' cells stored";
}

/// A gate's solve and where its figures go.
struct Gate {
  const CalculixDefinition* definition;
  const char* name;
  double* mm;
  int* poses;
  double* scale;  ///< where to keep the increments it was solved at (nullptr: nowhere)
  /// Where to say what it was solved at, where not at its reference's increments (the finer
  /// gate: ReferenceGates::refinedBy; nullptr: nowhere).
  std::string* refinedBy;
  std::string* failures;  ///< where its unsolved poses go: blocking or stated (statedFailures)
};

/// Muscle `m`'s surface at pose `p` in `solution` (its `count` vertices from `first` in a pose's
/// surface): its share of the pose's, or where another muscle failed the pose, its part's
/// (CalculixSolution::muscles); empty where neither has it.
std::span<const btVector3> muscleSurface(const CalculixSolution& solution, size_t m, size_t first,
                                         size_t count, size_t p) {
  if (!solution.poseSurfaces[p].empty())
    return std::span(solution.poseSurfaces[p]).subspan(first, count);
  if (m < solution.muscles.size() && p < solution.muscles[m].stepSurfaces.size())
    return solution.muscles[m].stepSurfaces[p];
  return {};
}

/// Adds pose `p`'s squared vertex distances [mm²] between `a` and `b` over the muscles covered
/// there (rmsBetweenSolutions) to `squares` and their count to `counted`; false (nothing added)
/// where no muscle is covered or either lacks the surface of one that is.
bool addPoseSquares(const CalculixSolution& a, const CalculixSolution& b,
                    std::span<const size_t> vertices, std::span<const int> covered, size_t p,
                    double& squares, size_t& counted) {
  double poseSquares = 0;
  size_t poseCounted = 0, first = 0;
  for (size_t m = 0; m < vertices.size(); first += vertices[m++]) {
    if (static_cast<int>(p) >= covered[m]) continue;
    const std::span<const btVector3> from = muscleSurface(a, m, first, vertices[m], p),
                                     to = muscleSurface(b, m, first, vertices[m], p);
    if (from.empty() || to.empty()) return false;
    const double rms = rmsDistanceMm(from, to);
    poseSquares += rms * rms * static_cast<double>(from.size());
    poseCounted += from.size();
  }
  if (poseCounted == 0) return false;
  squares += poseSquares;
  counted += poseCounted;
  return true;
}

using LimitedMuscle = ReferenceGates::LimitedMuscle;

/// Where ccx failed a pose the reference solved in a judged gate's solve (not interrupted nor on
/// its memory limit), each muscle it did not solve up to there stops there: `stops` (per muscle,
/// the earliest of the judged solves'; poses -1 where none) takes the stop, its solve and ccx's
/// reason. False (a failure) otherwise.
bool stopsTheGates(const CalculixSolution& reference, const Solve& solve,
                   const CalculixDefinition& asked, const std::string& name,
                   const PreparedScene& prepared, std::vector<LimitedMuscle>& stops) {
  const CalculixSolution& solution = solve.solution;
  if (solution.solvedPoses() >= reference.solvedPoses() || ccxFailureToRetry(solution).empty())
    return false;
  const std::vector<size_t> vertices = muscleVertices(prepared);
  size_t first = 0;
  for (size_t m = 0; m < vertices.size(); first += vertices[m++]) {
    int stop = 0;
    while (stop < reference.solvedPoses() &&
           !muscleSurface(solution, m, first, vertices[m], static_cast<size_t>(stop)).empty())
      ++stop;
    if (stop >= reference.solvedPoses() || (stops[m].poses >= 0 && stops[m].poses <= stop))
      continue;
    const std::string& failure = m < solution.muscles.size() ? solution.muscles[m].failure : "";
    const std::string why = failure.empty()
                                ? solution.poseFailures[static_cast<size_t>(stop)]
                                : "muscle " + prepared.muscles[m]->name + ": " + failure;
    stops[m] = {m, prepared.muscles[m]->name, stop, name,
                why + (solve.definition.incrementScale == asked.incrementScale
                           ? " (its retry at finer increments not computed)"
                           : "")};
  }
  return true;
}

/// The judged gates' stops (`stops`, per muscle) as what the gates cover: where every muscle
/// stopped, the gates stop at the latest (gatedPoses, gateStop); the muscles stopped before the
/// gateable poses are limited to their own.
void limitGates(const std::vector<LimitedMuscle>& stops, ReferenceGates& gates) {
  const auto stopped = [](const LimitedMuscle& stop) { return stop.poses >= 0; };
  if (!stops.empty() && std::all_of(stops.begin(), stops.end(), stopped)) {
    const LimitedMuscle& latest = *std::max_element(
        stops.begin(), stops.end(),
        [](const LimitedMuscle& a, const LimitedMuscle& b) { return a.poses < b.poses; });
    gates.gatedPoses = latest.poses;
    gates.gateStop = latest.solve + " pose " + std::to_string(latest.poses) + ": " + latest.why;
  }
  for (const LimitedMuscle& stop : stops)
    if (stopped(stop) && stop.poses < gates.gateablePoses()) gates.limited.push_back(stop);
}

/// Each solved gate's RMS against `base` and the poses it compared, over what the gates cover
/// (ReferenceGates::coveredPoses: the judged solves' stops are known).
void gateFigures(const CalculixSolution& base,
                 const std::vector<std::pair<const Gate*, Solve>>& solved,
                 const PreparedScene& prepared, ReferenceGates& gates) {
  const std::vector<size_t> vertices = muscleVertices(prepared);
  std::vector<int> covered;
  for (size_t m = 0; m < vertices.size(); ++m) covered.push_back(gates.coveredPoses(m));
  for (const auto& [gate, solve] : solved)
    *gate->mm = rmsBetweenSolutions(base, solve.solution, vertices, covered, gate->poses);
}

/// `refinedBy`, with the increments the finer gate's solve took where they are not the
/// reference's (it starts from the asked ones: gateDefinitions).
std::string refinedText(const std::string& refinedBy, const CalculixDefinition& finer,
                        const CalculixDefinition& reference, const PreparedScene& prepared) {
  const std::string increments = incrementsText(finer, prepared);
  const std::string references = incrementsText(reference, prepared);
  if (increments == references) return refinedBy;
  return refinedBy + ", increments " + increments + " (the reference's " + references + ")";
}

/// The gate solves (gateDefinitions) against `base`, cheapest first.
void solveGates(const LoadedScene& scene, const PreparedScene& prepared, SceneCuts& cuts,
                const ReferenceOptions& options, const Solve& base, ReferenceGates& gates) {
  const GateDefinitions definitions =
      gateDefinitions(base.definition, options.definition, gatePoseLimit(base.solution));
  gates.refinedBy = definitions.refinedBy;
  const auto solves = gateSolves(definitions);
  const Gate variants[] = {
      {&solves[0].second, solves[0].first.c_str(), &gates.attachmentLowMm,
       &gates.attachmentLowPoses, nullptr, nullptr, &gates.statedFailures},
      {&solves[1].second, solves[1].first.c_str(), &gates.attachmentHighMm,
       &gates.attachmentHighPoses, nullptr, nullptr, &gates.statedFailures},
      {&solves[2].second, solves[2].first.c_str(), &gates.incrementsMm, &gates.incrementsPoses,
       &gates.incrementsScale, nullptr, &gates.failures},
      {&solves[3].second, solves[3].first.c_str(), &gates.refinementMm, &gates.refinementPoses,
       nullptr, &gates.refinedBy, &gates.failures}};
  solveGateCells(scene, prepared, cuts, options, definitions);
  std::vector<LimitedMuscle> stops(prepared.muscles.size(), {0, "", -1, "", ""});
  std::vector<std::pair<const Gate*, Solve>> solved;
  for (const Gate& gate : variants) {
    Solve solve;
    if (options.cancel && options.cancel->load()) break;
    if (!solveVariant(scene, prepared, cuts, *gate.definition, options, gate.name, solve)) {
      appendItem(gates.notComputed,
                 gate.name + storedCellsText(options.cacheDir, solve.key, prepared.muscles.size()));
      continue;
    }
    const CalculixSolution& solution = solve.solution;
    // Retried at finer increments where ccx failed it: say what it was solved at.
    if (gate.refinedBy)
      *gate.refinedBy =
          refinedText(definitions.refinedBy, solve.definition, base.definition, prepared);
    if (gate.scale) *gate.scale = solve.definition.incrementScale;
    if (gate.scale && !solve.definition.muscleIncrementScales.empty())
      gates.incrementsPerMuscle = incrementsText(solve.definition, prepared);
    const bool judged = gate.failures == &gates.failures;
    if (!judged ||
        !stopsTheGates(base.solution, solve, *gate.definition, gate.name, prepared, stops)) {
      const std::string more = failures(solution, gate.name);
      if (!more.empty()) appendItem(*gate.failures, more);
    }
    // With more material attached, its cut can come earlier (pinch x1.5: at pose 1).
    if (solution.cut.pose != base.solution.cut.pose)
      appendItem(gates.excluded, std::string(gate.name) + ": " + excludedPoses(solution));
    solved.emplace_back(&gate, std::move(solve));
  }
  limitGates(stops, gates);
  gateFigures(base.solution, solved, prepared, gates);
}

/// What computeReference solves next for `definition`.
struct NextSolve {
  CalculixDefinition definition;  ///< `definition`, or its retry at kFinerIncrements
  std::string retryOf;            ///< the key of the failed solve it retries; else ""
  /// gatePoseLimit of that solve where it is stored [poses] (0: every pose, or not stored).
  int gatePoseLimit = 0;
};

/// The solution of `definition` stored whole (or shipped) or as every muscle's part, and its
/// key; false where it is not stored.
bool storedSolution(const LoadedScene& scene, const PreparedScene& prepared, SceneCuts& cuts,
                    const CalculixDefinition& definition, const std::string& cacheDir,
                    std::string& key, CalculixSolution& solution) {
  const ContinuumCut& cut = cuts.at(definition.attachmentScale);
  key = referenceCacheKey(scene, prepared, definition, cut);
  return loadStoredSolution(cacheDir, key, solution) ||
         mergeCalculixParts(scene, prepared, definition, cut, cacheDir, solution);
}

/// `definition`, or its retry at kFinerIncrements where it is stored with a pose ccx failed;
/// with the gate pose limit of the one chosen where that is stored.
NextSolve storedRetry(const LoadedScene& scene, const PreparedScene& prepared, SceneCuts& cuts,
                      const CalculixDefinition& definition, const std::string& cacheDir) {
  std::string key;
  CalculixSolution solution;
  if (!storedSolution(scene, prepared, cuts, definition, cacheDir, key, solution))
    return {definition, "", 0};
  if (ccxFailureToRetry(solution).empty()) return {definition, "", gatePoseLimit(solution)};
  NextSolve retry{retryFor(scene, prepared, cuts, definition, cacheDir, solution), key, 0};
  if (storedSolution(scene, prepared, cuts, retry.definition, cacheDir, key, solution))
    retry.gatePoseLimit = gatePoseLimit(solution);
  return retry;
}

}  // namespace

std::string resolvedCacheDir(const ReferenceOptions& options) {
  return options.cacheDir.empty() ? defaultReferenceCacheDir() : options.cacheDir;
}

std::vector<NamedReferenceCell> referenceCells(const LoadedScene& scene,
                                               const PreparedScene& prepared,
                                               const ReferenceOptions& options) {
  const std::string cacheDir = resolvedCacheDir(options);
  SceneCuts cuts(scene, prepared);
  const CalculixDefinition asked = sceneDefinition(scene, options);
  const NextSolve reference = storedRetry(scene, prepared, cuts, asked, cacheDir);
  std::vector<std::pair<std::string, NextSolve>> solves{{"reference", reference}};
  if (options.gates)
    for (const auto& [name, gate] :
         gateSolves(gateDefinitions(reference.definition, asked, reference.gatePoseLimit)))
      solves.emplace_back(name, storedRetry(scene, prepared, cuts, gate, cacheDir));
  std::vector<NamedReferenceCell> cells;
  for (const auto& [name, solve] : solves) {
    const ContinuumCut& cut = cuts.at(solve.definition.attachmentScale);
    const std::string key = referenceCacheKey(scene, prepared, solve.definition, cut);
    for (size_t m = 0; m < prepared.muscles.size(); ++m) {
      // A muscle a retry keeps is taken from the failed solve: nothing to solve.
      const std::string kept = keptPartKey(scene, prepared, solve.definition, cut, m);
      MuscleSolution part;
      cells.push_back({name,
                       key,
                       prepared.muscles[m]->name,
                       {solve.definition, cut, m},
                       referencePartStored(cacheDir, key, m) ||
                           (!kept.empty() && loadSolvedPart(cacheDir, kept, m, part)),
                       solve.retryOf});
    }
  }
  return cells;
}

namespace {

/// `v` as "0.123 mm" (three significant digits), "—" where NaN.
std::string mmText(double v) {
  if (std::isnan(v)) return "\u2014";
  char text[32];
  std::snprintf(text, sizeof text, "%.3g mm", v);
  return text;
}

/// " against a third of the methods' spread 1.48 mm": the bound a judged gate is held to.
std::string spreadBoundText(const ReferenceGates& g) {
  return " against a third of the methods' spread " + mmText(kRefinementShareOfSpread * g.spreadMm);
}

/// The gates computed and judged that `g` fails, each with its figure and bound, joined by
/// " and ": "one level finer 2.07 mm against a third of the methods' spread 1.48 mm".
std::string failedGatesText(const ReferenceGates& g) {
  std::string text;
  const auto add = [&](const std::string& item) { text += (text.empty() ? "" : " and ") + item; };
  if (g.returnFails())
    add("return to rest " + mmText(g.returnMm) + " against its bound " + mmText(kReturnGateMm));
  const auto judged = [&](const char* name, double mm, int compared) {
    if (!g.judgedAndFails(mm, compared)) return;
    add(name + (" " + mmText(mm)) + spreadBoundText(g) +
        (compared < g.gateablePoses() ? " (over fewer poses than the reference solved)" : ""));
  };
  judged("one level finer", g.refinementMm, g.refinementPoses);
  judged("increments halved", g.incrementsMm, g.incrementsPoses);
  return text;
}

}  // namespace

std::string ReferenceGates::whyNotPassed() const {
  if (passed()) return "";
  ReferenceGates gatesAlone = *this;  // the same gates with every pose solved
  gatesAlone.failures.clear();
  gatesAlone.stopped.clear();
  gatesAlone.solvedPoses = gateablePoses();
  gatesAlone.gatedPoses = -1;
  std::vector<std::string> why;
  if (gatesAlone.failed())
    why.push_back("the reference fails a gate (" + failedGatesText(gatesAlone) + ")");
  if (!failures.empty()) why.push_back("ccx did not solve every pose the ranking needs");
  if (stoppedTooSoon())
    why.push_back(std::string("ccx stopped ") +
                  (gateablePoses() < solvedPoses ? "a judged gate's solve" : "the reference") +
                  " at pose " + std::to_string(gateablePoses()) + ", before " +
                  std::to_string(kMinRankedPoses) + " poses to rank over");
  if (!gatesAlone.failed() && !gatesAlone.passed())
    why.push_back("the reference's gates were not computed" +
                  (notComputed.empty() ? std::string() : " (" + notComputed + ")"));
  std::string text;
  for (const std::string& reason : why) appendItem(text, reason);
  return text;
}

int ReferenceGates::coveredPoses(size_t m) const {
  for (const LimitedMuscle& muscle : limited)
    if (muscle.muscle == m)
      return muscle.poses < kMinRankedPoses ? 0 : std::min(muscle.poses, gateablePoses());
  return gateablePoses();
}

std::string ReferenceGates::limitedText() const {
  std::string text;
  for (const LimitedMuscle& muscle : limited)
    appendItem(text, muscle.name +
                         (muscle.poses < kMinRankedPoses
                              ? " left out of every figure (fewer than " +
                                    std::to_string(kMinRankedPoses) + " poses)"
                              : " over poses 0\u2013" + std::to_string(muscle.poses - 1)) +
                         ": ccx did not solve its pose " + std::to_string(muscle.poses) +
                         " in the " + muscle.solve + " solve (" + muscle.why + ")");
  return text;
}

std::string ReferenceGates::rankedPosesText() const {
  const int ranked = gateablePoses();
  if (!passed() || (ranked >= poses && limited.empty())) return "";
  const auto fewer = [&]() -> std::string {
    if (ranked < solvedPoses)
      return "no judged gate covers pose " + std::to_string(ranked) +
             " or later (ccx did not solve it in the " + gateStop + ")";
    if (stopped.empty()) return "the later ones have no continuum equilibrium";
    return "ccx did not solve pose " + std::to_string(solvedPoses) + " (" + stopped + ") or later";
  };
  std::string text =
      "ranked over poses 0\u2013" + std::to_string(ranked - 1) + " of " + std::to_string(poses);
  if (ranked < poses) text += ": " + fewer();
  if (!limited.empty()) text += "; " + limitedText();
  return text;
}

CalculixDefinition retryDefinition(const CalculixDefinition& definition,
                                   const CalculixSolution& failed) {
  CalculixDefinition retry = definition;
  retry.incrementScale *= kFinerIncrements;
  retry.muscleIncrementScales.clear();
  for (size_t m = 0; m < failed.muscles.size(); ++m)
    retry.muscleIncrementScales.push_back(
        definition.incrementScaleOf(m) *
        (failed.muscles[m].solvedEveryStep() ? 1 : kFinerIncrements));
  std::vector<double>& scales = retry.muscleIncrementScales;
  if (scales.empty()) return retry;  // stored without its parts: every muscle again
  const auto [finest, coarsest] = std::minmax_element(scales.begin(), scales.end());
  retry.incrementScale = *finest;            // the solve's own: the finest any muscle is solved at
  if (*finest == *coarsest) scales.clear();  // one scale for every muscle: a uniform solve
  return retry;
}

std::string incrementsText(const CalculixDefinition& definition, const PreparedScene& prepared) {
  std::ostringstream text;
  text << "x" << definition.incrementScale;
  if (definition.muscleIncrementScales.empty()) return text.str();
  std::map<double, std::string> muscles;  // their names by scale
  for (size_t m = 0; m < prepared.muscles.size(); ++m) {
    std::string& names = muscles[definition.incrementScaleOf(m)];
    names += (names.empty() ? "" : ", ") + prepared.muscles[m]->name;
  }
  text << " for " << muscles[definition.incrementScale] << " only (";
  std::string others;
  for (const auto& [scale, names] : muscles) {
    if (scale == definition.incrementScale) continue;
    std::ostringstream at;
    at << names << " at x" << scale;
    appendItem(others, at.str());
  }
  text << others << ")";
  return text.str();
}

std::string ccxFailureToRetry(const CalculixSolution& solution) {
  if (solution.interrupted || solution.hitMemoryLimit()) return "";
  for (size_t p = 0; p < solution.poseFailures.size(); ++p)
    if (!solution.poseFailures[p].empty())
      return "pose " + std::to_string(p) + ": " + solution.poseFailures[p];
  if (!solution.returnFailure.empty()) return "return to rest: " + solution.returnFailure;
  return "";
}

double rmsBetweenSolutions(const CalculixSolution& a, const CalculixSolution& b,
                           std::span<const size_t> vertices, std::span<const int> covered,
                           int* compared) {
  double squares = 0;
  size_t counted = 0;
  int poses = 0;
  for (size_t p = 0; p < std::min(a.poseSurfaces.size(), b.poseSurfaces.size()); ++p, ++poses)
    if (!addPoseSquares(a, b, vertices, covered, p, squares, counted)) break;
  if (compared) *compared = poses;
  return counted ? std::sqrt(squares / static_cast<double>(counted)) : RunMetrics::kNone;
}

double methodSpreadMm(const std::vector<RunMetrics>& runs) {
  std::map<std::string, double> best;
  for (const RunMetrics& run : runs) {
    if (std::isnan(run.rmsToReferenceMm) || roleOf(run.method) == MethodRole::Reference) continue;
    const std::string family = run.method.substr(0, run.method.find_first_of(":@"));
    auto [it, added] = best.try_emplace(family, run.rmsToReferenceMm);
    if (!added) it->second = std::min(it->second, run.rmsToReferenceMm);
  }
  if (best.empty()) return RunMetrics::kNone;
  double low = best.begin()->second, high = low;
  for (const auto& [family, rms] : best) {
    low = std::min(low, rms);
    high = std::max(high, rms);
  }
  return best.size() == 1 ? high : high - low;
}

int gatePoseLimit(const CalculixSolution& reference) {
  const auto failed = [](const std::string& failure) { return !failure.empty(); };
  if (std::none_of(reference.poseFailures.begin(), reference.poseFailures.end(), failed)) return 0;
  return std::max(reference.solvedPoses(), 1);
}

GateDefinitions gateDefinitions(const CalculixDefinition& reference,
                                const CalculixDefinition& asked, int poseLimit) {
  GateDefinitions gates{reference, reference, reference, reference, ""};
  gates.finer.incrementScale = asked.incrementScale;
  gates.finer.muscleIncrementScales = asked.muscleIncrementScales;
  gates.attachmentLow.attachmentScale *= 0.5f;
  gates.attachmentHigh.attachmentScale *= 1.5f;
  gates.increments.incrementScale *= kIncrementGateFactor;
  for (double& scale : gates.increments.muscleIncrementScales) scale *= kIncrementGateFactor;
  if (gates.finer.element == CalculixElement::C3D4) {
    gates.finer.element = CalculixElement::C3D10;
    gates.refinedBy = "C3D10 on the same tetrahedra";
  } else {
    gates.finer.mesher.refinement += 1;
    gates.refinedBy = "mesh level " + std::to_string(gates.finer.mesher.refinement);
  }
  for (CalculixDefinition* gate :
       {&gates.attachmentLow, &gates.attachmentHigh, &gates.increments, &gates.finer}) {
    gate->returnToRest = false;
    gate->poseLimit = poseLimit;
  }
  return gates;
}

CalculixDefinition sceneDefinition(const LoadedScene& scene, const ReferenceOptions& options) {
  CalculixDefinition definition = options.definition;
  if (!options.contactSlidingGiven && scene.reference.contactSliding == "small")
    definition.contactSliding = ContactSliding::Small;
  if (scene.analytic.type != "sphere-planes") return definition;
  if (!options.elementGiven) definition.element = CalculixElement::C3D10;
  if (!options.contactPenaltyGiven) definition.contactPenalty = kSpherePlanesContactPenalty;
  return definition;
}

Reference computeReference(const LoadedScene& scene, const PreparedScene& prepared,
                           const ReferenceOptions& options) {
  ReferenceOptions resolved = options;
  resolved.cacheDir = resolvedCacheDir(options);
  resolved.definition = sceneDefinition(scene, options);
  SceneCuts cuts(scene, prepared);
  Reference reference;
  Solve base;
  const bool found =
      solveVariant(scene, prepared, cuts, resolved.definition, resolved, "reference", base);
  reference.key = base.key;
  reference.cacheEntry =
      base.shippedFrom.empty() ? resolved.cacheDir + "/" + reference.key : base.shippedFrom;
  if (!found) {
    reference.missing = true;
    return reference;
  }
  reference.solution = base.solution;
  reference.fromCache = base.fromCache;
  const CalculixDefinition& definition = base.definition;
  const CalculixSolution& solution = reference.solution;
  referenceFailures(scene, solution,
                    definition.incrementScale != resolved.definition.incrementScale,
                    reference.gates);
  reference.gates.excluded = excludedPoses(solution);
  reference.gates.poses = static_cast<int>(solution.poseSurfaces.size());
  reference.gates.solvedPoses = solution.solvedPoses();
  if (!solution.returnSurface.empty())
    reference.gates.returnMm = rmsDistanceMm(solution.returnSurface, restSurfaces(prepared));
  if (options.gates && !(options.cancel && options.cancel->load()))
    solveGates(scene, prepared, cuts, resolved, base, reference.gates);
  reference.metrics = referenceMetrics(scene, prepared, solution, definition, reference.gates);
  std::ostringstream description;
  description << "CalculiX (" << calculixVersion(definition.program)
              << ") static equilibrium per pose, "
              << "Neo-Hookean (E " << definition.material.youngsModulus / 1000 << " kPa, nu "
              << definition.material.poissonRatio << "), " << toString(definition.element)
              << ", tetgen -pYq" << definition.mesher.radiusEdgeRatio
              << " mesh of each muscle's surface (level " << definition.mesher.refinement << "; "
              << solution.nodes << " nodes, " << solution.elements
              << " tetrahedra), material within " << definition.attachmentScale
              << "x the attachment distance of a bone moves with it ("
              << (declaresAreas(scene) ? "of a muscle that declares its areas, theirs only; " : "")
              << solution.prescribedNodes
              << " nodes); increments of at most 2.5 deg and 1 mm of attached move ("
              << (definition.incrementRule == IncrementRule::BoneFrame
                      ? "beyond the rigid motion of the bone frame it is least in"
                      : "in the world")
              << "); ";
  if (!definition.muscleIncrementScales.empty())
    description << "retried at increments " << incrementsText(definition, prepared)
                << " where ccx failed a pose of a muscle at its coarser increments; ";
  else if (definition.incrementScale != 1)
    description << "increments x" << definition.incrementScale
                << " (ccx failed a pose at the default 2.5 deg / 1 mm); ";
  if (definition.contactPenalty > 0)
    description << "frictionless muscle-bone contact (penalty " << definition.contactPenalty * 1e-3
                << " E per mm of overclosure, " << toString(definition.contactSliding)
                << " sliding, every bone a rigid obstacle), no muscle-muscle contact";
  else
    description << "no contact";
  reference.description = description.str();
  reference.increments = incrementsText(definition, prepared);
  return reference;
}

namespace {

/// The limited muscles as [{"muscle", "index", "poses", "solve", "why"}...].
nlohmann::json limitedJson(const std::vector<ReferenceGates::LimitedMuscle>& limited) {
  nlohmann::json list = nlohmann::json::array();
  for (const ReferenceGates::LimitedMuscle& muscle : limited)
    list.push_back({{"muscle", muscle.name},
                    {"index", muscle.muscle},
                    {"poses", muscle.poses},
                    {"solve", muscle.solve},
                    {"why", muscle.why}});
  return list;
}

}  // namespace

nlohmann::json referenceJson(const Reference& reference) {
  if (reference.missing)
    return {{"key", reference.key}, {"cache_entry", reference.cacheEntry}, {"missing", true}};
  const auto number = [](double v) {
    return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
  };
  const CalculixSolution& s = reference.solution;
  nlohmann::json poses = nlohmann::json::array();
  for (size_t p = 0; p < s.poseSurfaces.size(); ++p) {
    const bool excluded = s.cut.pose >= 0 && static_cast<int>(p) >= s.cut.pose;
    poses.push_back({{"solved", !s.poseSurfaces[p].empty()},
                     {"failure", s.poseFailures[p]},
                     {"excluded", excluded ? s.cut.reason : std::string()}});
  }
  const ReferenceGates& g = reference.gates;
  return {{"key", reference.key},
          {"cache_entry", reference.cacheEntry},
          {"from_cache", reference.fromCache},
          {"description", reference.description},
          {"poses", poses},
          {"return_failure", s.returnFailure},
          {"gates",
           {{"return_mm", number(g.returnMm)},
            {"return_bound_mm", kReturnGateMm},
            {"return_not_applicable", g.returnNotApplicable},
            {"return_passes", g.returnPasses()},
            {"refinement_mm", number(g.refinementMm)},
            {"refined_by", g.refinedBy},
            {"spread_mm", number(g.spreadMm)},
            {"refinement_passes", g.refinementPasses()},
            {"increments_mm", number(g.incrementsMm)},
            {"increments_scale", number(g.incrementsScale)},
            {"increments_per_muscle", g.incrementsPerMuscle},
            {"increments_passes", g.incrementsPass()},
            {"attachment_low_mm", number(g.attachmentLowMm)},
            {"attachment_high_mm", number(g.attachmentHighMm)},
            {"poses", g.poses},
            {"refinement_poses", g.refinementPoses},
            {"increments_poses", g.incrementsPoses},
            {"solved_poses", g.solvedPoses},
            {"attachment_low_poses", g.attachmentLowPoses},
            {"attachment_high_poses", g.attachmentHighPoses},
            {"failures", g.failures},
            {"stated_failures", g.statedFailures},
            {"not_computed", g.notComputed},
            {"stopped", g.stopped},
            {"gated_poses", g.gatedPoses},
            {"gate_stop", g.gateStop},
            {"limited_muscles", limitedJson(g.limited)},
            {"excluded", g.excluded},
            {"passed", g.passed()},
            {"ranked_poses", g.rankedPoses()}}},
          {"increment_scales", reference.increments},
          {"nodes", s.nodes},
          {"tetrahedra", s.elements},
          {"prescribed_nodes", s.prescribedNodes},
          {"newton_iterations", s.newtonIterations},
          {"increments", s.increments},
          {"seconds", s.seconds}};
}

namespace {
/// gateLines' lines on what limits the gates: poses ccx did not solve, excluded or stopped, and
/// the gates not computed.
void addGateLimits(const ReferenceGates& g, std::vector<std::string>& lines) {
  if (!g.statedFailures.empty())
    lines.push_back(
        "ccx did not solve (stated gates: their figures cover the poses before, no "
        "ranking waits on them): " +
        g.statedFailures);
  if (!g.excluded.empty())
    lines.push_back("excluded, not ccx failures (no RMS, gate or ranking covers them): " +
                    g.excluded);
  if (!g.stopped.empty())
    lines.push_back(
        "ccx stopped the reference at pose " + std::to_string(g.solvedPoses) + " of " +
        std::to_string(g.poses) + ", after its retry at finer increments (" + g.stopped + "): " +
        (g.solvedPoses < kMinRankedPoses ? std::string("too few poses to rank over, no ranking")
         : g.gatedPoses >= 0             ? std::string("not a failure")
                                         : "not a failure; every RMS, gate and ranking covers "
                                           "poses 0\u2013" +
                                   std::to_string(g.solvedPoses - 1)));
  if (g.gatedPoses >= 0)
    lines.push_back("a judged gate's solve stopped before the reference (" + g.gateStop + "): " +
                    (g.gatedPoses < kMinRankedPoses
                         ? std::string("too few poses to rank over, no ranking")
                         : "every RMS, gate and ranking covers poses 0\u2013" +
                               std::to_string(g.gatedPoses - 1)));
  if (!g.limited.empty())
    lines.push_back(
        "judged gates' solves stopped some muscles before the others (each muscle is its own ccx "
        "problem; every RMS, gate and ranking follows): " +
        g.limitedText() + "; every other muscle over poses 0\u2013" +
        std::to_string(g.gateablePoses() - 1));
  if (!g.failures.empty()) lines.push_back("ccx did not solve: " + g.failures);
  if (!g.notComputed.empty())
    lines.push_back(
        "not computed, their solves not stored (`fibremss reference` with the scene's "
        "overrides solves them; its `--cells` lists their cells): " +
        g.notComputed);
}
}  // namespace

std::vector<std::string> gateLines(const ReferenceGates& g) {
  std::vector<std::string> lines;
  if (!g.returnNotApplicable.empty())
    lines.push_back("return to rest after the motion: \u2014 (does not apply, not blocking: " +
                    g.returnNotApplicable + ")");
  else
    lines.push_back("return to rest after the motion: " + mmText(g.returnMm) + " RMS (bound " +
                    mmText(kReturnGateMm) + "): " +
                    (std::isnan(g.returnMm) ? "not computed"
                     : g.returnPasses()     ? "passes"
                                            : "FAILS"));
  // " over k/N poses" where a gate compared fewer poses than the motion has.
  const auto over = [&](int compared) {
    return compared < g.poses && compared > 0
               ? " over " + std::to_string(compared) + "/" + std::to_string(g.poses) + " poses"
               : std::string();
  };
  // "... against a third of the methods' spread X: passes" for a gate judged against it.
  const auto verdict = [&](double moved, int compared) {
    if (std::isnan(moved)) return std::string(": not computed");
    if (std::isnan(g.spreadMm))
      return std::string(
          " (passes when below a third of the spread between the methods: needs a comparison)");
    return spreadBoundText(g) + ": " +
           (g.withinSpread(moved, compared) ? "passes"
            : compared < g.gateablePoses()  ? "FAILS (over fewer poses than the reference solved)"
                                            : "FAILS");
  };
  lines.push_back("one level finer (" + (g.refinedBy.empty() ? "\u2014" : g.refinedBy) +
                  "): moves it " + mmText(g.refinementMm) + " RMS" + over(g.refinementPoses) +
                  verdict(g.refinementMm, g.refinementPoses));
  char scale[64] = "\u2014";
  if (!std::isnan(g.incrementsScale)) std::snprintf(scale, sizeof scale, "x%g", g.incrementsScale);
  const std::string increments =
      (g.incrementsPerMuscle.empty() ? std::string(scale) : g.incrementsPerMuscle) +
      (std::isnan(g.incrementsScale) ? "" : " of the default 2.5 deg / 1 mm");
  lines.push_back("increments halved (" + increments + "): moves it " + mmText(g.incrementsMm) +
                  " RMS" + over(g.incrementsPoses) + verdict(g.incrementsMm, g.incrementsPoses));
  lines.push_back("attachment distance x0.5 / x1.5: moves it " + mmText(g.attachmentLowMm) +
                  over(g.attachmentLowPoses) + " / " + mmText(g.attachmentHighMm) +
                  over(g.attachmentHighPoses) + " RMS (stated, not a pass/fail gate)");
  addGateLimits(g, lines);
  return lines;
}

}  // namespace fibremss
