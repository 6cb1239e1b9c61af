#pragma once
// The accuracy reference: each muscle's static equilibrium per pose, solved by CalculiX
// (Debian calculix-ccx) as a Neo-Hookean body (*STATIC, NLGEOM) on a conforming tetrahedral
// mesh of its surface (tetgen -pYq: the surface vertices are mesh nodes). Attachments follow
// FibreMSS's rule: material within a muscle's attachment distance of a bone moves rigidly with
// that bone (prescribed displacements per pose). The surface meshed is the loaded one:
// preparation moves surface vertices that lie inside a bone out of it, which makes thigh13's
// prepared surfaces self-intersect (24–481 facet pairs per muscle, tetgen -d); those vertices
// are attached, so the reference reports them where that bone carries the prepared vertex.
// Muscle–bone contact is modelled (bones as rigid tetgen-meshed obstacles, penalty contact:
// `contactPenalty`; every free surface node a slave, C3D10's midside nodes included).
// Not modelled: muscle–muscle contact, gravity, activation; each muscle is solved on its own.
#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "fibremss/Calculix.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"

namespace fibremss {

/// What bounds an attached node's move within one increment (CalculixDefinition::incrementRule).
enum class IncrementRule : uint8_t {
  World,  ///< its whole move: a tibia attachment carried 70 mm by the hip takes 70 increments
  /// Its move relative to the rigid motion of the frame in which the muscle's attached nodes
  /// move least: a bone's (any of the scene's) or the world's. A rigid motion carries the
  /// muscle's rest state to an equilibrium of its own (a translation exactly, a turn bounded by
  /// the 2.5° rule), so only the deformation part needs small increments.
  BoneFrame,
};
const char* toString(IncrementRule rule);

/// What the reference solves and how.
struct CalculixDefinition {
  /// Neo-Hookean, ν = 0.49 (muscle is nearly incompressible). Every load is a prescribed
  /// displacement (no gravity) and the contact penalty scales with E, so the displacements do
  /// not depend on E; E is stated.
  NeoHookeMaterial material;
  /// Linear tetrahedra; the mesh-refinement gate solves the same mesh with quadratic C3D10
  /// (which also measures C3D4's volumetric locking at ν = 0.49; comparisons/README.md).
  CalculixElement element = CalculixElement::C3D4;
  TetgenDefinition mesher;       ///< tetgen settings and the refinement level
  btScalar attachmentScale = 1;  ///< × each muscle's attachment distance (the ±50 % gate)
  /// Steps back to the rest pose after the poses (the return gate), retracing them so that no
  /// bone turns more than 45° in one step.
  bool returnToRest = true;
  /// Muscle–bone contact: every bone meshed (tetgen) as a rigid obstacle whose boundary is a
  /// frictionless node-to-surface penalty contact for the muscle's free surface nodes (C3D10:
  /// midside ones too), with the pressure-overclosure slope K = contactPenalty × E [1/m] (50
  /// per mm: 1 µm of overclosure carries 5 % of E). 0: no contact (the muscle passes through
  /// bones).
  double contactPenalty = 5e4;
  /// How ccx tracks that contact (finite sliding: its default). A scene chooses small sliding
  /// where its muscle slides little against the bones within a step (LoadedScene::reference):
  /// pinch's C3D10 solve stops in pose 1 with finite sliding and solves with small
  /// (comparisons/README.md). In the cache key only where it is small.
  ContactSliding contactSliding = ContactSliding::Finite;
  double initialIncrement = 1;  ///< first increment of a step (ccx cuts it back as needed)
  /// × the largest increment of every step: at 1 no bone turns more than 2.5° and no attached
  /// node moves more than 1 mm within one increment. A reference that ccx fails is solved again
  /// at a quarter of it (comparisons' Reference.h: kFinerIncrements): ccx cuts an increment back
  /// where Newton diverges slowly, but exits where a diverging contact iteration turns to NaN
  /// first (pinch with the attachment distance x0.5: a 10.9 m correction at 86 % of pose 1,
  /// then "matrix found to be singular"). In the cache key only where it is not 1.
  double incrementScale = 1;
  /// Per muscle, the incrementScale its job is solved at, where the muscles differ (empty:
  /// every muscle at incrementScale): a retry at finer increments of the muscles ccx failed in
  /// a solve, the others as that solve gave them (comparisons' retryDefinition). In the cache
  /// key only where it is not empty.
  std::vector<double> muscleIncrementScales;
  /// Which move the 1 mm bound applies to. In the cache key only where it is BoneFrame (the
  /// world rule's entries keep their keys).
  IncrementRule incrementRule = IncrementRule::BoneFrame;
  /// Poses given to ccx: at most this many leading ones (0: every pose before the continuum
  /// cut). A gate of a reference that ccx solved only in part stops where the reference stopped
  /// (comparisons' gateDefinitions). In the cache key only where it drops a pose.
  int poseLimit = 0;
  std::string program = "ccx";  ///< the CalculiX executable (PATH is searched)
  /// Address-space limit of each ccx run [GiB] (0: none). A run that exceeds it fails its
  /// allocation and its poses are reported failed, naming the limit. Not in the cache key: it
  /// changes whether a solve finishes, never its result.
  double memoryLimitGiB = defaultCalculixMemoryGiB();

  /// The incrementScale muscle `m`'s job is solved at.
  double incrementScaleOf(size_t m) const {
    return m < muscleIncrementScales.size() ? muscleIncrementScales[m] : incrementScale;
  }
};

/// The definition muscle `m` of `definition` is solved at, as a solve of every muscle at it:
/// its incrementScale that muscle's, without per-muscle scales.
CalculixDefinition muscleDefinition(const CalculixDefinition& definition, size_t m);

/// Where the motion leaves no static continuum equilibrium. Two bones close across a muscle:
/// some point of the muscle's rest volume lies d_a from one bone and d_b from another with
/// d_a + d_b below twice the muscle's attachment distance, where at rest that pair left more
/// room than that. Material there is within the attachment distance of both bones (FibreMSS's
/// rule moves it with each), so the muscle must be cut (pinch's blades passing like shears); a
/// static continuum has no answer at that pose, nor at any later one (the muscle is torn).
struct ContinuumCut {
  int pose = -1;       ///< first pose without a continuum equilibrium; -1: every pose has one
  double gapMm = 0;    ///< the smallest d_a + d_b there [mm]
  std::string reason;  ///< why, in words: the bones, the muscle, the gap and its bound
};

/// Each muscle's loaded volume sampled on a grid of half its attachment distance (coarser for a
/// big muscle: at most ~10^5 grid points each): where findContinuumCut measures the bones'
/// gaps. Taking them is most of a cut's cost (thigh13 R=20: about 1.5 s) and depends on the
/// scene's muscles alone, so it is done once per scene.
struct ContinuumSamples {
  std::vector<std::vector<btVector3>> muscles;  ///< per muscle, points inside it [m]
};

ContinuumSamples sampleContinuum(const LoadedScene& scene);

/// The poses given to ccx, counted from the first: those before the continuum cut (all without
/// one), at most `poseLimit` where that is above 0 (CalculixDefinition::poseLimit).
int ccxPoseCount(const LoadedScene& scene, const ContinuumCut& cut, int poseLimit = 0);

/// Finds the first pose where two bones close across a muscle (ContinuumCut) at its samples,
/// with each muscle's attachment distance × `attachmentScale` (the attachment gates' solves
/// attach more or less material, so their cut can come earlier or later). `bones` are the
/// bones' rest meshes in scene order.
ContinuumCut findContinuumCut(const LoadedScene& scene, const std::vector<MeshDistance>& bones,
                              const ContinuumSamples& samples, btScalar attachmentScale = 1);

/// Where a reference solve is, after every step ccx finishes.
struct ReferenceProgress {
  std::string muscle;  ///< muscle being solved
  int muscleIndex = 0;
  int muscles = 0;
  int step = 0;        ///< steps finished of this muscle's job
  int steps = 0;       ///< steps in it (the poses, then the steps back to rest)
  double seconds = 0;  ///< since the solve started
};

/// One muscle's share of a reference solve: its own ccx job (muscles have no contact with each
/// other in the reference, so each is solved on its own and the muscles of a solve can run at
/// once, as separate ccx processes).
struct MuscleSolution {
  /// Per step of its job (the poses before the cut, then the steps back to rest): its surface
  /// vertices [m] (prepared restSurface order), empty where ccx gave none.
  std::vector<std::vector<btVector3>> stepSurfaces;
  std::string failure;         ///< "" or why ccx stopped (its last error line)
  size_t nodes = 0;            ///< nodes of its job (midside and bone obstacle nodes included)
  size_t tetrahedra = 0;       ///< tetrahedra of its mesh
  size_t prescribedNodes = 0;  ///< its nodes moved with a bone
  long newtonIterations = 0;   ///< summed over its increments (ccx's .sta)
  long increments = 0;         ///< increments ccx took over its steps
  double seconds = 0;          ///< wall time of its tetgen and ccx runs [s]
  std::string inputFile;       ///< its .inp ("" : shipped, solved elsewhere)
  bool interrupted = false;    ///< cancelled before the end

  /// Whether its ccx run failed an allocation under its memory limit (solved again).
  bool hitMemoryLimit() const;
  /// Whether ccx finished every step of its job (not interrupted).
  bool solvedEveryStep() const { return failure.empty() && !interrupted; }
};

/// The reference's result: per pose, all muscles' surface vertices (prepared restSurface order,
/// muscle after muscle), or why ccx did not give that pose.
struct CalculixSolution {
  std::vector<std::vector<btVector3>> poseSurfaces;  ///< per pose; empty where it failed
  std::vector<std::string> poseFailures;             ///< per pose: "" or the reason
  std::vector<btVector3> returnSurface;  ///< after the step back to rest (empty: none / failed)
  std::string returnFailure;             ///< "" or why the return step failed
  size_t nodes = 0;                      ///< mesh nodes of all muscles (midside included)
  size_t elements = 0;                   ///< tetrahedra of all muscles
  size_t prescribedNodes = 0;            ///< nodes moved with a bone
  long newtonIterations = 0;             ///< summed over all increments (from ccx's .sta)
  long increments = 0;                   ///< increments ccx took over all steps
  double seconds = 0;                    ///< wall time of tetgen and ccx
  std::vector<std::string> inputFiles;   ///< the .inp files, one per muscle solved on this machine
  bool interrupted = false;              ///< cancelled before the end
  /// Poses from cut.pose on are not solved (no continuum equilibrium: not a ccx failure; their
  /// poseFailures stay ""); the return step starts from the last pose before it.
  ContinuumCut cut;
  /// Where ccx failed a muscle's job (not interrupted): every muscle's part in muscle order,
  /// those that solved every step with their step surfaces, the others without; empty
  /// otherwise. A retry at finer increments takes the solved ones as they are and solves only
  /// the others again (comparisons' retryDefinition). Stored with the solution.
  std::vector<MuscleSolution> muscles;

  /// Poses solved, counted from the first (a failed pose ends the run of solved ones).
  int solvedPoses() const;
  /// Whether a ccx run failed an allocation under its memory limit (a failure names the
  /// limit): the cache solves such a key again instead of giving it back.
  bool hitMemoryLimit() const;
};

/// Meshes muscle `m` and solves its poses with ccx in `workDir` (created; its .inp, .dat, .sta
/// and logs are kept there, named muscle<m>.*). Poses from `cut.pose` on (findContinuumCut at
/// the definition's attachment scale) and past its poseLimit are not given to ccx (ccxPoseCount;
/// assembled, they are unsolved without a failure). Throws InputError for a muscle that tetgen
/// cannot mesh or that has no material near any bone, unless the scene is a sphere-planes case:
/// then the sphere is held by its symmetry (the node nearest its centre fixed, three nodes'
/// equations against rigid rotation; no effect on the exact answer).
MuscleSolution solveCalculixMuscle(
    const LoadedScene& scene, const PreparedScene& prepared, const CalculixDefinition& definition,
    const ContinuumCut& cut, size_t m, const std::string& workDir,
    const std::function<void(const ReferenceProgress&)>& progress = {},
    const std::atomic<bool>* cancel = nullptr);

/// Muscle `m`'s part as ccx left it in `solvedDir` (a solve's directory: its muscle<m>.inp,
/// .dat, .sta and .log), without ccx: its mesh made again by tetgen in `workDir`; false (nothing
/// read) where the input made again is not the one ccx solved there. Its seconds are ccx's own
/// ("Total CalculiX Time" in its log; tetgen's not counted, 0 where ccx did not end); where ccx
/// failed it and its log names no error, its failure says "exit -1".
bool readSolvedMuscle(const LoadedScene& scene, const PreparedScene& prepared,
                      const CalculixDefinition& definition, const ContinuumCut& cut, size_t m,
                      const std::string& solvedDir, const std::string& workDir,
                      MuscleSolution& part);

/// The solution of the muscles' parts, in muscle order (fewer than the scene's muscles: a solve
/// interrupted after them). A pose ccx does not finish for a muscle is reported in poseFailures
/// (with ccx's last error line), never dropped; the solution's `cut` is `cut`; its seconds are
/// the parts' summed.
CalculixSolution assembleCalculixSolution(const LoadedScene& scene, const PreparedScene& prepared,
                                          const CalculixDefinition& definition,
                                          const ContinuumCut& cut,
                                          const std::vector<MuscleSolution>& muscles);

/// Every muscle solved in turn (solveCalculixMuscle) in `workDir`, assembled
/// (assembleCalculixSolution); stops after a muscle that was interrupted.
CalculixSolution solveCalculixReference(
    const LoadedScene& scene, const PreparedScene& prepared, const CalculixDefinition& definition,
    const ContinuumCut& cut, const std::string& workDir,
    const std::function<void(const ReferenceProgress&)>& progress = {},
    const std::atomic<bool>* cancel = nullptr);

}  // namespace fibremss
