#pragma once
// The strain limit (SpringParameters::strainLimit, internal): a position projection after each
// iteration's integration and after a step's last response, so that no spring of a muscle ends
// an iteration or a step longer than MuscleSettings::strainLimit times its rest length.
#include <cstddef>

#include "kernels/SpringForces.h"

namespace fibremss {

struct ContactState;
struct MuscleSettings;
struct ParticleState;

/// Shortens every spring of a muscle (its `settings`, its `particles`' positions) longer than
/// strainLimit·L0 to just inside that length (a relative 1e-5, beyond float rounding),
/// mass-weighted (the particles weigh the same: two free ends move alike, a fixed end never), in
/// passes over the springs in order (Gauss–Seidel) until one finds none beyond or `passes` have
/// run. Sequential in one muscle, allocation-free: the same
/// positions for every thread count. Returns the springs shortened (0: no spring was beyond, the
/// positions are untouched; a limit of 0 checks nothing). A particle it moves is marked in
/// `contact`'s pushedLast.
size_t limitStrain(const MuscleSettings& settings, ParticleState& particles, ContactState& contact,
                   int passes);
/// limitStrain on `kernel`'s instruction set (AVX2 tests eight springs at once; every kernel
/// gives the same positions). The other runs on fastestSpringKernel().
size_t limitStrain(const MuscleSettings& settings, ParticleState& particles, ContactState& contact,
                   int passes, SpringKernel kernel);

/// Passes of limitStrain after each integration of a muscle whose forces found a spring near the
/// limit (SpringForceResult::nearLimit; none otherwise) [passes]: one. A spring a pass leaves
/// beyond (its neighbours' projections stretched it again) is shortened in the next iteration;
/// more passes cost a pass over the springs each (8 per iteration: 1.5× real-hip's time per
/// iteration).
constexpr int kIterationStrainPasses = 1;
/// Passes of limitStrain after a step's last response [passes]: until none is beyond, but for
/// chains that cannot reach between their fixed ends within the limit.
constexpr int kEndStrainPasses = 64;

/// Σ |x − x(t−dt)| over the free `particles` [m]: an iteration's displacement after
/// the projection moved some of them.
double freeDisplacement(const ParticleState& particles);

}  // namespace fibremss
