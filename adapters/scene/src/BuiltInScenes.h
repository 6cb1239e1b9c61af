#pragma once
// The built-in procedural scenes as JSON definitions (generators, not meshes), so that
// `fibremss scenes --export NAME` gives a file that regenerates the same scene.
#include <string>

namespace fibremss {

/// The JSON text a built-in scene is defined by (defaults not yet filled in: loadScene() does
/// that). Empty when `name` is not a built-in scene. Lengths are in millimetres.
std::string builtInSceneDefinition(const std::string& name);

}  // namespace fibremss
