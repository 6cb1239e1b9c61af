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
#include "fibremss/Output.h"

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

bool allFinite(std::span<const btVector3> points) {
  return std::all_of(points.begin(), points.end(), [](const btVector3& p) {
    return std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z());
  });
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

  /// Points (surface vertices) inside the bones placed at `transforms`; `depthsMm` (one per
  /// point) receives each one's depth [mm].
  Penetration points(std::span<const btVector3> points, std::span<const btTransform> transforms,
                     std::span<float> depthsMm) const {
    return measurePenetration(points, pointers_, transforms, depthsMm);
  }

  /// Free boundary particles' spheres in the bones: max(0, r − signed distance of the centre)
  /// (fixed particles sit on their bones by design and are left out).
  Penetration spheres(const MuscleSettings& muscle, std::span<const btVector3> positions,
                      std::span<const btTransform> transforms) {
    for (size_t b = 0; b < transforms.size(); ++b) inverses_[b] = transforms[b].inverse();
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
        depth = std::max(depth, radius - distances_[b].signedDistance(local));
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

}  // namespace

RunMetrics runFibreMSS(const LoadedScene& scene, const PreparedScene& prepared,
                       const FibreRunOptions& options, FibreRunDetails* details) {
  const auto runStart = Clock::now();
  RunMetrics metrics;
  metrics.scene = scene.name;
  metrics.method = options.method;
  metrics.integrator = toString(scene.simulation.integrator);

  MuscleSystem system(scene.simulation);
  metrics.threads = static_cast<int>(system.threads());
  std::vector<BoneHandle> bones;
  for (const auto& bone : prepared.bones) {
    bones.push_back(system.addBone(bone));
    metrics.boneSpheres += bone->sphereCentres.size();
  }
  BoneMeshes boneMeshes(prepared);
  std::vector<MuscleHandle> muscles;
  double restVolume = 0, restLengthSum = 0;
  std::vector<double> muscleRestVolumes, muscleRestLengths;
  for (const auto& muscle : prepared.muscles) {
    muscles.push_back(system.addMuscle(muscle, bones));
    metrics.particles += muscle->particleCount();
    metrics.springs += muscle->springs.size();
    metrics.boundaryParticles += muscle->boundaryParticles.size();
    muscleRestVolumes.push_back(muscle->restSurface.empty() ? 0.0
                                                            : meshVolume(muscle->restSurface));
    restVolume += muscleRestVolumes.back();
    double lengths = 0;
    for (const Spring& spring : muscle->springs) lengths += spring.restLength;
    muscleRestLengths.push_back(lengths);
    restLengthSum += lengths;
  }

  const int steps = options.steps >= 0 ? options.steps : std::max(scene.poseCount, 1);
  const int frameEvery = options.frameEvery >= 0 ? options.frameEvery : scene.outputs.frameEvery;
  std::unique_ptr<FrameWriter> frames;
  if (!options.outDir.empty() && frameEvery > 0)
    frames = std::make_unique<FrameWriter>(options.outDir, scene.outputs, scene.unitScale);

  std::vector<btTransform> boneTransforms(bones.size(), btTransform::getIdentity());
  std::vector<double> msPerStep, msPerIteration, mss, volumeTerm, muscleCd, boneCd, response,
      output, measureMsPerStep;
  Penetration penetration, spherePenetration;
  std::vector<btVector3> poseSurface;
  std::vector<std::vector<float>> surfaceDepthsMm(muscles.size());  // per muscle, this step
  double simulatedTime = 0;                                         // [s]
  FibreRunDetails guard;  // what the numerical guard did, and the soak samples
  std::vector<bool> reportedFrozen(muscles.size(), false);
  double sampleSolverMs = 0;
  size_t candidateOverflows = 0;  // StepStats::candidateOverflows over the run
  long sampleIterations = 0;
  for (int s = 0; s < steps; ++s) {
    if (options.cancel && options.cancel->load()) {
      metrics.interrupted = true;
      break;
    }
    const int pose = poseOfStep(s, scene.poseCount, options.loopMotion);
    const auto stepStart = Clock::now();
    for (size_t b = 0; b < bones.size(); ++b) {
      boneTransforms[b] = scene.bonePose(b, pose);
      system.setBoneTransform(bones[b], boneTransforms[b]);
    }
    system.step();
    const double stepMs = millisecondsSince(stepStart);
    const StepStats& stats = system.lastStep();
    simulatedTime += stats.simulatedTime;
    metrics.steps = s + 1;
    metrics.iterations += stats.iterations;

    // Measures of this step: surface penetration into the bones, and at the last step the
    // volume change and spring deviation of all muscles together.
    const auto measureStart = Clock::now();
    bool finite = true;
    poseSurface.clear();
    for (MuscleHandle muscle : muscles) {
      std::span<const btVector3> surface = system.surface(muscle);
      finite = finite && allFinite(surface) && allFinite(system.positions(muscle));
      poseSurface.insert(poseSurface.end(), surface.begin(), surface.end());
    }
    if (finite)
      for (size_t m = 0; m < muscles.size(); ++m) {
        std::span<const btVector3> surface = system.surface(muscles[m]);
        if (muscleRestVolumes[m] != 0) {
          const double change = volumeChangePercent(prepared.muscles[m]->restSurface, surface);
          if (!(std::abs(change) <= std::abs(metrics.worstMuscleVolumeChangePct))) {
            metrics.worstMuscleVolumeChangePct = change;
            metrics.worstVolumeMuscle = prepared.muscles[m]->name;
          }
        }
        surfaceDepthsMm[m].resize(surface.size());
        penetration =
            combine(penetration, boneMeshes.points(surface, boneTransforms, surfaceDepthsMm[m]));
        spherePenetration = combine(
            spherePenetration, boneMeshes.spheres(system.settings(muscles[m]),
                                                  system.positions(muscles[m]), boneTransforms));
      }
    const double measureMs = millisecondsSince(measureStart);

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

    candidateOverflows += stats.candidateOverflows;
    // The guard's verdict: a frozen muscle or a failure left in place (Report) ends the run.
    guard.rolledBackSteps += stats.rolledBack ? 1 : 0;
    guard.retries += stats.retries;
    if (stats.trappedMuscles > 0) {
      if (guard.trappedSteps++ == 0) guard.firstTrappedStep = s;
      guard.trappedParticlesMax = std::max(guard.trappedParticlesMax, stats.trappedParticles);
    }
    for (size_t m = 0; stats.newlyFrozen > 0 && m < muscles.size(); ++m)
      if (system.frozen(muscles[m]) && !reportedFrozen[m]) {
        reportedFrozen[m] = true;
        const bool blamed = muscles[m].index == stats.failedMuscle.index &&
                            muscles[m].generation == stats.failedMuscle.generation;
        guard.frozen.push_back({system.settings(muscles[m]).name, s, blamed && stats.failedNan});
      }
    const bool failed = stats.failed || stats.newlyFrozen > 0;
    metrics.nan = !finite || (failed && stats.failedNan);
    metrics.exploded = failed && !metrics.nan;

    sampleSolverMs += stepMs;
    sampleIterations += stats.iterations;
    if (options.sampleEvery > 0 && sampleIterations >= options.sampleEvery) {
      SoakSample sample;
      sample.step = s + 1;
      sample.iterations = metrics.iterations;
      sample.seconds = millisecondsSince(runStart) / 1000.0;
      sample.msPerIteration = sampleSolverMs / static_cast<double>(sampleIterations);
      sample.residentMb = statusMemoryMb("VmRSS:");
      sample.fixedDriftMm = fixedDriftMm(system, muscles, bones);
      sample.finite = finite;
      guard.samples.push_back(sample);
      sampleSolverMs = 0;
      sampleIterations = 0;
    }
    if (options.keepPoseSurfaces) metrics.poseSurfaces.push_back(poseSurface);
    if (options.progress) {
      RunProgress progress;
      progress.step = s + 1;
      progress.steps = steps;
      progress.iterations = metrics.iterations;
      progress.seconds = millisecondsSince(runStart) / 1000.0;
      progress.lastStep = &stats;
      options.progress(progress);
    }
    if (metrics.nan || metrics.exploded) {
      metrics.failedStep = s;
      break;
    }
    if (frames && (s % frameEvery == 0 || s == steps - 1))
      frames->write({s, pose, poseLabel(scene, pose), simulatedTime}, system, muscles, prepared,
                    boneTransforms, surfaceDepthsMm);
  }
  if (candidateOverflows > 0)
    std::fprintf(stderr,
                 "note: collision candidate lists overflowed %zu time(s): those pairs were "
                 "traversed directly (same contacts, slower)\n",
                 candidateOverflows);

  if (metrics.steps > 0 && !metrics.nan) {
    metrics.maxPenetrationMm = penetration.maxMm;
    metrics.meanPenetrationMm = penetration.meanMm;
    double volumeChange = 0, deviation = 0;
    for (size_t m = 0; m < muscles.size(); ++m) {
      const MuscleSettings& muscle = *prepared.muscles[m];
      if (muscleRestVolumes[m] != 0)
        volumeChange += muscleRestVolumes[m] *
                        volumeChangePercent(muscle.restSurface, system.surface(muscles[m]));
      if (muscleRestLengths[m] != 0)
        deviation += muscleRestLengths[m] *
                     springDeviationRatio(muscle.springs, system.positions(muscles[m]));
    }
    if (restVolume != 0) metrics.volumeChangePct = volumeChange / restVolume;
    if (!muscles.empty())
      metrics.analytic = measureAnalytic(scene.analytic, prepared.muscles[0]->restSurface,
                                         system.surface(muscles[0]));
    if (restLengthSum != 0) metrics.springDeviationRatio = deviation / restLengthSum;
  }
  metrics.msPerStep = median(msPerStep);
  metrics.msPerIteration = metrics.msPerTimeStep = median(msPerIteration);
  metrics.timing = {medianOrZero(mss),      medianOrZero(muscleCd), medianOrZero(boneCd),
                    medianOrZero(response), medianOrZero(output),   medianOrZero(volumeTerm)};
  if (details) {
    *details = std::move(guard);
    details->spherePenetration = spherePenetration;
    details->frames = frames ? frames->frames() : 0;
    details->measureMsPerStep = median(measureMsPerStep);
  }
  metrics.peakMemoryMb = statusMemoryMb("VmHWM:");
  metrics.wallSeconds = millisecondsSince(runStart) / 1000.0;
  return metrics;
}

}  // namespace fibremss
