#pragma once
// thigh13 at a low resolution stepped through its first poses, for the tests that compare whole
// runs (threads_test, reorder_test).
#include <functional>
#include <memory>
#include <vector>

#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"

namespace fibremss::testing {

/// thigh13 at resolution 8 (13 muscles that touch each other, five bones), prepared once.
inline const PreparedScene& preparedThigh(LoadedScene& scene) {
  static LoadedScene loaded = loadScene("thigh13", {"resolution=8"});
  static const PreparedScene prepared =
      prepareScene(loaded.bones, loaded.muscles, loaded.simulation.seed);
  scene = loaded;
  return prepared;
}

/// What a run left: per muscle, its particles and surface, and the last iteration's contacts.
struct StepOutcome {
  std::vector<std::vector<btVector3>> positions;  ///< per muscle after the steps
  std::vector<std::vector<btVector3>> surfaces;   ///< per muscle after the steps
  size_t contacts = 0;                            ///< contacts of the last iteration
  std::vector<std::vector<btVector3>> residuals;  ///< per muscle: residualForces after the steps
  ForceResidual residual;                         ///< forceResidual() after the steps
};

/// Two steps through the first poses, 20 iterations each, with `threads` threads: the prepared
/// bones and the given muscles; `before` (if set) sees the system and the muscles' handles
/// before the first step, `after` (if set) right after the last.
inline StepOutcome stepThroughPoses(
    const LoadedScene& scene, const PreparedScene& prepared,
    const std::vector<std::shared_ptr<const MuscleSettings>>& muscles, int threads,
    const std::function<void(MuscleSystem&, const std::vector<MuscleHandle>&)>& before = {},
    const std::function<void()>& after = {}) {
  MuscleSystemDef parameters = scene.simulation;
  parameters.threads = threads;
  parameters.stepSettings.iterations = 20;
  MuscleSystem system(parameters);
  std::vector<BoneHandle> bones;
  for (const auto& bone : prepared.bones) bones.push_back(system.addBone(bone));
  std::vector<MuscleHandle> handles;
  for (const auto& muscle : muscles) handles.push_back(system.addMuscle(muscle, bones));
  if (before) before(system, handles);
  for (int pose = 1; pose <= 2; ++pose) {
    for (size_t b = 0; b < bones.size(); ++b)
      system.setBoneTransform(bones[b], scene.bonePose(b, pose % scene.poseCount));
    system.step();
  }
  if (after) after();
  StepOutcome outcome;
  for (MuscleHandle handle : handles) {
    const auto x = system.positions(handle);
    const auto surface = system.surface(handle);
    outcome.positions.emplace_back(x.begin(), x.end());
    outcome.surfaces.emplace_back(surface.begin(), surface.end());
  }
  outcome.contacts = system.lastStep().contacts;
  outcome.residual = system.forceResidual();
  for (MuscleHandle handle : handles) {
    const auto r = system.residualForces(handle);
    outcome.residuals.emplace_back(r.begin(), r.end());
  }
  return outcome;
}

}  // namespace fibremss::testing
