#pragma once
// The adaptive time step (method.md §4, thesis eq 5.1), internal.
#include <LinearMath/btScalar.h>

#include "kernels/SpringForces.h"
#include "state/MuscleState.h"

namespace fibremss {

/// The largest dt ≥ 0 with |F|·dt² − c·|Δx|·dt + m·(|Δx| − r) ≤ 0 (thesis eq 5.1: no particle
/// moves farther than r in one Verlet iteration), where |Δx| = speed·dt is the displacement the
/// particle makes over this dt at its current speed: (|F| − c·v)·dt² + m·v·dt − m·r ≤ 0. With a
/// fixed dt this is eq 5.1 as printed; written with the speed it stays right when dt changes.
/// `centredDamping` (Verlet's centred damping term, γ = c·dt/(2m)): the bound of its step
/// (1 + γ)·|Δx| ≤ (1 − γ)·v·dt + |F|·dt²/m, i.e. (|F| − c·v/2)·dt² + (m·v − c·r/2)·dt − m·r ≤ 0.
/// Infinity when every dt satisfies it.
btScalar largestSafeTimeStep(btScalar force, btScalar speed, btScalar radius, btScalar mass,
                             btScalar damping, bool centredDamping);

/// The minimum of largestSafeTimeStep over the free particles of a muscle, r being a particle's
/// radius (boundary) or the muscle's mean radius (inner particles, which never collide but
/// should not outrun their neighbours either), speed = |x − x_prev| / previousDt, with centred
/// damping when `centred` (the muscle is prepared for Verlet); also capped by the muscle's
/// stability bound (ParticleState::stableTimeStep). Float builds with SSE2 take four particles at
/// a time (AVX2: eight), each bound bit for bit the scalar one, so every kernel gives the same
/// dt. Runs on the spring kernel's instruction set (fastestSpringKernel).
btScalar adaptiveTimeStep(const MuscleSettings& settings, const ParticleState& particles,
                          bool centred, btScalar previousDt);

/// adaptiveTimeStep on the instruction set of `kernel`, which must be available (tests compare).
btScalar adaptiveTimeStep(const MuscleSettings& settings, const ParticleState& particles,
                          bool centred, btScalar previousDt, SpringKernel kernel);

/// The largest dt for which `kind` is stable for every particle of the settings, times a safety
/// factor. The spring stiffness is bounded by Gershgorin (eigenvalues ω² of K/m in [0, 2·Σk/m]);
/// each mode s² + (c/m)·s + ω² = 0 must map inside the integrator's stability region. Verlet
/// with centred damping: λ·dt² < 4 whatever c; semi-implicit Euler: λ·dt² + 2(c/m)·dt < 4.
/// Explicit Euler, RK2, RK4: |R(dt·s)| ≤ 1 with R their stability polynomial, found by bisection
/// over sampled ω². Implicit and position-based integrators: infinity (eq 5.1 alone bounds their
/// dt). Eq 5.1 alone does not bound the oscillation of stiff springs.
btScalar stableTimeStep(const MuscleSettings& settings, Integrator kind = Integrator::Verlet);

}  // namespace fibremss
