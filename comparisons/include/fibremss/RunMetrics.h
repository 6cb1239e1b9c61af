#pragma once
// The metrics of one run of one method on one scene: the same fields for FibreMSS,
// btSoftBody and FEM, written to summary.json by `run` and `compare`.
#include <LinearMath/btVector3.h>

#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "fibremss/MuscleMetrics.h"

namespace fibremss {

/// Median milliseconds per iteration spent in each part of a FibreMSS step (seed 004 Table 1).
struct PartTiming {
  double mss = 0;       ///< spring forces + volume term + integration
  double muscleCd = 0;  ///< muscle–muscle collision detection
  double boneCd = 0;    ///< muscle–bone collision detection
  double response = 0;  ///< collision response
  double output = 0;    ///< the solver's fibres and surfaces (measuring for reports excluded)
  double volume = 0;    ///< the volume term (part of mss)
};

/// sphere-planes at one pose: the plate's approach, the contact patch's radius on it and Hertz's.
struct ContactPose {
  static constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
  int pose = 0;
  double approachMm = kNone;     ///< δ: how far the plate moved towards the centre [mm]
  double radiusMm = kNone;       ///< contact radius of the surface on the plate [mm]
  double exactRadiusMm = kNone;  ///< Hertz: √(Rδ) [mm]
};

/// An analytic case measured at the last pose (sphere-planes: at every pose), beside its exact
/// answer (NaN: does not apply).
struct AnalyticMetrics {
  static constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
  /// "cylinder-stretch", "cylinder-twist", "sphere-planes" ("": none)
  std::string type;
  double poissonRatio = kNone;          ///< effective ν = −ln(r/r0) / ln(stretch), mid-section
  double exactPoissonRatio = kNone;     ///< the homogeneous Neo-Hookean answer's
  double volumeChangePct = kNone;       ///< the muscle's volume against rest [%]
  double exactVolumeChangePct = kNone;  ///< exact [%]
  double midRadiusRatio = kNone;        ///< mid-section radius / rest radius
  double exactMidRadiusRatio = kNone;   ///< exact
  double midRotationDeg = kNone;        ///< twist: rotation of the mid-section about the axis [°]
  double exactMidRotationDeg = kNone;   ///< exact (half the end's twist)
  double rotationErrorDeg = kNone;  ///< twist: largest |rotation − exact| over 9 sections [°]
  /// twist: the surface's vertex RMS to the exact torsion of the rest surface (each vertex
  /// turned by the twist at its rest place along the axis) [mm]
  double exactTorsionRmsMm = kNone;
  std::vector<ContactPose> contact;  ///< sphere-planes: per pose (step) measured

  /// |volume change − exact| [percentage points]: the measure methods are ranked by on an
  /// analytic case (no reference needed); NaN when either is missing.
  double volumeErrorPct() const { return std::abs(volumeChangePct - exactVolumeChangePct); }
};

/// One muscle's surface vertex RMS to another surface: the CalculiX reference's or the
/// "equilibrium" run's.
struct MuscleRms {
  static constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
  std::string muscle;             ///< the muscle's name
  double rmsMm = kNone;           ///< over the poses both runs reached [mm]
  std::vector<double> perPoseMm;  ///< per pose both reached, in order [mm]
};

/// The largest surface vertex RMS to the "equilibrium" run of one muscle at one pose.
struct MusclePoseRms {
  static constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
  std::string muscle;    ///< the muscle ("": none measured)
  int pose = -1;         ///< the pose (index into poseSurfaces; -1: none)
  double rmsMm = kNone;  ///< its RMS [mm]
};

/// Vertices of a run's pose surfaces that count over fewer poses than it has (one muscle's).
struct SurfaceLimit {
  size_t first = 0;  ///< the first of them in a pose's surface
  size_t count = 0;  ///< how many
  int poses = 0;     ///< the poses they count over, counted from the first
};

/// One run's results. NaN marks a metric that does not apply or was not measured.
struct RunMetrics {
  static constexpr double kNone = std::numeric_limits<double>::quiet_NaN();

  std::string scene;              ///< scene name
  std::string method;             ///< "fibremss", "btsoftbody", "fem", "fibremss:<variant>", ...
  std::string integrator;         ///< integrator name where it applies
  size_t particles = 0;           ///< particles / nodes
  size_t springs = 0;             ///< springs / links / tetrahedra
  size_t boundaryParticles = 0;   ///< colliding particles
  size_t boneSpheres = 0;         ///< bone spheres (FibreMSS)
  int steps = 0;                  ///< simulation steps (poses) run
  int poses = 0;                  ///< poses of the scene's motion (steps planned)
  long iterations = 0;            ///< solver iterations in total
  int threads = 0;                ///< threads the method computed with (0: not recorded)
  double msPerStep = kNone;       ///< median wall time of one step
  double msPerIteration = kNone;  ///< median wall time of one iteration
  /// Median wall time of one time step: a FibreMSS iteration (one integration step of dt), a
  /// Bullet world substep (btSoftBody, FEM).
  double msPerTimeStep = kNone;
  PartTiming timing;                 ///< per-part breakdown (FibreMSS)
  double maxPenetrationMm = kNone;   ///< surface vertices into bones' true meshes
  double meanPenetrationMm = kNone;  ///< mean over penetrating vertices
  double volumeChangePct = kNone;    ///< final volume against rest [%], the worst muscle's
  /// The largest |volume change| of one muscle at any pose [%] (FibreMSS), and that muscle.
  double worstMuscleVolumeChangePct = kNone;
  std::string worstVolumeMuscle;        ///< the muscle of worstMuscleVolumeChangePct
  double springDeviationRatio = kNone;  ///< Σ|l−L0|/ΣL0 (spring families), the worst muscle's
  double rmsToReferenceMm = kNone;      ///< surface vertex RMS against the CalculiX reference [mm]
  /// Symmetric nearest-surface RMS against the reference [mm]: every vertex's distance to the
  /// other surface, both ways (sliding along the surface is not counted), over all poses.
  double shapeRmsToReferenceMm = kNone;
  std::string worstMuscle;          ///< the muscle with the largest vertex RMS to the reference
  double worstMuscleRmsMm = kNone;  ///< its vertex RMS over all poses [mm]
  std::vector<double> rmsToReferencePerPoseMm;  ///< vertex RMS per pose both reached [mm]
  /// Per muscle (scene order): its vertex RMS to the reference, over the poses and per pose.
  std::vector<MuscleRms> musclesToReference;
  double rmsToSelfReferenceMm = kNone;  ///< against FibreMSS at dt/8, 8× iterations
  /// Against the "equilibrium" run (FibreMSS converged at every pose): RMS over the poses, and
  /// the worst pose's RMS.
  double rmsToEquilibriumMm = kNone;
  double worstPoseRmsToEquilibriumMm = kNone;     ///< the largest per-pose RMS to equilibrium
  int rmsToEquilibriumPoses = 0;                  ///< poses rmsToEquilibriumMm covers
  std::vector<double> rmsToEquilibriumPerPoseMm;  ///< vertex RMS per pose both reached [mm]
  int worstPoseToEquilibrium = -1;  ///< the pose of worstPoseRmsToEquilibriumMm (-1: none)
  /// Per muscle (scene order): its vertex RMS to the equilibrium run, over the poses and per pose.
  std::vector<MuscleRms> musclesToEquilibrium;
  std::string worstMuscleToEquilibrium;          ///< the muscle with the largest RMS over poses
  double worstMuscleRmsToEquilibriumMm = kNone;  ///< its RMS over the poses [mm]
  MusclePoseRms worstMusclePoseToEquilibrium;    ///< the farthest muscle at any single pose
  /// Against the same method's run at twice the resolution (fillFinerResolution): how much one
  /// level finer moves it, its discretisation's share of the error [mm].
  double rmsToFinerResolutionMm = kNone;
  int unconvergedPoses = 0;  ///< "equilibrium" run: poses that hit the iteration cap unconverged
  /// The force residual after each step measured (FibreMSS; MuscleSystem::forceResidual, all
  /// muscles): RMS and largest over the free particles of the equivalent displacement |r_i|/k_i
  /// [mm] and of the force |r_i| [N], one entry per step (NaN: the step was not finite).
  std::vector<double> residualRmsMmPerPose;
  std::vector<double> residualMaxMmPerPose;  ///< see residualRmsMmPerPose [mm]
  std::vector<double> residualRmsNPerPose;   ///< see residualRmsMmPerPose [N]
  std::vector<double> residualMaxNPerPose;   ///< see residualRmsMmPerPose [N]
  int residualWorstPose = -1;       ///< the step of the largest RMS equivalent displacement
  double residualRmsMm = kNone;     ///< that step's RMS equivalent displacement [mm]
  double residualMaxMm = kNone;     ///< that step's largest equivalent displacement [mm]
  double residualRmsN = kNone;      ///< that step's RMS force [N]
  double residualMaxN = kNone;      ///< that step's largest force [N]
  size_t residualContacts = 0;      ///< that step's particles a contact held (ForceResidual)
  int rmsToReferencePoses = 0;      ///< poses rmsToReferenceMm covers (both reached them intact)
  int rmsToSelfReferencePoses = 0;  ///< poses rmsToSelfReferenceMm covers
  bool nan = false;                 ///< a NaN or inf appeared
  bool exploded = false;            ///< stability criteria violated
  int failedStep = -1;              ///< step where it failed, -1 if none
  /// The reference: its first pose without a continuum equilibrium (not solved, not a
  /// failure; ContinuumCut), -1 if none, and why.
  int excludedFrom = -1;
  std::string exclusion;
  bool interrupted = false;     ///< stopped by the user (Ctrl-C)
  double peakMemoryMb = kNone;  ///< peak resident set of the process
  double wallSeconds = 0;       ///< whole run

  AnalyticMetrics analytic;  ///< the scene's exact case, if it is one

  /// Per muscle (FibreMSS): volume, penetration per bone, fixed particles, fibre length, worst
  /// spring, rollbacks, freezes; the headline volume change and spring deviation are the worst
  /// muscle's.
  std::vector<MuscleResults> muscles;
  /// Per step, per muscle (FibreMSS): volume, mean fibre length, largest fibre stretch,
  /// deepest penetration, contacts; the steps in order, the muscles in scene order within each.
  std::vector<SeriesRow> series;
  /// Per pose, the surface vertices of all muscles concatenated (for RMS between methods);
  /// a NaN or exploded pose is left out.
  std::vector<std::vector<btVector3>> poseSurfaces;
  /// The reference: the muscles a judged gate's solve stopped before the others
  /// (ReferenceGates::limited); no RMS counts their vertices from their `poses` on. Empty: every
  /// vertex of every pose counts.
  std::vector<SurfaceLimit> surfaceLimits;
};

/// JSON object with the summary keys (snake_case; NaN written as null; no poseSurfaces).
nlohmann::json toJson(const RunMetrics& metrics);
/// Reads what toJson wrote (missing keys keep their defaults).
RunMetrics runMetricsFromJson(const nlohmann::json& object);

}  // namespace fibremss
