#pragma once
// A muscle's part of the contact state for the surface push (MuscleSystemDef::surfacePush,
// collision/SurfacePush.h), internal: empty when off. Sized once when the muscle is added.
#include <LinearMath/btMatrix3x3.h>
#include <LinearMath/btVector3.h>

#include <cstdint>
#include <vector>

#include "fibremss/Parameters.h"

namespace fibremss {

/// The surface vertices each particle moves, the springs its local frame is fitted over, and the
/// scratch of one bone's surface push.
struct SurfacePushState {
  /// Per particle + 1: where its vertices start in particleVertices.
  std::vector<uint32_t> vertexOffsets;
  std::vector<uint32_t> particleVertices;  ///< surface vertices that bind each particle
  /// Per particle + 1: where its springs start in particleSprings.
  std::vector<uint32_t> springOffsets;
  std::vector<uint32_t> particleSprings;  ///< springs with an end at each particle, in order
  bool blended = true;                    ///< MuscleSystemDef::blendedPretransform
  PretransformBlend blend = PretransformBlend::Linear;  ///< MuscleSystemDef::pretransformBlend

  /// Particles the bone spheres found near the bone of the running bone visit, in the order
  /// found (capacity: every particle).
  std::vector<uint32_t> found;
  size_t foundCount = 0;  ///< entries of `found` in use
  /// Per particle, valid while it is in `found`: its centre's distance from the bone's mesh (0
  /// inside) [m]; nothing of the mesh lies nearer.
  std::vector<btScalar> clearances;
  std::vector<uint32_t> vertexVisits;     ///< per vertex: the bone visit that last tested it
  std::vector<uint32_t> frameVisits;      ///< per particle: the bone visit of `deformations`
  std::vector<btMatrix3x3> deformations;  ///< per particle: its F in that visit [1]
  std::vector<btVector3> spread;          ///< per particle: Σ w·push of the visit [m]
  std::vector<btScalar> spreadWeights;    ///< per particle: Σ w of the visit [1]
  std::vector<uint32_t> spreadParticles;  ///< particles with a spread push, in order
  size_t spreadCount = 0;                 ///< entries of spreadParticles in use

  /// Whether the muscle pushes its surface (sized by prepareSurfacePush).
  bool enabled() const { return !vertexVisits.empty(); }
};

}  // namespace fibremss
