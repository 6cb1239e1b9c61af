#pragma once
// Per-muscle results of a run: each muscle measured at a step (MuscleStep, what a
// per-step series is made of) and summed up over the run (MuscleResults, summary.json
// "muscles"), so that the worst muscle shows instead of an average over all of them.
#include <LinearMath/btTransform.h>

#include <limits>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

#include "fibremss/Geometry.h"
#include "fibremss/MuscleSettings.h"

namespace fibremss {

/// One muscle measured at one step.
struct MuscleStep {
  static constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
  bool finite = true;                   ///< every particle and surface vertex is finite
  double volumeChangePct = kNone;       ///< surface volume against rest [%]
  std::vector<double> penetrationMm;    ///< per bone: deepest surface vertex inside it [mm]
  double meanFibreLengthMm = kNone;     ///< mean length of the fibres [mm]
  double worstSpringRatio = kNone;      ///< largest l / L0 of its springs
  double springDeviationRatio = kNone;  ///< Σ|l − L0| / ΣL0 of its springs
  double maxFibreStretch = kNone;       ///< largest l / L0 of its fibre segments
  /// largest l / L0 of its other fibre segments (the belly)
  double maxBellyStretch = kNone;
  /// largest l / L0 of its fibre segments in a tendon (both ends tendon or fixed; NaN: none)
  double maxTendonStretch = kNone;
  /// strain of its belly's fibre segments: Σl / ΣL0 − 1 over them [1]
  double bellyStrain = kNone;
  /// strain of its tendons' fibre segments (as maxTendonStretch's; NaN: none) [1]
  double tendonStrain = kNone;
  /// Its free boundary particles whose collision sphere reaches into a bone's true mesh (filled
  /// by runFibreMSS from its sphere test; measureMuscle leaves 0).
  size_t boneContacts = 0;
  /// Per bone: the deepest of those spheres inside its true mesh (filled with boneContacts) [mm].
  std::vector<double> sphereDepthMm;
  /// Its force residual (MuscleSystem::forceResidual; filled by runFibreMSS): RMS and largest
  /// equivalent displacement over its free particles [mm].
  double residualRmsMm = kNone;
  double residualMaxMm = kNone;  ///< see residualRmsMm [mm]
  /// Springs tearing broke so far (MuscleSystem::tear; filled by runFibreMSS for a muscle that
  /// tears, else −1: no such column).
  long brokenSprings = -1;
  long pieces = -1;  ///< its pieces (MuscleTear::pieces), as brokenSprings; −1: it does not tear
  /// Springs blades cut so far (MuscleTear::cutSprings; filled by runFibreMSS in a scene with
  /// blades, else −1: no such column).
  long cutSprings = -1;
  /// Whether the muscle tears (its tear is measured).
  bool tears() const { return brokenSprings >= 0; }

  /// The deepest surface vertex inside any bone [mm] (NaN when not measured).
  double maxPenetrationMm() const;
  /// The deepest free particle sphere inside any bone [mm] (NaN when not measured).
  double maxSphereDepthMm() const;
};

/// Measures a muscle (its particles `positions`, deformed surface `surface`) against the bones'
/// true meshes `bones` (rest frames) placed at `boneTransforms`. A muscle with a non-finite
/// particle or vertex gets only `finite = false`.
MuscleStep measureMuscle(const MuscleSettings& muscle, std::span<const btVector3> positions,
                         std::span<const btVector3> surface,
                         std::span<const MeshDistance* const> bones,
                         std::span<const btTransform> boneTransforms);

/// One muscle at one step: a row of series.csv and of summary.json "series", what a user plots
/// against the joint angle.
struct SeriesRow {
  int step = 0;               ///< solver step (0: the first)
  int pose = 0;               ///< pose of the motion at that step
  double poseLabel = 0;       ///< the pose's label (LoadedScene::poseLabels, e.g. a joint angle)
  double timeS = 0;           ///< simulated time at the end of the step [s]
  std::string muscle;         ///< the muscle's name
  MuscleStep measures;        ///< the muscle's measures at that step
  size_t solverContacts = 0;  ///< sphere pairs the solver found overlapping in the step's last
                              ///< iteration, all muscles, muscle–muscle and muscle–bone
                              ///< (StepStats::contacts)
};

/// The series as CSV: a header, then one line per row (a value not measured is left empty).
std::string seriesCsv(const std::vector<SeriesRow>& rows);
/// The series as a JSON array of objects with the CSV's column names (null: not measured).
nlohmann::json seriesJson(const std::vector<SeriesRow>& rows);
/// Reads what seriesJson wrote (per-bone penetration and sphere depth come back as the one
/// deepest value).
std::vector<SeriesRow> seriesFromJson(const nlohmann::json& array);

/// A muscle's results over a run, from the steps it was measured at.
struct MuscleResults {
  static constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
  std::string name;                      ///< the muscle's name
  std::vector<std::string> bones;        ///< bone names, the order of the per-bone fields
  double volumeChangePct = kNone;        ///< at the last finite step [%]
  double worstVolumeChangePct = kNone;   ///< of largest magnitude over the finite steps [%]
  int worstVolumeStep = -1;              ///< the step of worstVolumeChangePct
  std::vector<double> maxPenetrationMm;  ///< per bone: deepest surface vertex, all steps [mm]
  std::vector<double> maxSphereDepthMm;  ///< per bone: deepest free particle sphere, all steps [mm]
  std::vector<size_t> fixedParticles;    ///< per bone: particles fixed to it
  bool frozen = false;                   ///< the numerical guard froze it
  int frozenStep = -1;                   ///< the step that froze it
  std::string frozenCause;               ///< "nan" or "exploded" (empty when not frozen)
  int rollbacks = 0;                     ///< step attempts it failed that the guard rolled back
  double fibreLengthRestMm = kNone;      ///< mean fibre length at rest [mm]
  double fibreLengthLastMm = kNone;      ///< at the last finite step [mm]
  double fibreLengthMinMm = kNone;       ///< smallest over the finite steps [mm]
  double fibreLengthMaxMm = kNone;       ///< largest over the finite steps [mm]
  double worstSpringRatio = kNone;       ///< largest l / L0 over the finite steps
  double worstBellyStretch = kNone;      ///< largest MuscleStep::maxBellyStretch over them
  double worstTendonStretch = kNone;     ///< largest MuscleStep::maxTendonStretch over them
  double worstBellyStrain = kNone;       ///< largest MuscleStep::bellyStrain over them [1]
  double worstTendonStrain = kNone;      ///< largest MuscleStep::tendonStrain over them [1]
  double springDeviationRatio = kNone;   ///< Σ|l − L0| / ΣL0 at the last finite step
  long brokenSprings = -1;  ///< springs broken at the last step measured (−1: it does not tear)
  long pieces = -1;         ///< its pieces at the last step measured (−1: it does not tear)
  long cutSprings = -1;     ///< springs cut at the last step measured (−1: no blade)
  int lastStep = -1;        ///< the last finite step measured (-1: none)

  /// Name, bones, fixed particles per bone and the rest fibre length of `muscle`.
  MuscleResults(const MuscleSettings& muscle, std::vector<std::string> boneNames);
  MuscleResults() = default;
  /// Adds step `step`'s measures (a non-finite step changes nothing: earlier steps' stay).
  void add(int step, const MuscleStep& measures);
};

nlohmann::json toJson(const MuscleResults& results);
/// Reads what toJson wrote (missing keys keep their defaults).
MuscleResults muscleResultsFromJson(const nlohmann::json& object);

/// The muscles as a Markdown table: volume change (last and worst), penetration and fixed
/// particles per bone, mean fibre length, worst spring, worst belly and tendon stretch and strain,
/// rollbacks, frozen; broken springs and pieces when a muscle tears.
std::string muscleTable(const std::vector<MuscleResults>& muscles);

/// The muscle whose last volume change is largest in magnitude (null when none was measured).
const MuscleResults* worstVolumeMuscle(const std::vector<MuscleResults>& muscles);

}  // namespace fibremss
