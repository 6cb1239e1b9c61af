#pragma once
// Runs one scene through several methods measured the same way (Measures.h): FibreMSS and
// its variants, the self-reference (FibreMSS at dt/8 and 8× iterations), the btSoftBody
// baseline and the FEM reference; then the RMS of every run's surfaces to the FEM and
// self-reference runs, pose by pose.
#include <atomic>
#include <functional>
#include <string>
#include <vector>

#include "fibremss/FemBuilder.h"
#include "fibremss/RunMetrics.h"
#include "fibremss/Scene.h"
#include "fibremss/SoftBodyBuilder.h"

namespace fibremss {

/// The "equilibrium" method: FibreMSS at every pose until the mean displacement per iteration is
/// below this [m] (1e-4 mm), from the previous pose's equilibrium.
inline constexpr double kEquilibriumEpsilon = 1e-7;
/// Its iteration cap per pose (a pose that reaches it is counted in RunMetrics::unconvergedPoses).
inline constexpr int kEquilibriumIterations = 20000;
/// The time-to-accuracy figure's bound: a pose within this RMS of its equilibrium [mm].
inline constexpr double kEquilibriumAccuracyMm = 0.5;

/// Method names `compare` knows; "fibremss:<key>=<value>[+<key>=<value>...]" adds a FibreMSS
/// variant with those scene overrides (e.g. "fibremss:integrator=semi-implicit-euler").
inline constexpr const char* kDefaultMethods[] = {"fibremss", "self-reference", "btsoftbody",
                                                  "fem"};

/// Where a method run is, passed to the progress callback after every step.
struct MethodProgress {
  std::string method;   ///< method running
  int step = 0;         ///< steps done
  int steps = 0;        ///< steps planned
  long iterations = 0;  ///< iterations so far
  double seconds = 0;   ///< since this method started
};

/// How `compare` runs.
struct CompareOptions {
  std::vector<std::string> methods{std::begin(kDefaultMethods), std::end(kDefaultMethods)};
  SoftBodyDefinition softBody;  ///< the baseline (poseDuration set from the scene, see below)
  FemDefinition fem;            ///< the reference (poseDuration set from the scene)
  int selfReferenceFactor = 8;  ///< self-reference: dt / f and f × iterations
  std::function<void(const MethodProgress&)> progress;  ///< after every step (may be empty)
  std::function<void(const std::string&)> log;          ///< one line of news (may be empty)
  const std::atomic<bool>* cancel = nullptr;            ///< stop after the current step when true
  double methodBudgetSeconds = 0;  ///< > 0: a method stops after the step that passes this wall
                                   ///< time (its metrics cover the steps done, interrupted set)
};

/// Iterations counted for the pose duration when the stop rule makes them only a cap.
inline constexpr int kPoseIterationsCap = 100;

/// Simulated time of one pose for the baseline and the reference: what FibreMSS can at most
/// simulate in one step (iterations × dt, the upper clamp of the adaptive dt; for the
/// converged and time-budget stop rules at most kPoseIterationsCap iterations).
double poseDuration(const SimulationParameters& simulation);

/// One run's options shared by the baseline and reference runners.
struct MethodRunOptions {
  std::function<void(const MethodProgress&)> progress;  ///< after every step (may be empty)
  const std::atomic<bool>* cancel = nullptr;            ///< stop after the current step
  double budgetSeconds = 0;  ///< > 0: wall time after which the FEM stops inside its pose
};

/// The btSoftBody baseline on every pose of the scene.
RunMetrics runSoftBody(const LoadedScene& scene, const PreparedScene& prepared,
                       const SoftBodyDefinition& definition, const MethodRunOptions& options = {});
/// The FEM reference on every pose of the scene.
RunMetrics runFem(const LoadedScene& scene, const PreparedScene& prepared,
                  const FemDefinition& definition, const MethodRunOptions& options = {});

/// Poses both runs reached without failing (the first ones: a run stops at its first failure).
int sharedPoses(const RunMetrics& a, const RunMetrics& b);

/// Root-mean-square surface distance between two runs over the poses both reached (NaN when
/// they share none or their surfaces differ in size); `worstPose`, when given, receives the
/// largest per-pose RMS.
double rmsBetweenRuns(const RunMetrics& a, const RunMetrics& b, double* worstPose = nullptr);

/// The scene's settings for the "equilibrium" method: the converged stop rule at
/// kEquilibriumEpsilon with kEquilibriumIterations as the cap, the bones moving over as many
/// iterations as in the scene's own settings.
SimulationParameters equilibriumSettings(const SimulationParameters& simulation);

/// Fills rmsToFemMm / rmsToSelfReferenceMm / rmsToEquilibriumMm of every run from the "fem",
/// "self-reference" and "equilibrium" runs among them (the references get 0 against themselves).
void fillRms(std::vector<RunMetrics>& runs);

/// A method and its scene overrides, parsed from "name" or "fibremss:k=v+k=v".
struct MethodSpec {
  std::string name;    ///< the full name as given
  std::string family;  ///< "fibremss", "self-reference", "equilibrium", "btsoftbody", "fem"
  std::vector<std::string> overrides;  ///< extra --set overrides of a FibreMSS variant
};
/// Throws InputError for an unknown method or a malformed variant.
MethodSpec parseMethod(const std::string& name);

/// What one comparison ran: the scene as loaded and every method's metrics.
struct Comparison {
  std::string scene;                   ///< scene name
  std::vector<std::string> overrides;  ///< the --set overrides it was loaded with
  int resolution = 0;                  ///< particles per fibre (first muscle), 0 if none
  double stepDeg = RunMetrics::kNone;  ///< sweep step of the motion (NaN if not a sweep)
  std::vector<RunMetrics> runs;        ///< in the order of the methods
};

/// Loads and prepares the scene once (again for variants with overrides), runs every method
/// in order and fills the RMS fields.
Comparison runComparison(const std::string& sceneNameOrPath,
                         const std::vector<std::string>& overrides, const CompareOptions& options);

}  // namespace fibremss
