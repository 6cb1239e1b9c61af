#pragma once
// The volume-preservation term of a muscle (issue 18), internal: a pressure on the skinned
// surface against the deviation of the volume it encloses from the rest volume.
#include <span>

#include "MuscleState.h"

namespace fibremss {

/// True when the muscle has a volume term (settings.volumeModulus > 0 and a skinned surface).
bool hasVolumeTerm(const MuscleSettings& settings);

/// The surface offsets of the skin (Skin.h) at the muscle's bone transforms: each vertex's
/// Σ w·R(v − p) over its skin particles, so that the skinned surface is offsets + Σ w·x.
/// Called when the bones moved; every other iteration reuses them.
void updateVolumeOffsets(MuscleState& muscle, bool blended);

/// Adds the volume term's forces at `positions` into `forces`: with the skinned surface s(x) =
/// offsets + Σ w·x, its enclosed volume V and the rest volume V0, the energy
/// ½·K·(V − V0)²/|V0| (K = settings.volumeModulus) gives each surface vertex the force
/// K·(V0 − V)/|V0| · ∂V/∂s (a third of its area-weighted normal), spread over its skin particles
/// by their weights. Returns V [m³]. Uses muscle.volumeSurface and volumeGradient as scratch.
double addVolumeForces(MuscleState& muscle, std::span<const btVector3> positions,
                       std::span<btVector3> forces);

}  // namespace fibremss
