#pragma once
// Runs one scene through several methods measured the same way (Measures.h): FibreMSS and
// its variants, the self-reference (FibreMSS at dt/8 and 8× iterations), the btSoftBody
// baseline and the FEM reference; then the RMS of every run's surfaces to the FEM and
// self-reference runs, pose by pose.
#include <atomic>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "fibremss/BaselineScene.h"
#include "fibremss/FemBuilder.h"
#include "fibremss/Reference.h"
#include "fibremss/RunMetrics.h"
#include "fibremss/Scene.h"
#include "fibremss/SoftBodyBuilder.h"

namespace fibremss {

/// The "equilibrium" method: FibreMSS's projective solver at every pose until its force
/// residual's RMS equivalent displacement (MuscleSystem::forceResidual, StopRule::Residual) is
/// below this [m] (1e-5 mm), from the previous pose's equilibrium. The equivalent displacement is
/// a local measure: on fusiform a state 1e-3 mm from zero by it lay 1.6 mm from the equilibrium
/// (docs/performance.md, "Distance to equilibrium"), so the bound sits near the float floor (about
/// 1e-5 mm there).
inline constexpr double kEquilibriumResidual = 1e-8;
/// Its iteration cap per pose (a pose that reaches it is counted in RunMetrics::unconvergedPoses).
inline constexpr int kEquilibriumIterations = 3000;
/// Its projective ρ (MuscleSystemDef::projectiveRho; momentum ω = 2/(1 + √(1 − ρ²))): a run
/// of thousands of iterations is left with the slowest modes, whose rate is closer to 1 than the
/// 0.9 a 10-iteration pose is tuned for. fusiform R=12 with the fans, pose 2, iterations to a
/// 1e-5 mm residual: ρ 0.9 none within 3 000 (1.2e-5 mm plateau), 0.98 2 544, 0.99 1 632, 0.995
/// 1 088; with per-tetrahedron terms 496, 208, 144, 96 (docs/decisions.md, "Solver").
inline constexpr double kEquilibriumRho = 0.99;
/// The time-to-accuracy figure's bound: a pose within this RMS of its equilibrium [mm].
inline constexpr double kEquilibriumAccuracyMm = 0.5;

/// The methods `compare` runs by default (Methods.h: those marked byDefault).
std::vector<std::string> defaultMethods();

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
  std::vector<std::string> methods = defaultMethods();  ///< Methods.h names, or their variants
  SoftBodyDefinition softBody;  ///< the baseline (poseDuration set from the scene, see below)
  FemDefinition fem;            ///< Bullet's FEM method (poseDuration set from the scene)
  bool fronts = true;           ///< each method swept over its cost knob (frontMethods)
  bool withReference = true;    ///< compute (or find) the CalculiX reference and its gates
  ReferenceOptions reference;   ///< how (log, progress and cancel are set by runComparison)
  int selfReferenceFactor = 8;  ///< self-reference: dt / f and f × iterations
  std::function<void(const MethodProgress&)> progress;  ///< after every step (may be empty)
  std::function<void(const std::string&)> log;          ///< one line of news (may be empty)
  /// Stop when true: a FibreMSS run within its current step, a baseline after it.
  const std::atomic<bool>* cancel = nullptr;
  double methodBudgetSeconds = 0;  ///< > 0: a method stops after the step that passes this wall
                                   ///< time (its metrics cover the steps done, interrupted set)
  /// The "equilibrium" method's iteration cap per pose (--equilibrium-cap).
  int equilibriumIterations = kEquilibriumIterations;
};

/// Iterations counted for the pose duration when the stop rule makes them only a cap.
inline constexpr int kPoseIterationsCap = 100;

/// Simulated time of one pose for the baseline and the reference: what FibreMSS can at most
/// simulate in one step (iterations × dt, the upper clamp of the adaptive dt; for the
/// converged and time-budget stop rules at most kPoseIterationsCap iterations).
double poseDuration(const StepSettings& step);

/// One run's options shared by the baseline and reference runners.
struct MethodRunOptions {
  std::function<void(const MethodProgress&)> progress;  ///< after every step (may be empty)
  const std::atomic<bool>* cancel = nullptr;            ///< stop after the current step
  double budgetSeconds = 0;  ///< > 0: wall time after which the FEM stops inside its pose
};

/// A baseline simulator (`build` makes it at the scene's first pose) on every pose of the scene,
/// measured the way runFibreMSS measures: penetration into the bones' true meshes over all
/// steps, volume change at the last intact step, spring deviation at the last step, and a run
/// that NaNs or explodes by FibreMSS's guard rule failed at that step.
RunMetrics runBaseline(
    const LoadedScene& scene, const std::string& method, const PreparedScene& prepared,
    const MethodRunOptions& options,
    const std::function<std::unique_ptr<BaselineScene>(std::span<const btTransform>)>& build);

/// Volume change of all muscles together (rest-volume weighted) [%] for their surfaces
/// concatenated in muscle order (NaN when no muscle has a rest surface).
double volumeChangePct(const PreparedScene& prepared, std::span<const btVector3> surfaces);

/// Poses both runs reached without failing (the first ones: a run stops at its first failure).
int sharedPoses(const RunMetrics& a, const RunMetrics& b);

/// Root-mean-square surface distance between two runs over the poses both reached (NaN when
/// they share none or their surfaces differ in size); `worstPose`, when given, receives the
/// largest per-pose RMS.
double rmsBetweenRuns(const RunMetrics& a, const RunMetrics& b, double* worstPose = nullptr);

/// The scene's settings for the "equilibrium" method: the projective integrator and the residual
/// stop rule at kEquilibriumResidual with `cap` iterations per pose at most, ρ kEquilibriumRho,
/// the bones moving over as many iterations as in the scene's own settings.
MuscleSystemDef equilibriumSettings(const MuscleSystemDef& simulation,
                                    int cap = kEquilibriumIterations);

/// Fills rmsToReferenceMm / rmsToSelfReferenceMm / rmsToEquilibriumMm of every run from the
/// runs among them whose roles (roleOf, Methods.h) are Reference, SelfReference and Equilibrium
/// (each gets 0 against itself).
void fillRms(std::vector<RunMetrics>& runs);

/// One muscle's share of a run's concatenated pose surfaces (RunMetrics::poseSurfaces).
struct SurfaceBlock {
  std::string muscle;   ///< the muscle's name
  size_t vertices = 0;  ///< its surface vertices, in scene order after the previous blocks'
};

/// The blocks of `prepared`'s muscles, in scene order.
std::vector<SurfaceBlock> surfaceBlocks(const PreparedScene& prepared);

/// Against the "equilibrium" run among `runs`: each run's vertex RMS per pose, its worst pose,
/// each muscle's RMS over the poses and per pose (`blocks` split the surfaces), the muscle with
/// the largest RMS over the poses and the muscle and pose with the largest single RMS. A run
/// without a shared pose, or whose surfaces the blocks do not split, keeps none.
void fillMusclesToEquilibrium(std::vector<RunMetrics>& runs, std::span<const SurfaceBlock> blocks);

/// Against the reference's run (kReferenceMethod) among `runs`: each run's vertex RMS per pose,
/// shape RMS (symmetric nearest-surface distance, per muscle surface) and worst muscle (largest
/// vertex RMS over the shared poses). Runs without a shared pose keep NaN.
void fillReferenceShapes(std::vector<RunMetrics>& runs, const PreparedScene& prepared);

/// Symmetric nearest-surface RMS of two surfaces with the same triangles [mm]: the distance of
/// each vertex of either to the other surface, over both vertex sets.
double shapeRmsMm(const TriangleMesh& a, const TriangleMesh& b);

/// A method and its scene overrides, parsed from "name" or "fibremss:k=v+k=v".
struct MethodSpec {
  std::string name;    ///< the full name as given
  std::string family;  ///< the method's name (Methods.h): "fibremss", "btsoftbody", ...
  std::vector<std::string> overrides;  ///< FibreMSS: extra --set overrides; other methods:
                                       ///< their knobs ("iterations=N", "substeps=xF", ...)
};
/// Throws InputError for an unknown method or a malformed variant.
MethodSpec parseMethod(const std::string& name);

/// A knob's value: "N" (an integer > 0) or "xF" (F times `defaultValue`, rounded, at least 1);
/// 0 when it is neither.
int knobValue(const std::string& value, int defaultValue);

/// The setting that ends a FibreMSS step's iterations under `step`'s stop rule, and so its
/// cost: `iterations` for a fixed count, `budget_ms` for the time budget, the threshold of the
/// others (`tolerance` of the residual and equilibrium rules, `epsilon`, `deviation_epsilon`),
/// where the iterations are only a cap.
struct FibreKnob {
  std::string key;         ///< the scene key (`--set`)
  bool costGrows = false;  ///< a larger value costs more (a count, a budget; not a threshold)
};
FibreKnob fibreCostKnob(const StepSettings& step);

/// Each method with a front (Methods.h) swept over its cost knob, cheapest first: fibremss over
/// the knob of `simulation`'s stop rule (fibreCostKnob: a count or budget ×0.5, 1, 2, 4, a
/// threshold ×2, 1, 0.5, 0.25) and its resolution (×0.5, 2), btsoftbody over its link iterations
/// (×0.5, 1, 2), fem over its substeps (×0.5, 1, 2); other methods and variants as they are.
std::vector<std::string> frontMethods(const std::vector<std::string>& methods,
                                      const MuscleSystemDef& simulation);

/// Each FibreMSS run of the resolution front (`fibremss`, at `resolution`, and
/// `fibremss:resolution=N`) gets rmsToFinerResolutionMm against the run at twice its resolution,
/// where there is one.
void fillFinerResolution(std::vector<RunMetrics>& runs, int resolution);

/// What one comparison ran: the scene as loaded and every method's metrics.
/// The override that switches muscle–muscle contact off, as the methods a reference ranks run.
inline constexpr const char* kNoMuscleContact = "collision.muscle_muscle=false";

struct Comparison {
  std::string scene;  ///< scene name
  /// The --set overrides the methods ran with: those it was loaded with, and kNoMuscleContact
  /// where muscleContactOff.
  std::vector<std::string> overrides;
  int resolution = 0;                  ///< particles per fibre (first muscle), 0 if none
  double stepDeg = RunMetrics::kNone;  ///< sweep step of the motion (NaN if not a sweep)
  std::vector<RunMetrics> runs;        ///< the reference ("calculix") first, then the methods
  std::optional<Reference> reference;  ///< the CalculiX reference, its gates against the runs
  /// The scene collides its muscles with each other, the reference does not, and so every
  /// method ran without muscle–muscle contact to solve the reference's problem.
  bool muscleContactOff = false;
};

/// Loads and prepares the scene once (again for variants with overrides), runs every method
/// in order and fills the RMS fields.
Comparison runComparison(const std::string& sceneNameOrPath,
                         const std::vector<std::string>& overrides, const CompareOptions& options);

}  // namespace fibremss
