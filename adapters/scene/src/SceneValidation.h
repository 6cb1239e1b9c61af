#pragma once
// Scene-wide checks on the raw JSON (after overrides, before reading): things the field
// readers cannot see one field at a time.
#include <string>

#include "SceneFields.h"

namespace fibremss::scene {

/// Throws InputError naming the field for transforms that are not rigid: quaternions that
/// are not of unit length (a scale in disguise) and scale, shear or matrix entries.
void validateSceneJson(const Json& raw, const std::string& source);

}  // namespace fibremss::scene
