#pragma once
// Internal to the scene loader: the top-level "tool" object, a sphere posed by a script at
// haptic rate.
#include "SceneFields.h"
#include "fibremss/Scene.h"

namespace fibremss::scene {

/// Reads `tool` (lengths in scene units, times in ms) into SI; InputError for waypoints whose
/// times do not increase from 0.
ToolScript readTool(Fields& tool, double scale);

}  // namespace fibremss::scene
