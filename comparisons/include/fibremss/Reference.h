#pragma once
// The CalculiX reference as `reference` and `compare` use it: the cached solve, its gates
// (return to rest, mesh refinement, increments halved, attachment distance ±50 %) and its
// metrics as a run.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <functional>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

#include "fibremss/ReferenceCache.h"
#include "fibremss/RunMetrics.h"

namespace fibremss {

/// How the reference is computed.
struct ReferenceOptions {
  CalculixDefinition definition;  ///< material, element, mesher, attachment rule
  std::string cacheDir;           ///< "" : defaultReferenceCacheDir()
  /// Also solve the gates' variants: attachment distance ±50 %, increments halved, one level
  /// finer (gateDefinitions).
  bool gates = true;
  /// Take the reference (and each gate's solve) only from the cache; what is not there is not
  /// computed (Reference::missing, gates left out). For jobs that must stay short.
  bool cachedOnly = false;
  /// Cells (one muscle of one solve: the reference's or a gate's) solved at once, each a ccx
  /// process of its own; the cache then holds the same entries as a serial run (1).
  int jobs = 1;
  std::function<void(const std::string&)> log;             ///< one line of news (may be empty)
  std::function<void(const ReferenceProgress&)> progress;  ///< while ccx runs (may be empty)
  const std::atomic<bool>* cancel = nullptr;               ///< stop when true
  /// Whether `definition`'s element / contact penalty / contact sliding were given (the
  /// command line's --ccx-element / --ccx-contact / --ccx-sliding); where not, a scene may
  /// choose its own (sceneDefinition).
  bool elementGiven = false;
  bool contactPenaltyGiven = false;
  bool contactSlidingGiven = false;
};

/// The cache directory `options` name: its cacheDir, or defaultReferenceCacheDir() when empty.
std::string resolvedCacheDir(const ReferenceOptions& options);

/// The contact penalty of a sphere-planes reference (× E per metre): 100× the default, so that
/// C3D10's surface nodes stay within 1.5 µm of the plates (with the default they go 0.1–0.28
/// mm in; comparisons/README.md).
inline constexpr double kSpherePlanesContactPenalty = 5e6;

/// Where ccx fails a pose or the return step of a solve (ccxFailureToRetry), it is done once more
/// with its increments × this (CalculixDefinition::incrementScale; its own cache key), only for
/// the muscles ccx failed where the failed solve keeps its parts (retryDefinition). pinch
/// with the attachment distance x0.5 ends on a NaN at 86 % of pose 1 with 1 mm increments and
/// solves with 0.25 mm ones in 29 increments of 2–5 Newton iterations (comparisons/README.md).
inline constexpr double kFinerIncrements = 0.25;

/// `options.definition` for `scene`: a sphere-planes case is solved as C3D10 with
/// kSpherePlanesContactPenalty where the options do not give the element or the penalty. C3D4
/// at ν 0.49 locks and reads Hertz's contact radius 5–12 % short (comparisons/README.md). The
/// contact sliding is the scene's (`reference.contact_sliding`) where the options do not give
/// it; the gates' solves start from this definition, so they use the same formulation.
CalculixDefinition sceneDefinition(const LoadedScene& scene, const ReferenceOptions& options);

/// The bound of the return-to-rest gate [mm]: the surface at rest after the motion, RMS to the
/// prepared rest surface.
inline constexpr double kReturnGateMm = 0.5;
/// The mesh-refinement and increment gates pass when their solve moves the reference by less
/// than this share of the spread between the methods compared.
inline constexpr double kRefinementShareOfSpread = 1.0 / 3.0;
/// The increment gate solves the reference with every increment bound × this. Halving is the
/// step's counterpart of one mesh level (which halves the edge length): where the answer
/// depends on the increment to first order (pinch's small-sliding contact keeps each node's
/// blade face through an increment) the change under halving is half the reference's own
/// increment error, as one level finer estimates the mesh's; where it does not (frictionless
/// contact with finite sliding, no contact: a path-independent hyperelastic equilibrium) it
/// shows as a change near ccx's tolerance (fusiform, the cylinders: 10⁻⁷–3·10⁻⁴ mm; pinch 0.14
/// mm). A quarter would cost twice as much again (cylinder-twist's halved solve: 147
/// increments, 19 min wall) for the same verdict where the error is first order
/// (comparisons/README.md, "Measured: the references, their gates and the
/// fronts").
inline constexpr double kIncrementGateFactor = 0.5;

/// Poses a ranking needs at least: the first pose and one after it. A reference that ccx
/// stops before its second pose (its first posed one) ranks nothing.
inline constexpr int kMinRankedPoses = 2;

/// The reference's gates. NaN where not computed.
struct ReferenceGates {
  double returnMm = RunMetrics::kNone;  ///< RMS at rest after the motion, to the rest surface
  /// Why the return gate does not apply ("" : it does): the motion itself does not return to
  /// rest and ccx did not solve the steps the reference adds back to it.
  std::string returnNotApplicable;
  double refinementMm = RunMetrics::kNone;  ///< RMS one level finer against the reference
  /// What "one level finer" was (quadratic elements or the next level), with its increments
  /// where they are not the reference's.
  std::string refinedBy;
  /// RMS with every increment bound × kIncrementGateFactor against the reference [mm].
  double incrementsMm = RunMetrics::kNone;
  /// That solve's increment bounds × the default ones (2.5° / 1 mm; CalculixDefinition::
  /// incrementScale): 0.5 for a reference at the default, 0.125 for one retried at 0.25.
  double incrementsScale = RunMetrics::kNone;
  /// Where that solve's muscles are at different increments (its reference retried for some
  /// muscles only): its increments per muscle (incrementsText: "x0.0625 for iliacus only
  /// (psoas, gluteal at x0.25)"); "" otherwise.
  std::string incrementsPerMuscle;
  double attachmentLowMm = RunMetrics::kNone;   ///< RMS with the attachment distance × 0.5
  double attachmentHighMm = RunMetrics::kNone;  ///< RMS with it × 1.5
  /// Poses each gate compared (both solves solved them) of the reference's `poses`: a gate
  /// over fewer poses than the motion's says so.
  int poses = 0;
  int refinementPoses = 0, incrementsPoses = 0, attachmentLowPoses = 0, attachmentHighPoses = 0;
  /// Poses the reference itself solved.
  int solvedPoses = 0;
  /// Where ccx failed a pose the reference solved in the judged gates' solves (increments,
  /// refinement; their retry at finer increments failed or was not computed) for every muscle:
  /// the latest of the muscles' stops (each the earliest of its judged solves'). No judged gate
  /// vouches for the reference past it, so every RMS, gate and ranking covers only these poses;
  /// -1 : some muscle was not stopped before the reference (or none was).
  int gatedPoses = -1;
  /// Where gatedPoses is set: the gate's solve and ccx's reason at pose gatedPoses.
  std::string gateStop;
  /// A muscle a judged gate's solve stopped before gateablePoses(): each muscle is its own ccx
  /// problem, so the stop says nothing of the others.
  struct LimitedMuscle {
    size_t muscle = 0;  ///< its index (scene order)
    std::string name;   ///< its name
    int poses = 0;      ///< poses that solve solved of it, counted from the first
    std::string solve;  ///< the gate's solve ("increments halved", "one level finer")
    std::string why;    ///< ccx's reason at pose `poses` ("muscle …: …")
  };
  /// The muscles judged gates' solves stopped before gateablePoses(), in scene order: every RMS,
  /// gate and ranking covers each over its own poses (coveredPoses), the other muscles over
  /// gateablePoses().
  std::vector<LimitedMuscle> limited;
  /// Poses ccx did not finish that block the ranking: of a judged gate's solve (increments,
  /// refinement), or of the reference where it did not stop as `stopped` says (interrupted, its
  /// memory limit, not retried yet).
  std::string failures;
  /// Poses ccx did not finish in a stated gate's solve (the attachment distance × 0.5 / × 1.5):
  /// its figure covers the poses before them (attachmentLowPoses, attachmentHighPoses); they do
  /// not block the ranking.
  std::string statedFailures;
  /// Why ccx stopped the reference at pose `solvedPoses` after its retry at kFinerIncrements
  /// (ccx's reason there; "" : it did not stop). Not a failure where it solved at least
  /// kMinRankedPoses poses: the gates, every RMS and the ranking cover the poses before it.
  std::string stopped;
  /// The gates whose solve is not stored (`--reference-cached-only`), in the listing's order,
  /// each with how many of its muscles' cells are where some are ("one level finer: 4 of 13
  /// muscles' cells stored"); "" where every gate was found or solved.
  std::string notComputed;
  /// Poses without a continuum equilibrium ("poses k to N-1 of N: why"; ContinuumCut): not
  /// solved, not failures; the RMS, the gates and the ranking cover the poses before them.
  std::string excluded;
  /// The spread between the methods compared [mm] (NaN until a comparison sets it) and the
  /// refinement and increment gates' verdicts against it.
  double spreadMm = RunMetrics::kNone;

  bool returnPasses() const { return returnMm <= kReturnGateMm; }
  /// Poses the gates may vouch for: those the reference solved, up to gatedPoses.
  int gateablePoses() const {
    return gatedPoses < 0 ? solvedPoses : std::min(solvedPoses, gatedPoses);
  }
  /// Poses every RMS, gate and ranking covers of muscle `m`: gateablePoses(), or a limited
  /// muscle's own poses; none (0) where those are fewer than kMinRankedPoses (left out of every
  /// figure).
  int coveredPoses(size_t m) const;
  /// Whether a solve that moved the reference by `mm` over `compared` poses passes: below a
  /// third of the spread, over every gateable pose (a finer solve that stopped early without
  /// saying so has measured the easy poses alone).
  bool withinSpread(double mm, int compared) const {
    return mm < kRefinementShareOfSpread * spreadMm && compared >= gateablePoses();
  }
  bool refinementPasses() const { return withinSpread(refinementMm, refinementPoses); }
  bool incrementsPass() const { return withinSpread(incrementsMm, incrementsPoses); }
  /// ccx stopped the reference, or a judged gate's solve, before kMinRankedPoses poses.
  bool stoppedTooSoon() const {
    return (!stopped.empty() || gatedPoses >= 0) && gateablePoses() < kMinRankedPoses;
  }
  /// Every gate passed (the return gate where it applies) and every pose solved but those
  /// excluded and those from where ccx stopped the reference or a judged gate's solve (at least
  /// kMinRankedPoses solved before it): rankings may be reported.
  bool passed() const {
    return (returnPasses() || !returnNotApplicable.empty()) && refinementPasses() &&
           incrementsPass() && failures.empty() && !stoppedTooSoon();
  }
  /// Poses the ranking covers for the muscles not limited, counted from the first: the
  /// gateable ones (0 where nothing may be ranked).
  int rankedPoses() const { return passed() ? gateablePoses() : 0; }
  /// "ranked over poses 0–5 of 19: ccx did not solve pose 6 (why) or later" where a ranking
  /// covers fewer poses than the motion's (ccx stopped the reference or a judged gate's solve,
  /// or a continuum cut), followed by each limited muscle's poses and why ("(iliacus over poses
  /// 0–1: ccx did not solve its pose 2 in the one level finer solve: …)"); "" otherwise.
  std::string rankedPosesText() const;
  /// Each limited muscle's poses and why: "iliacus over poses 0–1: ccx did not solve its pose 2
  /// in the one level finer solve (why)" ("left out of every figure" below kMinRankedPoses),
  /// joined by "; "; "" where none is limited.
  std::string limitedText() const;
  /// The return gate computed, applying, and above its bound.
  bool returnFails() const {
    return !std::isnan(returnMm) && returnNotApplicable.empty() && !returnPasses();
  }
  /// A gate judged against the spread (both known) that moved the reference by `mm` over
  /// `compared` poses and does not pass (withinSpread).
  bool judgedAndFails(double mm, int compared) const {
    return !std::isnan(mm) && !std::isnan(spreadMm) && !withinSpread(mm, compared);
  }
  /// A gate computed and judged that does not pass, or a pose ccx did not solve. Neither this
  /// nor passed(): some gate was not computed (`--no-gates`, a stopped solve) or not judged.
  bool failed() const {
    return returnFails() || judgedAndFails(refinementMm, refinementPoses) ||
           judgedAndFails(incrementsMm, incrementsPoses) || !failures.empty() || stoppedTooSoon();
  }
  /// Why nothing may be ranked against the reference ("" when passed()): that it fails a gate,
  /// that ccx failed a pose the ranking needs or stopped the reference too soon, that its gates
  /// were not computed (those that apply, and notComputed).
  std::string whyNotPassed() const;
};

/// A computed reference.
struct Reference {
  std::string key;            ///< cache key of the reference solve
  std::string cacheEntry;     ///< directory holding its .inp files and results
  bool fromCache = false;     ///< the reference solve came from the cache
  bool missing = false;       ///< cachedOnly and not in the cache: no reference at all
  CalculixSolution solution;  ///< the reference solve
  ReferenceGates gates;
  RunMetrics metrics;  ///< as a run ("calculix"): surfaces of the solved poses, volume, penetration
  std::string description;  ///< one sentence: element, ν, mesh, attachments, ccx version
  std::string increments;   ///< the increments it was solved at (incrementsText)
};

/// The gates' solves, each the reference's definition (its increments and contact sliding
/// included) with one thing changed and no return step (the return gate is the reference's
/// own solve): cheapest first, as solveGates runs them (each is cached as it ends, so a stopped
/// run keeps the cheap ones).
struct GateDefinitions {
  CalculixDefinition attachmentLow;   ///< attachment distance × 0.5
  CalculixDefinition attachmentHigh;  ///< attachment distance × 1.5
  CalculixDefinition increments;      ///< every increment bound × kIncrementGateFactor
  /// One level finer: C3D4 made quadratic (C3D10) on the same tetrahedra, or for a C3D10
  /// reference the next mesh level; from the asked increments, not the reference's retried
  /// ones (like any solve, retried at kFinerIncrements for the muscles ccx fails). Its solve
  /// costs 6–8× the reference's per increment, and the increments gate shows where the path
  /// matters; from a retry's it would cost 4× more (comparisons/README.md, "Gates").
  CalculixDefinition finer;
  std::string refinedBy;  ///< what "one level finer" is, in words
};
/// The gates of the reference solved as `reference`, asked as `asked` (sceneDefinition: they
/// differ where ccx failed the asked increments and the reference is their retry).
/// `poseLimit` (gatePoseLimit of the reference's solve) is every gate's
/// CalculixDefinition::poseLimit: a gate compares the poses the reference solved, and solving
/// those ccx failed in the reference would cost hours to compare none.
GateDefinitions gateDefinitions(const CalculixDefinition& reference,
                                const CalculixDefinition& asked, int poseLimit);

/// The poses a reference's gates solve: where ccx failed a pose of the reference, the poses it
/// solved before it (at least pose 0); else 0 (every pose before the continuum cut: the cut is
/// no failure and the gates' keys stay as they are).
int gatePoseLimit(const CalculixSolution& reference);

/// Solves (or finds in the cache) the reference and, with options.gates, its four gate
/// variants (gateDefinitions); fills the metrics as runPoses does for the simulated methods.
Reference computeReference(const LoadedScene& scene, const PreparedScene& prepared,
                           const ReferenceOptions& options);

/// A reference's cells for a batch engine, in the order `fibremss reference --cell I` numbers
/// them: the reference's muscles, then each gate's (attachment x0.5, x1.5, increments halved,
/// one level finer). Each solve's definition is the one computeReference would solve given the
/// cache: a solve stored with a pose ccx failed is replaced by its retry at kFinerIncrements,
/// and the gates start from the reference's, limited to the poses it solved where it is stored
/// with a pose ccx failed (gatePoseLimit); where the reference is not stored yet, from its
/// default increments over every pose (its retry, where needed, is left to the run that merges
/// the cells).
struct NamedReferenceCell {
  std::string solve;   ///< "reference" or the gate's name
  std::string key;     ///< the solve's cache key
  std::string muscle;  ///< the muscle's name
  ReferenceCell cell;  ///< what cachedCalculixMuscle solves
  /// The solve or this muscle's part of it is in the cache, or a retry keeps this muscle from
  /// the failed solve (retryDefinition) and that keeps its part: nothing to solve.
  bool stored = false;
  /// Where the solve is a retry at kFinerIncrements: the key of the stored solve whose failed
  /// pose it retries (a fresh machine finds the retry through it); else "".
  std::string retryOf;
};
std::vector<NamedReferenceCell> referenceCells(const LoadedScene& scene,
                                               const PreparedScene& prepared,
                                               const ReferenceOptions& options);

/// The retry of `definition`, whose solve `failed` had a pose ccx failed (ccxFailureToRetry):
/// its increments × kFinerIncrements for the muscles ccx failed; where `failed` keeps its
/// muscles' parts (CalculixSolution::muscles) and some solved every step, those keep their
/// increments (CalculixDefinition::muscleIncrementScales; incrementScale the finest of them, and
/// no per-muscle scales where every muscle ends at one) and their parts are taken from `failed`
/// as they are, not solved again. Its cache key says which muscle was solved at which
/// increments, so a mixed retry never shares the key of one of every muscle at the finer ones.
/// A failed solve stored without its parts (before they were kept) is retried whole.
CalculixDefinition retryDefinition(const CalculixDefinition& definition,
                                   const CalculixSolution& failed);

/// The increments `definition` solves at, × the default 2.5° / 1 mm: "x0.25", or per muscle
/// "x0.25 for iliacus only (psoas, gluteal at x1)".
std::string incrementsText(const CalculixDefinition& definition, const PreparedScene& prepared);

/// What a solve is retried at kFinerIncrements for: the first pose ccx failed ("pose k: why"),
/// else its failed return step ("return to rest: why"); "" when none failed, or when it was
/// interrupted or stopped on its memory limit (which finer increments do not mend).
std::string ccxFailureToRetry(const CalculixSolution& solution);

/// RMS between two solutions' surfaces [mm] over the (muscle, pose) pairs covered: muscle m
/// (its `vertices[m]` after the previous muscles') over its first `covered[m]` poses, up to the
/// poses where both have the surface of every muscle covered there (a muscle's from its part
/// where another muscle failed the pose: CalculixSolution::muscles), their count into `compared`
/// where given. NaN where none.
double rmsBetweenSolutions(const CalculixSolution& a, const CalculixSolution& b,
                           std::span<const size_t> vertices, std::span<const int> covered,
                           int* compared = nullptr);

/// The spread between methods: per method family (the name before ':' and the cost suffix
/// '@'), its best RMS to the reference; the spread is the largest minus the smallest of those,
/// or the one family's best when only one was compared. NaN when no run has an RMS.
double methodSpreadMm(const std::vector<RunMetrics>& runs);

/// {"key", "cache_entry", "missing": true} when it was not in the cache (cachedOnly), else
/// {"key", "cache_entry", "from_cache", "description", "poses": [{"solved", "failure"}...],
/// "gates": {...}, "increment_scales" (Reference::increments), "nodes", "tetrahedra",
/// "prescribed_nodes", "newton_iterations", "increments", "seconds"} (NaN written as null).
nlohmann::json referenceJson(const Reference& reference);

/// The gates as lines of text, one per gate: value, bound and verdict ("—" where a value is
/// missing); the refinement and increment gates say "needs a comparison" while spreadMm is
/// NaN.
std::vector<std::string> gateLines(const ReferenceGates& gates);

}  // namespace fibremss
