#include "fibremss/SceneSystem.h"

namespace fibremss {

PreparedScene prepareScene(const LoadedScene& scene) {
  return prepareScene(scene.bones, scene.muscles, scene.simulation.seed, scene.simulation.threads);
}

SceneHandles addScene(MuscleSystem& system, const PreparedScene& prepared) {
  SceneHandles handles;
  for (const auto& bone : prepared.bones) handles.bones.push_back(system.addBone(bone));
  handles.muscles = addMuscles(system, prepared, handles.bones);
  return handles;
}

std::vector<BladeHandle> addBlades(MuscleSystem& system, const LoadedScene& scene) {
  std::vector<BladeHandle> blades;
  for (size_t b = 0; b < scene.blades.size(); ++b)
    blades.push_back(
        system.addBlade(scene.blades[b].from, scene.blades[b].to, scene.bladePose(b, 0)));
  return blades;
}

WorldScene addScene(MuscleWorld& world, const LoadedScene& scene, const PreparedScene& prepared) {
  WorldScene added;
  for (size_t b = 0; b < prepared.bones.size(); ++b) {
    added.bodies.push_back(std::make_unique<BoneBody>(prepared.bones[b], scene.bonePose(b, 0)));
    added.handles.bones.push_back(world.addBone(prepared.bones[b], added.bodies.back()->body()));
  }
  added.handles.muscles = addMuscles(world, prepared, added.handles.bones);
  return added;
}

}  // namespace fibremss
