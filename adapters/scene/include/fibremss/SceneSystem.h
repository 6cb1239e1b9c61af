#pragma once
// A loaded scene made into a simulation: prepared with its own seed and threads, its bones and
// then its muscles added to a MuscleSystem, or to a Bullet world (MuscleWorld) with each bone a
// kinematic body at the scene's first pose. The runner, the viewer and the bench build their
// systems with these.
#include <memory>
#include <span>
#include <vector>

#include "fibremss/BoneBody.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/MuscleWorld.h"
#include "fibremss/Scene.h"

namespace fibremss {

/// Prepares the scene's bones and muscles with its simulation's seed and threads.
PreparedScene prepareScene(const LoadedScene& scene);

/// The handles of a prepared scene's bones and muscles in a system, in the scene's order.
struct SceneHandles {
  std::vector<BoneHandle> bones;      ///< bone b of the scene
  std::vector<MuscleHandle> muscles;  ///< muscle m of the scene
};

/// Adds the prepared scene's muscles to `host` (a MuscleSystem or a MuscleWorld), each attached
/// to `bones` (the scene's bones' handles there), in the scene's order.
template <class Host>
std::vector<MuscleHandle> addMuscles(Host& host, const PreparedScene& prepared,
                                     std::span<const BoneHandle> bones) {
  std::vector<MuscleHandle> muscles;
  for (const auto& muscle : prepared.muscles) muscles.push_back(host.addMuscle(muscle, bones));
  return muscles;
}

/// Adds the prepared scene's bones to `system` (moved by setBoneTransform), then its muscles.
SceneHandles addScene(MuscleSystem& system, const PreparedScene& prepared);

/// Adds the scene's blades to `system` at their first pose, in the scene's order (after its
/// muscles: each blade gives them their own settings to cut).
std::vector<BladeHandle> addBlades(MuscleSystem& system, const LoadedScene& scene);

/// A prepared scene in a Bullet world: the bones' kinematic bodies and the handles.
struct WorldScene {
  std::vector<std::unique_ptr<BoneBody>> bodies;  ///< bone b's body (move it to move the bone)
  SceneHandles handles;                           ///< the bones and muscles in the world
};

/// Adds the prepared scene's bones to `world` as kinematic bodies at `scene`'s first pose, then
/// its muscles. Remove the muscles and bones from the world before the bodies go.
WorldScene addScene(MuscleWorld& world, const LoadedScene& scene, const PreparedScene& prepared);

}  // namespace fibremss
