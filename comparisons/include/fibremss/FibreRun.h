#pragma once
// Runs a loaded, prepared scene through FibreMSS: one solver step per pose of the scene's
// motion, measured every step the way every method is measured (Measures.h), optionally
// writing ParaView frames. Used by `fibremss run` and `fibremss compare`.
#include <atomic>
#include <functional>
#include <string>
#include <vector>

#include "fibremss/Measures.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/RunMetrics.h"
#include "fibremss/Scene.h"

namespace fibremss {

/// Where a run is, passed to the progress callback after every step.
struct RunProgress {
  int step = 0;                         ///< steps done (1 after the first)
  int steps = 0;                        ///< steps planned
  long iterations = 0;                  ///< solver iterations so far
  double seconds = 0;                   ///< wall time since the run started
  const StepStats* lastStep = nullptr;  ///< statistics of the step just done
};

/// How to run. The defaults run every pose of the scene without writing anything.
struct FibreRunOptions {
  std::string outDir;       ///< write frames and run.pvd here ("": write nothing)
  bool vtkFrames = true;    ///< frames as VTK XML (frames/*.vtp, run.pvd)
  bool gltfFrames = false;  ///< frames as glTF 2.0 binary (gltf/frame_NNNNN.glb)
  int frameEvery = -1;  ///< a frame every k-th step (the first and last included); < 0: the scene's
                        ///< outputs.frameEvery; 0: no frames
  int steps = -1;       ///< steps to run (< 0: one per pose); steps past the last pose hold it
  std::string method = "fibremss";  ///< method name written to the metrics
  bool keepPoseSurfaces = true;     ///< fill RunMetrics::poseSurfaces (for RMS between methods)
  std::function<void(const RunProgress&)> progress;  ///< called after every step (may be empty)
  /// When it becomes true the run stops within the current step, at the end of its running
  /// iteration (MuscleSystem::setCancelFlag; unless `interrupt` is set, then after the step):
  /// that step is neither measured nor written, the steps before it are; metrics.interrupted set.
  const std::atomic<bool>* cancel = nullptr;
  /// The user's Ctrl-C flag when `cancel` is a flag of the caller's own (a time budget that its
  /// progress callback sets between steps): this one is polled within the steps instead.
  const std::atomic<bool>* interrupt = nullptr;
  bool loopMotion = false;  ///< steps past the last pose sweep the motion back and forth (a soak
                            ///< run) instead of holding the last pose
  long sampleEvery = 0;     ///< iterations between soak samples (FibreRunDetails::samples; 0: none)
};

/// A muscle the numerical guard froze during a run.
struct FrozenMuscle {
  std::string name;  ///< the muscle's name
  int step = 0;      ///< the step that froze it
  bool nan = false;  ///< it had NaN/inf (else: burst springs)
};

/// A muscle that failed attempts of a step the numerical guard rolled back.
struct Rollback {
  int step = 0;        ///< the step
  std::string muscle;  ///< the muscle's name
  int attempts = 0;    ///< attempts of the step it failed (the first try and retries)
  bool nan = false;    ///< NaN/inf in one of them (else: springs beyond 3× their rest length)
};

/// The state of a long run every FibreRunOptions::sampleEvery iterations.
struct SoakSample {
  int step = 0;               ///< steps done
  long iterations = 0;        ///< solver iterations done
  double seconds = 0;         ///< wall time since the run started
  double msPerIteration = 0;  ///< solver wall time per iteration since the previous sample
  double residentMb = 0;      ///< resident set of the process now (VmRSS)
  double fixedDriftMm = 0;    ///< largest distance of a fixed particle from T·rest now
  bool finite = true;         ///< every particle is finite
};

/// What a FibreMSS run measures beyond RunMetrics.
struct FibreRunDetails {
  /// The boundary particles' collision spheres in the bones' true meshes: per sphere
  /// max(0, radius − signed distance of its centre), deepest bone; over all steps.
  Penetration spherePenetration;
  int frames = 0;  ///< frames written
  /// Median wall time of measuring one step [ms]; not part of RunMetrics::timing, which is the
  /// method's own cost (an application embedding FibreMSS does not measure).
  double measureMsPerStep = RunMetrics::kNone;
  /// Median wall time of extracting every muscle's implicit surface for one frame [ms]
  /// (OutputSettings::implicitSurface; kNone without).
  double implicitSurfaceMsPerFrame = RunMetrics::kNone;
  int rolledBackSteps = 0;           ///< steps the numerical guard rolled back
  int retries = 0;                   ///< attempts it repeated with a smaller dt, all steps
  std::vector<FrozenMuscle> frozen;  ///< muscles it froze, in order
  std::vector<Rollback> rollbacks;   ///< per rolled-back step, each muscle that failed in it
  /// Steps after which a muscle was trapped between bones (StepStats::trappedMuscles > 0).
  int trappedSteps = 0;
  int firstTrappedStep = -1;        ///< the first of them (-1: none)
  size_t trappedParticlesMax = 0;   ///< most particles still caught between bones after a step
  std::vector<SoakSample> samples;  ///< every options.sampleEvery iterations
};

/// Runs the scene. Step s sets every bone to the scene's pose min(s, poseCount−1) (looping: s
/// swept forth and back over the poses), steps the solver and measures every muscle
/// (RunMetrics::muscles: volume change, penetration into each bone's true mesh, fibre length,
/// worst spring, rollbacks, freezes) and the penetration of all muscle surfaces' vertices into
/// the bones (max over steps; mean over all penetrating vertices of all steps). The headline
/// volume change and spring deviation are the worst muscle's at its last finite step; steps
/// before a failure keep their measures. Stops at the first step the numerical guard could not
/// save (failedStep): NaN/an explosion left in place, or a muscle frozen, except under
/// FailurePolicy::StopBody, where the other muscles go on to the last step (failedStep is then
/// the first freeze). Throws std::runtime_error if frames cannot be written.
/// `details`, when given, receives what RunMetrics has no place for.
RunMetrics runFibreMSS(const LoadedScene& scene, const PreparedScene& prepared,
                       const FibreRunOptions& options = {}, FibreRunDetails* details = nullptr);

}  // namespace fibremss
