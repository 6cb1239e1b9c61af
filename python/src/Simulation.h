#pragma once
// A scene prepared into a MuscleSystem that Python steps: its bones follow the scene's poses or
// transforms set from Python, and its muscles are measured as `fibremss run` measures them.
#include <optional>
#include <vector>

#include "fibremss/Geometry.h"
#include "fibremss/MuscleMetrics.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"

namespace fibremss::python {

class Simulation {
 public:
  /// Prepares `scene` and adds its bones (at rest) and muscles to a MuscleSystem; `threads`
  /// replaces the scene's simulation.threads when given. InputError for unusable input.
  Simulation(LoadedScene scene, std::optional<int> threads);

  const LoadedScene& scene() const { return scene_; }
  MuscleSystem& system() { return system_; }
  const MuscleSystem& system() const { return system_; }
  const std::vector<MuscleHandle>& muscles() const { return muscles_; }
  const std::vector<BoneHandle>& bones() const { return bones_; }

  /// Every bone's target for the next step: the scene's transform at `pose` (IndexError
  /// beyond the scene's poses).
  void setPose(int pose);
  /// One step (`duration` [s]: MuscleSystem::step(duration), else a pose step); returns its
  /// statistics and adds its simulated time to time().
  const StepStats& step(std::optional<double> duration);
  double time() const { return time_; }  ///< simulated time of every step so far [s]
  int steps() const { return steps_; }   ///< steps so far

  /// Every muscle measured now as `fibremss run` measures it after a step (its series row: the
  /// surface against the bones' true meshes, and the force residual of all muscles together).
  std::vector<SeriesRow> measure();

 private:
  LoadedScene scene_;
  PreparedScene prepared_;
  MuscleSystem system_;
  std::vector<BoneHandle> bones_;
  std::vector<MuscleHandle> muscles_;
  std::vector<MeshDistance> boneMeshes_;  ///< the bones' true meshes, rest frames
  int pose_ = 0;                          ///< the scene pose the bones were last set to
  double time_ = 0;
  int steps_ = 0;
};

}  // namespace fibremss::python
