#pragma once
// The deformed surface (method.md §7), internal.
#include <LinearMath/btTransform.h>

#include <span>

#include "fibremss/MuscleSettings.h"

namespace fibremss {

/// Each rest vertex is first moved by the weighted average of its skin particles' rigid
/// pre-transforms (blended between two bones when `blended`, else their nearest bones as in the
/// thesis), then by the weighted average displacement of those particles from their own
/// pre-transformed rest positions. `boneTransforms[b]` is the current transform of the settings'
/// bone index b; particles without a bone use the identity.
void deformSurface(const MuscleSettings& settings, std::span<const btVector3> positions,
                   std::span<const btTransform> boneTransforms, bool blended,
                   std::span<btVector3> surface);

}  // namespace fibremss
