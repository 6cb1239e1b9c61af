#pragma once
// The deformed surface (method.md §7), internal.
#include <LinearMath/btTransform.h>

#include <span>

#include "fibremss/MuscleSettings.h"

namespace fibremss {

/// Each rest vertex is first moved by the weighted average of its skin particles' nearest-bone
/// transforms (the rigid pre-transform), then by the weighted average displacement of those
/// particles from their own pre-transformed rest positions. `boneTransforms[b]` is the current
/// transform of the settings' bone index b; particles without a nearest bone use the identity.
void deformSurface(const MuscleSettings& settings, std::span<const btVector3> positions,
                   std::span<const btTransform> boneTransforms, std::span<btVector3> surface);

}  // namespace fibremss
