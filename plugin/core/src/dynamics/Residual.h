#pragma once
// The force residual of a muscle (MuscleSystem::forceResidual), internal: the model's net force
// on each free particle at its current position, a contact's share taken out, and its size as a
// force and as an equivalent displacement.
#include <LinearMath/btVector3.h>

#include <cstddef>
#include <cstdint>
#include <vector>

#include "fibremss/MuscleSettings.h"
#include "fibremss/MuscleSystem.h"
#include "kernels/SpringForces.h"

namespace fibremss {

struct ContactState;
struct InteractionState;
struct ParticleState;
struct ResidualState;

/// k_i of every particle [N/m]: a third of the trace of its 3×3 diagonal block of the energy's
/// Hessian at rest, i.e. Σ k/3 of its springs plus K/(3·V0)·|∂V/∂x_i|² of each volume term it is
/// in (the tetrahedra's with their G0/G factor at rest, and the enclosed volume's). 0 for a
/// particle in no term. Allocates (made once when the muscle is added).
std::vector<btScalar> residualStiffness(const MuscleSettings& settings);

/// Sums over particles that combine across muscles in a fixed order.
struct ResidualSums {
  double forceSquares = 0;         ///< Σ |r_i|² [N²]
  double displacementSquares = 0;  ///< Σ (|r_i|/k_i)² [m²]
  double maxForce = 0;             ///< largest |r_i| [N]
  double maxDisplacement = 0;      ///< largest |r_i|/k_i [m]
  size_t particles = 0;            ///< free particles
  size_t contactParticles = 0;     ///< of them pushed by the last response

  void add(const ResidualSums& other);  ///< `other`'s particles counted too
  ForceResidual summary() const;        ///< RMS and maxima
};

/// Keeps the pushes the next applyPushes applies for the force residual (lastPushes, stamped
/// with that response's contactRound in pushRounds; a pinched particle's as the pairs summed
/// them; the bones' share of it in lastBonePushes). The step's last response calls it; the
/// iterations' responses do not, unless the integrator holds contacts.
void recordPushes(const MuscleSettings& settings, const ContactState& contact,
                  ResidualState& residual);

/// v / |v|, or zero for a zero (or NaN) vector: the direction of a push, none when it is zero.
inline btVector3 unitOrZero(const btVector3& v) {
  const btScalar length = v.length();
  return length > 0 ? v / length : btVector3(0, 0, 0);
}

/// The unit direction of the push the last response gave particle i (pushRounds[i] ==
/// contactRound: recorded and not since superseded), or zero when that response did not push it.
/// A contact there holds the part of the particle's force into it (withoutInto).
btVector3 contactNormal(const ContactState& contact, const ResidualState& residual, uint32_t i);

/// Fills residual.residual with the model's net force at the particles' positions
/// (ForceResidual: springs on fastestSpringKernel in one pass, every volume term, m·gravity and
/// external forces), before the contacts' reactions (addContactReactions); attached particles
/// get 0. No allocation.
void muscleForceResidual(const MuscleSettings& settings, const ParticleState& particles,
                         const InteractionState& interaction, ResidualState& residual,
                         const btVector3& gravity);

/// The muscle's spring forces at its positions, into particles.forces.
SpringForceResult springForces(const MuscleSettings& settings, ParticleState& particles);

/// The sums of residual.residual over the free particles (contactParticles: those with a
/// contactNormal), in one fixed order.
ResidualSums residualSums(const ParticleState& particles, const ContactState& contact,
                          const ResidualState& residual);

}  // namespace fibremss
