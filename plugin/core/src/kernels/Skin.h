#pragma once
// The deformed surface (method.md §7), internal.
#include <LinearMath/btMatrix3x3.h>
#include <LinearMath/btTransform.h>

#include <cstdint>
#include <span>
#include <vector>

#include "fibremss/MuscleSettings.h"
#include "fibremss/Parameters.h"

namespace fibremss {

/// Local frames of the particles that move the surface: the deformation of each one's spring
/// neighbourhood, so that the surface turns and stretches with the material, not with a blend of
/// bone rotations (which averages a 180° twist to nothing and keeps the layer between the
/// particles and the surface rigid under stretch). Sized by prepareSkinFrames.
struct SkinFrames {
  std::vector<uint8_t> used;             ///< per particle: 1 when a surface vertex binds it
  std::vector<btMatrix3x3> restInverse;  ///< per used particle: (Σ dX·dXᵀ)⁻¹ at rest [1/m²]
  std::vector<uint8_t> hasFrame;         ///< per particle: its neighbours span space at rest
  std::vector<btMatrix3x3> moments;      ///< scratch per particle: Σ dx·dXᵀ [m²]
  std::vector<btMatrix3x3> deformations;  ///< scratch per particle: its local F [1]
  /// Per surface vertex, after measureLayer: its distance from the nearest particle it binds
  /// [m]. A vertex lies at most this deep in a bone that particle is outside of: the
  /// surface-contact stage looks no deeper.
  std::vector<btScalar> layer;
};

/// Sizes `frames` for `settings` and fills used, restInverse and hasFrame (over the particle's
/// springs: dX = X_b − X_a at rest).
void prepareSkinFrames(const MuscleSettings& settings, SkinFrames& frames);

/// Each rest vertex v bound to particles p with weights w becomes Σ w·(x_p + F_p·(v − p)), F_p
/// the least-squares deformation gradient of p's spring neighbourhood, (Σ dx·dXᵀ)(Σ dX·dXᵀ)⁻¹. A
/// particle whose neighbours do not span space, or whose F is inverted, turns by its rigid
/// pre-transform's rotation instead (blended between two bones by `blend` when `blended`, else
/// its nearest bone's). `boneTransforms[b]` is the current transform of the settings' bone index b;
/// particles without a bone use the identity.
void deformSurface(const MuscleSettings& settings, std::span<const btVector3> positions,
                   std::span<const btTransform> boneTransforms, bool blended,
                   PretransformBlend blend, SkinFrames& frames, std::span<btVector3> surface);

/// Vertex v of deformSurface's surface from the particles' `deformations` (F_p, indexed by
/// particle; only v's particles are read).
btVector3 skinnedVertex(const MuscleSettings& settings, std::span<const btVector3> positions,
                        std::span<const btMatrix3x3> deformations, size_t v);

/// F_p of particle i as deformSurface takes it, from the settings' springs `springs` (the
/// indices of those with an end at i, in the springs' order; a broken spring, a == b, adds
/// nothing), with `frames` from prepareSkinFrames.
btMatrix3x3 particleDeformation(const MuscleSettings& settings,
                                std::span<const btVector3> positions,
                                std::span<const btTransform> boneTransforms, bool blended,
                                PretransformBlend blend, const SkinFrames& frames, uint32_t i,
                                std::span<const uint32_t> springs);

/// frames.layer from the deformed `surface` (deformSurface's) and the particles it binds; only
/// the surface-contact stage reads it.
void measureLayer(const MuscleSettings& settings, std::span<const btVector3> positions,
                  std::span<const btVector3> surface, SkinFrames& frames);

}  // namespace fibremss
