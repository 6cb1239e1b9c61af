#pragma once
// Spring forces of one muscle (method.md §3–§4), internal.
#include <cstddef>
#include <span>

#include "MuscleState.h"

namespace fibremss {

/// What one spring-force pass measured.
struct SpringForceResult {
  double deviation = 0;      ///< Σ |l − L0| [m]
  bool exploded = false;     ///< a spring beyond 3× its rest length, or not finite
  size_t overstretched = 0;  ///< springs beyond 3× their rest length, or not finite
};

/// F = k·(l − L0)·(x_b − x_a)/l on a, the opposite on b, at `positions` into `forces`
/// (overwritten), in one pass over the springs (SSE: four springs at a time, exact square
/// roots and divisions; the force on a summed in a register along the run of springs that share
/// a). Integrators that need forces at other positions (RK, implicit) call this with their
/// buffers.
SpringForceResult springForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                               std::span<btVector3> forces);

/// The muscle's spring forces at its positions, into muscle.forces.
SpringForceResult springForces(MuscleState& muscle);

}  // namespace fibremss
