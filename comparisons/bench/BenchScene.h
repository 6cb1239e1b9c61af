#pragma once
// The scene the kernel benchmarks run on: thigh13 prepared at one resolution, added to a
// MuscleSystem and stepped into contact, with the step's parts callable one at a time on one
// thread (the kernels), in the order an iteration runs them.
#include <memory>

#include "fibremss/MuscleSystem.h"
#include "fibremss/Scene.h"
#include "solver/MuscleSystemAccess.h"

namespace fibremss::bench {

/// The parts of one iteration, in order (method.md §5).
enum class Part {
  SpringForces,       ///< spring forces of every muscle
  VolumeForces,       ///< the volume terms' forces of every muscle
  AdaptiveTimeStep,   ///< the adaptive dt bound of every muscle (eq 5.1), and the dt
  Integration,        ///< the integrator's advance of every muscle
  TreeRefit,          ///< refitTree of every muscle (a refit only past the skin)
  MuscleMusclePairs,  ///< collideMusclePairs: pairs whose bounds meet, then each muscle's pushes
  MuscleBonePairs,    ///< every muscle against every bone (lists while they hold)
  Response,           ///< pushes applied to every muscle
};
constexpr Part kParts[] = {Part::SpringForces,    Part::VolumeForces, Part::AdaptiveTimeStep,
                           Part::Integration,     Part::TreeRefit,    Part::MuscleMusclePairs,
                           Part::MuscleBonePairs, Part::Response};

/// Name of a part as benchmarks and the callgrind reference print it.
const char* partName(Part part);

/// thigh13 at `resolution` with `threads` solver threads and `integrator` (the kernels' reference
/// counts are Verlet's), stepped to its second pose so that the muscles touch each other and the
/// bones.
class BenchScene {
 public:
  BenchScene(int resolution, int threads, Integrator integrator = Integrator::Verlet);

  MuscleSystem& system() { return *system_; }
  /// Particles of all muscles.
  size_t particles() const { return particles_; }
  /// Steps of exactly `iterations` iterations from the next on (StopRule::Iterations).
  void countIterations(int iterations);
  /// One step towards the other of the first two poses (bones move in every step).
  void stepPose();
  /// One part of an iteration over every muscle, on the calling thread.
  void run(Part part);

 private:
  LoadedScene scene_;                         ///< the loaded scene
  std::unique_ptr<MuscleSystem> system_;      ///< the prepared system
  std::vector<BoneHandle> bones_;             ///< bone handles, scene order
  MuscleSystemAccess::Impl* impl_ = nullptr;  ///< the system's private state
  size_t particles_ = 0;                      ///< particles of all muscles
  int pose_ = 0;                              ///< pose of the last stepPose()
  btScalar dt_ = 0;                           ///< dt of the last AdaptiveTimeStep part
};

}  // namespace fibremss::bench
