#include "Residual.h"

#include <algorithm>
#include <cmath>

#include "contact/BodyContacts.h"
#include "kernels/SpringForces.h"
#include "kernels/VolumeForces.h"
#include "state/MuscleState.h"

namespace fibremss {
namespace {

/// Adds K·inverse·(G0/G)/6·|∂(6V)/∂x_i|² of each fan of the local volume terms to its
/// particles' traces (1/V0 = 6·inverse, ∂V/∂x_i a sixth of the gradient; G the rest gradient
/// sum, uncapped).
void addFanTraces(const MuscleSettings& settings, std::vector<btScalar>& trace) {
  for (size_t k = 0; k < settings.fanInverseVolume.size(); ++k) {
    const std::span<const uint32_t> p = fanParticles(settings, k);
    const FanGradients rest = fanGradients(settings.restPositions.data(), p);
    if (!(rest.squared > 0)) continue;
    const btScalar scale = settings.volumeModulus * settings.fanInverseVolume[k] *
                           settings.fanRestGradient[k] / rest.squared / 6;
    for (size_t v = 0; v < p.size(); ++v) trace[p[v]] += scale * rest.gradients[v].length2();
  }
}

/// Adds K/V0·|∂V/∂x_i|² of the enclosed-volume term at rest to its particles' traces.
void addEnclosedTraces(const MuscleSettings& settings, std::vector<btScalar>& trace) {
  if (settings.enclosedFaces.empty()) return;
  const std::vector<btVector3> gradient = enclosedRestGradients(settings);
  const auto scale = static_cast<btScalar>(settings.enclosedModulus / settings.enclosedRestVolume);
  for (size_t i = 0; i < gradient.size(); ++i) trace[i] += scale * gradient[i].length2();
}

}  // namespace

std::vector<btScalar> residualStiffness(const MuscleSettings& settings) {
  std::vector<btScalar> trace(settings.particleCount(), 0);
  for (const Spring& spring : settings.springs) {
    trace[spring.a] += spring.stiffness;
    trace[spring.b] += spring.stiffness;
  }
  addFanTraces(settings, trace);
  addEnclosedTraces(settings, trace);
  for (btScalar& k : trace) k /= 3;
  return trace;
}

void ResidualSums::add(const ResidualSums& other) {
  forceSquares += other.forceSquares;
  displacementSquares += other.displacementSquares;
  maxForce = std::max(maxForce, other.maxForce);
  maxDisplacement = std::max(maxDisplacement, other.maxDisplacement);
  particles += other.particles;
  contactParticles += other.contactParticles;
}

ForceResidual ResidualSums::summary() const {
  ForceResidual residual;
  residual.particles = particles;
  residual.contactParticles = contactParticles;
  residual.maxForce = maxForce;
  residual.maxDisplacement = maxDisplacement;
  if (particles == 0) return residual;
  const auto count = static_cast<double>(particles);
  residual.rmsForce = std::sqrt(forceSquares / count);
  residual.rmsDisplacement = std::sqrt(displacementSquares / count);
  return residual;
}

void recordPushes(const MuscleSettings& settings, const ContactState& contact,
                  ResidualState& residual) {
  const uint32_t round = contact.contactRound + 1;  // applyPushes counts it first
  for (uint32_t i : settings.boundaryParticles) {
    if (contact.pushCounts[i] == 0) continue;
    residual.lastPushes[i] = contact.pushes[i];
    residual.pushRounds[i] = round;
    residual.lastBonePushes[i] = contact.pinchBones[i] >= 0
                                     ? contact.firstBonePushes[i] + contact.otherBonePushes[i]
                                     : btVector3(0, 0, 0);
  }
}

btVector3 contactNormal(const ContactState& contact, const ResidualState& residual, uint32_t i) {
  const uint32_t round = contact.contactRound;
  if (round == 0 || residual.pushRounds[i] != round) return btVector3(0, 0, 0);
  return unitOrZero(residual.lastPushes[i]);
}

void muscleForceResidual(const MuscleSettings& settings, const ParticleState& particles,
                         const InteractionState& interaction, ResidualState& residual,
                         const btVector3& gravity) {
  std::vector<btVector3>& r = residual.residual;
  springForces(settings, particles.positions, r);
  addLocalVolumeForces(settings, particles.positions, r);
  addEnclosedVolumeForces(settings, particles.positions, r);
  addExternalForces(settings, particles, interaction, gravity, r);
  for (uint32_t i : settings.fixedParticles) r[i].setZero();
}

SpringForceResult springForces(const MuscleSettings& settings, ParticleState& particles) {
  return springForces(settings, particles.positions, particles.forces);
}

ResidualSums residualSums(const ParticleState& particles, const ContactState& contact,
                          const ResidualState& residual) {
  ResidualSums sums;
  for (uint32_t i : particles.freeParticles) {
    if (!contactNormal(contact, residual, i).isZero()) ++sums.contactParticles;
    const double force = residual.residual[i].length();
    const btScalar k = residual.residualStiffness[i];
    const double displacement = k > 0 ? force / k : 0;
    sums.forceSquares += force * force;
    sums.displacementSquares += displacement * displacement;
    sums.maxForce = std::max(sums.maxForce, force);
    sums.maxDisplacement = std::max(sums.maxDisplacement, displacement);
  }
  sums.particles = particles.freeParticles.size();
  return sums;
}

}  // namespace fibremss
