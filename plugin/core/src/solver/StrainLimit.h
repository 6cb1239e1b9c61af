#pragma once
// The strain limit (SpringParameters::strainLimit, internal): a position projection after each
// iteration's integration and after a step's last response, so that no spring of a muscle ends
// an iteration or a step longer than MuscleSettings::strainLimit times its rest length.
#include <cstddef>

namespace fibremss {

struct MuscleState;

/// Shortens every spring of `muscle` longer than strainLimit·L0 to just inside that length (a
/// relative 1e-5, beyond float rounding), mass-weighted (the particles weigh the same: two free
/// ends move alike, a fixed end never), in passes over the springs in order (Gauss–Seidel) until
/// one finds none beyond or kStrainLimitPasses have run. Sequential in one muscle, allocation-free:
/// the same positions for every thread count. Returns the springs shortened (0: no spring was
/// beyond, the positions are untouched; a limit of 0 checks nothing).
size_t limitStrain(MuscleState& muscle);

/// Most passes limitStrain makes in one call [passes]. A spring it leaves beyond (a chain that
/// cannot reach between its fixed ends within the limit) is shortened again in the next call.
constexpr int kStrainLimitPasses = 8;

/// Σ |x − x(t−dt)| over the free particles of `muscle` [m]: an iteration's displacement after
/// the projection moved some of them.
double freeDisplacement(const MuscleState& muscle);

}  // namespace fibremss
