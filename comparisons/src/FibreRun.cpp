#include "fibremss/FibreRun.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "FrameWriter.h"
#include "fibremss/Analytic.h"
#include "fibremss/Geometry.h"
#include "fibremss/Measures.h"
#include "fibremss/Messages.h"
#include "fibremss/MuscleMetrics.h"
#include "fibremss/Output.h"
#include "fibremss/SceneSystem.h"

namespace fibremss {
namespace {

using Clock = std::chrono::steady_clock;

double millisecondsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

double median(std::vector<double> values) {
  if (values.empty()) return RunMetrics::kNone;
  const size_t middle = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + middle, values.end());
  if (values.size() % 2 == 1) return values[middle];
  const double upper = values[middle];
  return 0.5 * (upper + *std::max_element(values.begin(), values.begin() + middle));
}

double medianOrZero(std::vector<double> values) {
  return values.empty() ? 0.0 : median(std::move(values));
}

/// A memory figure of this process from /proc/self/status ("VmHWM:" peak resident set,
/// "VmRSS:" resident set now) [MB] (NaN where unavailable).
double statusMemoryMb(const char* field) {
  std::ifstream status("/proc/self/status");
  std::string key;
  while (status >> key) {
    if (key == field) {
      double kilobytes = 0;
      status >> kilobytes;
      return kilobytes / 1024.0;
    }
    status.ignore(1 << 12, '\n');
  }
  return RunMetrics::kNone;
}

/// The pose of step s: the scene's poses in order, then the last one held, or when looping
/// swept back to the first and forth again (0, 1, …, P−1, P−2, …, 1, 0, 1, …).
int poseOfStep(int s, int poseCount, bool loop) {
  const int last = std::max(poseCount, 1) - 1;
  if (!loop || last == 0) return std::min(s, last);
  const int phase = s % (2 * last);
  return phase <= last ? phase : 2 * last - phase;
}

/// The label of a pose (the pose's number where the scene gives none).
double poseLabel(const LoadedScene& scene, int pose) {
  return size_t(pose) < scene.poseLabels.size() ? scene.poseLabels[size_t(pose)] : pose;
}

/// Largest distance of a fixed particle from where its bone puts it (T·rest) [mm].
double fixedDriftMm(const MuscleSystem& system, std::span<const MuscleHandle> muscles,
                    std::span<const BoneHandle> bones) {
  double drift = 0;
  for (MuscleHandle handle : muscles) {
    const MuscleSettings& muscle = system.settings(handle);
    std::span<const btVector3> x = system.positions(handle);
    for (uint32_t p : muscle.fixedParticles) {
      const btVector3 target =
          system.boneTransform(bones[muscle.fixedBone[p]]) * muscle.restPositions[p];
      drift = std::max(drift, 1000.0 * double(x[p].distance(target)));
    }
  }
  return drift;
}

bool inside(const btVector3& p, const btVector3& lower, const btVector3& upper) {
  return p.x() >= lower.x() && p.y() >= lower.y() && p.z() >= lower.z() && p.x() <= upper.x() &&
         p.y() <= upper.y() && p.z() <= upper.z();
}

/// The bones' true meshes, to measure how deep muscle geometry sits in them.
class BoneMeshes {
 public:
  explicit BoneMeshes(const PreparedScene& prepared) {
    for (const auto& bone : prepared.bones) {
      distances_.emplace_back(bone->mesh);
      btVector3 lower, upper;
      pointBounds(bone->mesh.vertices, lower, upper);
      lower_.push_back(lower);
      upper_.push_back(upper);
    }
    for (const MeshDistance& distance : distances_) pointers_.push_back(&distance);
    inverses_.resize(distances_.size());
  }

  /// The bones' distance trees (rest frames), as Measures.h takes them.
  std::span<const MeshDistance* const> meshes() const { return pointers_; }

  /// Points (surface vertices) inside the bones placed at `transforms`; `depthsMm` (one per
  /// point) receives each one's depth [mm].
  Penetration points(std::span<const btVector3> points, std::span<const btTransform> transforms,
                     std::span<float> depthsMm) const {
    return measurePenetration(points, pointers_, transforms, depthsMm);
  }

  /// Free boundary particles' spheres in the bones: max(0, r − signed distance of the centre)
  /// (fixed particles sit on their bones by design and are left out); `perBoneMm` receives the
  /// deepest in each bone [mm].
  Penetration spheres(const MuscleSettings& muscle, std::span<const btVector3> positions,
                      std::span<const btTransform> transforms, std::vector<double>& perBoneMm) {
    for (size_t b = 0; b < transforms.size(); ++b) inverses_[b] = transforms[b].inverse();
    perBoneMm.assign(distances_.size(), 0.0);
    Penetration result;
    double sum = 0;
    for (uint32_t p : muscle.boundaryParticles) {
      if (muscle.isFixed(p)) continue;
      ++result.points;
      const btScalar radius = muscle.radii[p];
      const btVector3 margin(radius, radius, radius);
      btScalar depth = 0;
      for (size_t b = 0; b < distances_.size(); ++b) {
        const btVector3 local = inverses_[b] * positions[p];
        if (!inside(local, lower_[b] - margin, upper_[b] + margin)) continue;
        const btScalar inBone = radius - distances_[b].signedDistance(local);
        perBoneMm[b] = std::max(perBoneMm[b], 1000.0 * inBone);
        depth = std::max(depth, inBone);
      }
      if (depth > 0) {
        ++result.penetrating;
        sum += 1000.0 * depth;
        result.maxMm = std::max(result.maxMm, 1000.0 * depth);
      }
    }
    if (result.penetrating > 0) result.meanMm = sum / static_cast<double>(result.penetrating);
    return result;
  }

 private:
  std::vector<MeshDistance> distances_;        ///< one per bone, rest frame
  std::vector<const MeshDistance*> pointers_;  ///< the same, as Measures.h takes them
  std::vector<btVector3> lower_, upper_;       ///< rest-frame bounds per bone
  std::vector<btTransform> inverses_;          ///< current → rest, per bone (scratch)
};

/// The force residual of all muscles together after a step: sums of squares over the free
/// particles and the largest, of the equivalent displacement [mm², mm] and the force [N², N].
struct PoseResidual {
  double displacementSquares = 0, forceSquares = 0, maxMm = 0, maxN = 0;
  size_t particles = 0, contacts = 0;  ///< free particles; of them held by a contact
};

/// Step s's force residual (`pose`, NaN where the step was not finite) into the per-pose lists,
/// and the headline fields when its RMS equivalent displacement is the largest so far.
void addPoseResidual(RunMetrics& metrics, const PoseResidual& pose, bool finite, int s) {
  const double count = finite && pose.particles > 0 ? static_cast<double>(pose.particles) : NAN;
  const double rmsMm = std::sqrt(pose.displacementSquares / count);
  const double rmsN = std::sqrt(pose.forceSquares / count);
  const double maxMm = std::isnan(count) ? NAN : pose.maxMm;
  const double maxN = std::isnan(count) ? NAN : pose.maxN;
  metrics.residualRmsMmPerPose.push_back(rmsMm);
  metrics.residualMaxMmPerPose.push_back(maxMm);
  metrics.residualRmsNPerPose.push_back(rmsN);
  metrics.residualMaxNPerPose.push_back(maxN);
  if (std::isnan(rmsMm) || rmsMm <= metrics.residualRmsMm) return;
  metrics.residualWorstPose = s;
  metrics.residualRmsMm = rmsMm;
  metrics.residualMaxMm = maxMm;
  metrics.residualRmsN = rmsN;
  metrics.residualMaxN = maxN;
  metrics.residualContacts = pose.contacts;
}

/// Per-muscle results over a run (MuscleMetrics.h) and what the numerical guard did to each
/// muscle: rollbacks named by muscle and cause, freezes.
class MuscleLedger {
 public:
  /// `cuts`: the scene has blades (every muscle's cuts and pieces are measured).
  MuscleLedger(MuscleSystem& system, std::span<const MuscleHandle> muscles,
               const PreparedScene& prepared, bool cuts)
      : system_(system), muscles_(muscles), seen_(muscles.size()), cuts_(cuts) {
    std::vector<std::string> boneNames;
    for (const auto& bone : prepared.bones) boneNames.push_back(bone->name);
    for (MuscleHandle muscle : muscles) results.emplace_back(system.settings(muscle), boneNames);
  }

  /// After step s (at `where`): every muscle measured (a non-finite one keeps its earlier
  /// steps' results) with its free spheres' depth in the bones and its force residual (all of
  /// them together in `poseResidual`), a series row each, the muscles
  /// that failed a rolled-back attempt named in `guard.rollbacks`, the newly frozen ones in
  /// `guard.frozen`. Returns whether every muscle was finite.
  bool afterStep(const SeriesRow& where, const StepStats& stats, BoneMeshes& bones,
                 std::span<const btTransform> transforms, FibreRunDetails& guard) {
    poseResidual = PoseResidual{};
    measured_.clear();
    for (MuscleHandle muscle : muscles_) measured_.push_back(measure(muscle, bones, transforms));
    // Every muscle's residual in one call (a contact pair's reaction needs both muscles), after
    // the measures: the next step starts from the caches it leaves, as when each muscle's own
    // call came last (thigh13 R=40 ms_per_step read about 5 % higher with the call first).
    system_.forceResidual();
    bool finite = true;
    for (size_t m = 0; m < muscles_.size(); ++m) finite = record(m, where, stats, guard) && finite;
    return finite;
  }

  PoseResidual poseResidual;           ///< of the last afterStep (its finite muscles)
  std::vector<MuscleResults> results;  ///< one per muscle, in order
  std::vector<SeriesRow> series;       ///< per step, per muscle
  /// Free boundary particles' spheres in the bones, all finite muscles and steps.
  Penetration spherePenetration;

 private:
  /// A muscle's measures after a step, with its free spheres' depth in the bones when finite.
  MuscleStep measure(MuscleHandle muscle, BoneMeshes& bones,
                     std::span<const btTransform> transforms) {
    const MuscleSettings& settings = system_.settings(muscle);
    MuscleStep step = measureMuscle(settings, system_.positions(muscle), system_.surface(muscle),
                                    bones.meshes(), transforms);
    if (settings.breakStretch > 0 || cuts_) {
      const MuscleTear tear = system_.tear(muscle);
      step.brokenSprings = long(tear.brokenSprings);
      step.pieces = long(tear.pieces);
      if (cuts_) step.cutSprings = long(tear.cutSprings);
    }
    if (step.finite) {
      const Penetration spheres =
          bones.spheres(settings, system_.positions(muscle), transforms, step.sphereDepthMm);
      step.boneContacts = spheres.penetrating;
      spherePenetration = combine(spherePenetration, spheres);
    }
    return step;
  }

  /// Muscle m's measures (measured_[m]) with its residual into its results and a series row;
  /// its rollbacks and a new freeze into `guard`. Returns whether it was finite.
  bool record(size_t m, const SeriesRow& where, const StepStats& stats, FibreRunDetails& guard) {
    const MuscleHandle muscle = muscles_[m];
    MuscleStep& step = measured_[m];
    const bool finite = step.finite;
    if (finite) addResidual(system_.lastForceResidual(muscle), step);
    const int s = where.step;
    MuscleResults& result = results[m];
    result.add(s, step);
    series.push_back(where);
    series.back().muscle = result.name;
    series.back().measures = std::move(step);
    const MuscleFailures now = system_.failures(muscle);
    const int attempts = now.attempts - seen_[m].attempts, nan = now.nan - seen_[m].nan;
    seen_[m] = now;
    if (attempts > 0 && stats.rolledBack) {
      result.rollbacks += attempts;
      guard.rollbacks.push_back({s, result.name, attempts, nan > 0});
    }
    if (system_.frozen(muscle) && !result.frozen) {
      result.frozen = true;
      result.frozenStep = s;
      result.frozenCause = nan > 0 ? "nan" : "exploded";
      guard.frozen.push_back({result.name, s, nan > 0});
    }
    return finite;
  }

  /// A muscle's residual into its measures and the pose's sums.
  void addResidual(const ForceResidual& residual, MuscleStep& step) {
    step.residualRmsMm = 1000 * residual.rmsDisplacement;
    step.residualMaxMm = 1000 * residual.maxDisplacement;
    const auto count = static_cast<double>(residual.particles);
    poseResidual.displacementSquares += step.residualRmsMm * step.residualRmsMm * count;
    poseResidual.forceSquares += residual.rmsForce * residual.rmsForce * count;
    poseResidual.maxMm = std::max(poseResidual.maxMm, step.residualMaxMm);
    poseResidual.maxN = std::max(poseResidual.maxN, residual.maxForce);
    poseResidual.particles += residual.particles;
    poseResidual.contacts += residual.contactParticles;
  }

  MuscleSystem& system_;
  std::span<const MuscleHandle> muscles_;
  std::vector<MuscleFailures> seen_;  ///< each muscle's failures after the previous step
  std::vector<MuscleStep> measured_;  ///< each muscle's measures in the current afterStep
  bool cuts_;                         ///< the scene has blades: cuts and pieces are measured
};

/// The per-step timings of a run [ms]: the step, per iteration its parts, the measures.
struct StepTimings {
  std::vector<double> msPerStep;         ///< the step's wall time [ms]
  std::vector<double> msPerIteration;    ///< the step's wall time per iteration [ms]
  std::vector<double> mss;               ///< mass-spring per iteration [ms]
  std::vector<double> volumeTerm;        ///< volume terms per iteration [ms]
  std::vector<double> muscleCd;          ///< muscle collision detection per iteration [ms]
  std::vector<double> boneCd;            ///< bone collision detection per iteration [ms]
  std::vector<double> response;          ///< collision response per iteration [ms]
  std::vector<double> output;            ///< output per iteration [ms]
  std::vector<double> measureMsPerStep;  ///< the step's measures [ms]

  /// A step's figures: its wall time, its measures' and its stats' parts.
  void add(double stepMs, double measureMs, const StepStats& stats) {
    const double iterations = std::max(stats.iterations, 1);
    msPerStep.push_back(stepMs);
    msPerIteration.push_back(stepMs / iterations);
    mss.push_back(stats.timing.mss / iterations);
    volumeTerm.push_back(stats.timing.volume / iterations);
    muscleCd.push_back(stats.timing.muscleCd / iterations);
    boneCd.push_back(stats.timing.boneCd / iterations);
    response.push_back(stats.timing.response / iterations);
    output.push_back(stats.timing.output / iterations);
    measureMsPerStep.push_back(measureMs);
  }
};

/// Sets the run's cancel flag on `system` and adds the prepared scene to it.
SceneHandles addCancellableScene(MuscleSystem& system, const PreparedScene& prepared,
                                 const FibreRunOptions& options) {
  system.setCancelFlag(options.interrupt ? options.interrupt : options.cancel);
  return addScene(system, prepared);
}

/// One run of a scene through FibreMSS: the system with the scene added, each step's measures
/// and what the run collects into its metrics.
class FibreRunner {
 public:
  FibreRunner(const LoadedScene& scene, const PreparedScene& prepared,
              const FibreRunOptions& options, Clock::time_point runStart, RunMetrics& metrics)
      : scene_(scene),
        prepared_(prepared),
        options_(options),
        runStart_(runStart),
        metrics_(metrics),
        system_(scene.simulation),
        handles_(addCancellableScene(system_, prepared, options)),
        blades_(addBlades(system_, scene)),
        boneMeshes_(prepared),
        ledger_(system_, handles_.muscles, prepared, !scene.blades.empty()),
        steps_(options.steps >= 0 ? options.steps : std::max(scene.poseCount, 1)),
        frameEvery_(options.frameEvery >= 0 ? options.frameEvery : scene.outputs.frameEvery),
        boneTransforms_(handles_.bones.size(), btTransform::getIdentity()),
        surfaceDepthsMm_(handles_.muscles.size()) {
    metrics_.threads = static_cast<int>(system_.threads());
    for (const auto& bone : prepared.bones) metrics_.boneSpheres += bone->sphereCentres.size();
    for (const auto& muscle : prepared.muscles) {
      metrics_.particles += muscle->particleCount();
      metrics_.springs += muscle->springs.size();
      metrics_.boundaryParticles += muscle->boundaryParticles.size();
    }
    if (!options.outDir.empty() && frameEvery_ > 0)
      frames_ = std::make_unique<FrameWriter>(options.outDir, scene.outputs, scene.unitScale,
                                              FrameFormats{options.vtkFrames, options.gltfFrames});
  }

  /// Runs the steps until the last, a failure the policy does not go on from, or a cancel.
  void run() {
    for (int s = 0; s < steps_; ++s) {
      if (options_.cancel && options_.cancel->load()) {
        metrics_.interrupted = true;
        break;
      }
      if (!step(s)) break;
    }
    if (frames_) frames_->finish();
    if (candidateOverflows_ > 0)
      printNote("collision candidate lists overflowed " + std::to_string(candidateOverflows_) +
                " time(s): those pairs were traversed directly (same contacts, slower)");
  }

  /// The run's figures into the metrics and, when given, `details`.
  void finish(FibreRunDetails* details) {
    if (measured_) headline();
    const std::vector<MuscleHandle>& muscles = handles_.muscles;
    if (!muscles.empty() && !metrics_.nan) {
      metrics_.analytic = measureAnalytic(scene_.analytic, prepared_.muscles[0]->restSurface,
                                          system_.surface(muscles[0]));
      if (metrics_.analytic.type == "sphere-planes")
        metrics_.analytic.contact = std::move(contact_);
    }
    metrics_.muscles = std::move(ledger_.results);
    metrics_.series = std::move(ledger_.series);
    metrics_.msPerStep = median(timings_.msPerStep);
    metrics_.msPerIteration = metrics_.msPerTimeStep = median(timings_.msPerIteration);
    metrics_.timing = {medianOrZero(timings_.mss),    medianOrZero(timings_.muscleCd),
                       medianOrZero(timings_.boneCd), medianOrZero(timings_.response),
                       medianOrZero(timings_.output), medianOrZero(timings_.volumeTerm)};
    if (details) {
      *details = std::move(guard_);
      details->spherePenetration = ledger_.spherePenetration;
      details->frames = frames_ ? frames_->frames() : 0;
      details->measureMsPerStep = median(timings_.measureMsPerStep);
      if (frames_ && !frames_->implicitSurfaceMs().empty())
        details->implicitSurfaceMsPerFrame = median(std::vector<double>(
            frames_->implicitSurfaceMs().begin(), frames_->implicitSurfaceMs().end()));
    }
  }

 private:
  /// Step s: the bones to its pose, the solver's step, its measures, the guard's verdict, a
  /// soak sample, progress and a frame. Returns whether the run goes on.
  bool step(int s) {
    const int pose = poseOfStep(s, scene_.poseCount, options_.loopMotion);
    const auto stepStart = Clock::now();
    for (size_t b = 0; b < handles_.bones.size(); ++b) {
      boneTransforms_[b] = scene_.bonePose(b, pose);
      system_.setBoneTransform(handles_.bones[b], boneTransforms_[b]);
    }
    for (size_t b = 0; b < blades_.size(); ++b)
      system_.setBladeTransform(blades_[b], scene_.bladePose(b, pose));
    system_.step();
    const double stepMs = millisecondsSince(stepStart);
    const StepStats& stats = system_.lastStep();
    // Cancelled within the step: it is neither measured nor written.
    if (stats.interrupted) {
      metrics_.interrupted = true;
      return false;
    }
    simulatedTime_ += stats.simulatedTime;
    metrics_.steps = s + 1;
    metrics_.iterations += stats.iterations;
    const auto measureStart = Clock::now();
    SeriesRow where;
    where.step = s;
    where.pose = pose;
    where.poseLabel = poseLabel(scene_, pose);
    where.timeS = simulatedTime_;
    where.solverContacts = stats.contacts;
    const bool finite = measure(where, stats);
    timings_.add(stepMs, millisecondsSince(measureStart), stats);
    candidateOverflows_ += stats.candidateOverflows;
    const bool failed = judge(s, stats, finite);
    const bool goesOn =
        failed && scene_.simulation.onFailure == FailurePolicy::StopBody && finite && !stats.failed;
    sample(s, stepMs, stats, finite);
    addPoseResidual(metrics_, ledger_.poseResidual, finite, s);
    if (options_.keepPoseSurfaces) metrics_.poseSurfaces.push_back(poseSurface_);
    if (finite && !handles_.muscles.empty() && scene_.analytic.type == "sphere-planes")
      contact_.push_back(measureContact(scene_, prepared_.muscles[0]->restSurface,
                                        system_.surface(handles_.muscles[0]), pose));
    reportProgress(s, stats);
    if (failed && !goesOn) return false;
    if (frames_ && (s % frameEvery_ == 0 || s == steps_ - 1))
      frames_->write({s, pose, where.poseLabel, simulatedTime_}, system_, handles_.muscles,
                     prepared_, boneTransforms_, surfaceDepthsMm_);
    return true;
  }

  /// Measures of a step: each muscle's (and what the guard did to it), and the surface
  /// penetration into the bones of all muscles together. Returns whether all were finite.
  bool measure(const SeriesRow& where, const StepStats& stats) {
    const std::vector<MuscleHandle>& muscles = handles_.muscles;
    const bool finite = ledger_.afterStep(where, stats, boneMeshes_, boneTransforms_, guard_);
    measured_ = measured_ || finite;
    poseSurface_.clear();
    for (MuscleHandle muscle : muscles) {
      std::span<const btVector3> surface = system_.surface(muscle);
      poseSurface_.insert(poseSurface_.end(), surface.begin(), surface.end());
    }
    if (finite)
      for (size_t m = 0; m < muscles.size(); ++m) {
        std::span<const btVector3> surface = system_.surface(muscles[m]);
        surfaceDepthsMm_[m].resize(surface.size());
        penetration_ = combine(penetration_,
                               boneMeshes_.points(surface, boneTransforms_, surfaceDepthsMm_[m]));
      }
    return finite;
  }

  /// The guard's verdict on step s: a failure left in place (Report) ends the run, and so does
  /// a frozen muscle unless the policy is stop-body (then the others go on). Returns whether
  /// the step failed.
  bool judge(int s, const StepStats& stats, bool finite) {
    guard_.rolledBackSteps += stats.rolledBack ? 1 : 0;
    guard_.retries += stats.retries;
    if (stats.trappedMuscles > 0) {
      if (guard_.trappedSteps++ == 0) guard_.firstTrappedStep = s;
      guard_.trappedParticlesMax = std::max(guard_.trappedParticlesMax, stats.trappedParticles);
    }
    const bool failed = stats.failed || stats.newlyFrozen > 0 || !finite;
    if (failed) {
      metrics_.nan = metrics_.nan || !finite || stats.failedNan;
      metrics_.exploded = !metrics_.nan;
      if (metrics_.failedStep < 0) metrics_.failedStep = s;
    }
    return failed;
  }

  /// A soak sample after step s when options.sampleEvery iterations have passed since the last.
  void sample(int s, double stepMs, const StepStats& stats, bool finite) {
    sampleSolverMs_ += stepMs;
    sampleIterations_ += stats.iterations;
    if (options_.sampleEvery <= 0 || sampleIterations_ < options_.sampleEvery) return;
    SoakSample sample;
    sample.step = s + 1;
    sample.iterations = metrics_.iterations;
    sample.seconds = millisecondsSince(runStart_) / 1000.0;
    sample.msPerIteration = sampleSolverMs_ / static_cast<double>(sampleIterations_);
    sample.residentMb = statusMemoryMb("VmRSS:");
    sample.fixedDriftMm = fixedDriftMm(system_, handles_.muscles, handles_.bones);
    sample.finite = finite;
    guard_.samples.push_back(sample);
    sampleSolverMs_ = 0;
    sampleIterations_ = 0;
  }

  /// Step s's progress to the caller's callback, if any.
  void reportProgress(int s, const StepStats& stats) const {
    if (!options_.progress) return;
    RunProgress progress;
    progress.step = s + 1;
    progress.steps = steps_;
    progress.iterations = metrics_.iterations;
    progress.seconds = millisecondsSince(runStart_) / 1000.0;
    progress.lastStep = &stats;
    options_.progress(progress);
  }

  /// The headline: the steps measured before any failure, the worst muscle's figures.
  void headline() {
    metrics_.maxPenetrationMm = penetration_.maxMm;
    metrics_.meanPenetrationMm = penetration_.meanMm;
    if (const MuscleResults* worst = worstVolumeMuscle(ledger_.results))
      metrics_.volumeChangePct = worst->volumeChangePct;
    for (const MuscleResults& muscle : ledger_.results) {
      if (!(muscle.springDeviationRatio <= metrics_.springDeviationRatio))
        metrics_.springDeviationRatio = muscle.springDeviationRatio;
      if (std::isfinite(muscle.worstVolumeChangePct) &&
          !(std::abs(muscle.worstVolumeChangePct) <=
            std::abs(metrics_.worstMuscleVolumeChangePct))) {
        metrics_.worstMuscleVolumeChangePct = muscle.worstVolumeChangePct;
        metrics_.worstVolumeMuscle = muscle.name;
      }
    }
  }

  const LoadedScene& scene_;
  const PreparedScene& prepared_;
  const FibreRunOptions& options_;
  Clock::time_point runStart_;               ///< when the run started
  RunMetrics& metrics_;                      ///< what the run reports
  MuscleSystem system_;                      ///< the solver with the scene added
  SceneHandles handles_;                     ///< the scene's bones and muscles in `system_`
  std::vector<BladeHandle> blades_;          ///< the scene's blades in `system_`
  BoneMeshes boneMeshes_;                    ///< the bones' true meshes, for penetration
  MuscleLedger ledger_;                      ///< per-muscle results and series rows
  int steps_;                                ///< steps to run
  int frameEvery_;                           ///< a frame every this many steps (0: none)
  std::unique_ptr<FrameWriter> frames_;      ///< the frames' writer, when frames are written
  std::vector<btTransform> boneTransforms_;  ///< each bone's transform this step
  std::vector<std::vector<float>> surfaceDepthsMm_;  ///< per muscle, this step [mm]
  std::vector<btVector3> poseSurface_;  ///< all muscles' surface vertices this step [m]
  std::vector<ContactPose> contact_;    ///< sphere-planes: per step
  Penetration penetration_;             ///< muscle surfaces in the bones, finite steps
  StepTimings timings_;                 ///< per step
  FibreRunDetails guard_;               ///< what the numerical guard did, and the soak samples
  double simulatedTime_ = 0;            ///< [s]
  bool measured_ = false;               ///< some step's surfaces were finite
  double sampleSolverMs_ = 0;           ///< solver time since the last soak sample [ms]
  long sampleIterations_ = 0;           ///< iterations since the last soak sample
  size_t candidateOverflows_ = 0;       ///< StepStats::candidateOverflows over the run
};

}  // namespace

RunMetrics runFibreMSS(const LoadedScene& scene, const PreparedScene& prepared,
                       const FibreRunOptions& options, FibreRunDetails* details) {
  const auto runStart = Clock::now();
  RunMetrics metrics;
  metrics.scene = scene.name;
  metrics.method = options.method;
  metrics.integrator = toString(scene.simulation.integrator);
  FibreRunner runner(scene, prepared, options, runStart, metrics);
  runner.run();
  runner.finish(details);
  metrics.peakMemoryMb = statusMemoryMb("VmHWM:");
  metrics.wallSeconds = millisecondsSince(runStart) / 1000.0;
  return metrics;
}

}  // namespace fibremss
