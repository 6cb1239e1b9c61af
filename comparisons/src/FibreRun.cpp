#include "fibremss/FibreRun.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <span>
#include <string>
#include <vector>

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

/// A name usable in a file name: letters, digits, '-' and '_' kept, anything else '_'.
std::string fileSafe(const std::string& name) {
  std::string safe = name.empty() ? "unnamed" : name;
  for (char& c : safe)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') c = '_';
  return safe;
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

  /// Points (surface vertices) inside the bones placed at `transforms`.
  Penetration points(std::span<const btVector3> points,
                     std::span<const btTransform> transforms) const {
    return measurePenetration(points, pointers_, transforms);
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

/// Writes the frames of a run: per muscle its deformed surface and its particles (with radius,
/// flags and fibres), per bone its mesh where it is, and run.pvd listing them all.
class FrameWriter {
 public:
  FrameWriter(const std::string& outDir, const OutputSettings& settings)
      : outDir_(outDir), settings_(settings) {}

  void write(int step, const MuscleSystem& system, std::span<const MuscleHandle> muscles,
             const PreparedScene& prepared, std::span<const btTransform> boneTransforms) {
    char number[16];
    std::snprintf(number, sizeof number, "%05d", step);
    int part = 0;
    for (size_t m = 0; m < muscles.size(); ++m) {
      const MuscleSettings& muscle = system.settings(muscles[m]);
      const std::string stem = "frames/muscle" + std::to_string(m) + "_" + fileSafe(muscle.name);
      if (settings_.writeSurfaces && !muscle.restSurface.empty()) {
        PolyData surface;
        std::span<const btVector3> vertices = system.surface(muscles[m]);
        surface.points.assign(vertices.begin(), vertices.end());
        surface.triangles = muscle.restSurface.triangles;
        add(step, stem + "_surface_" + number + ".vtp", surface, part);
      }
      ++part;
      if (settings_.writeParticles || settings_.writeFibres) {
        add(step, stem + "_particles_" + number + ".vtp", particles(system, muscles[m], muscle),
            part);
      }
      ++part;
    }
    for (size_t b = 0; b < prepared.bones.size(); ++b) {
      const BoneSettings& bone = *prepared.bones[b];
      PolyData mesh;
      mesh.points = transformed(bone.mesh, boneTransforms[b]).vertices;
      mesh.triangles = bone.mesh.triangles;
      add(step,
          "frames/bone" + std::to_string(b) + "_" + fileSafe(bone.name) + "_" + number + ".vtp",
          mesh, part++);
    }
    pvd_.write(outDir_ + "/run.pvd");
    ++frames_;
  }

  int frames() const { return frames_; }

 private:
  PolyData particles(const MuscleSystem& system, MuscleHandle handle,
                     const MuscleSettings& muscle) const {
    PolyData data;
    std::span<const btVector3> positions = system.positions(handle);
    data.points.assign(positions.begin(), positions.end());
    data.pointsAsVertices = settings_.writeParticles;
    if (settings_.writeFibres) {
      data.lineIndices = muscle.fibreParticles;
      data.lineOffsets = muscle.fibreOffsets;
    }
    std::vector<float> radius(muscle.particleCount()), fixed(muscle.particleCount()),
        boundary(muscle.particleCount());
    for (uint32_t i = 0; i < muscle.particleCount(); ++i) {
      radius[i] = static_cast<float>(muscle.radii[i]);
      fixed[i] = muscle.isFixed(i) ? 1.0f : 0.0f;
      boundary[i] = muscle.isBoundary(i) ? 1.0f : 0.0f;
    }
    data.pointScalars = {{"radius", std::move(radius)},
                         {"fixed", std::move(fixed)},
                         {"boundary", std::move(boundary)}};
    return data;
  }

  void add(int step, const std::string& file, const PolyData& data, int part) {
    writeVtp(outDir_ + "/" + file, data);
    pvd_.add(step, file, part);
  }

  std::string outDir_;
  const OutputSettings& settings_;
  PvdCollection pvd_;
  int frames_ = 0;
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
    frames = std::make_unique<FrameWriter>(options.outDir, scene.outputs);

  std::vector<btTransform> boneTransforms(bones.size(), btTransform::getIdentity());
  std::vector<double> msPerStep, msPerIteration, mss, volumeTerm, muscleCd, boneCd, response,
      output, measureMsPerStep;
  Penetration penetration, spherePenetration;
  std::vector<btVector3> poseSurface;
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
    if (finite) {
      for (size_t m = 0; m < muscles.size(); ++m) {
        if (muscleRestVolumes[m] == 0) continue;
        const double change =
            volumeChangePercent(prepared.muscles[m]->restSurface, system.surface(muscles[m]));
        if (!(std::abs(change) <= std::abs(metrics.worstMuscleVolumeChangePct))) {
          metrics.worstMuscleVolumeChangePct = change;
          metrics.worstVolumeMuscle = prepared.muscles[m]->name;
        }
      }
      penetration = combine(penetration, boneMeshes.points(poseSurface, boneTransforms));
      for (MuscleHandle muscle : muscles)
        spherePenetration = combine(
            spherePenetration,
            boneMeshes.spheres(system.settings(muscle), system.positions(muscle), boneTransforms));
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
      frames->write(s, system, muscles, prepared, boneTransforms);
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
