// MuscleSystem's local steps (stepLocal): a duration step that moves only the particles of a
// region (setLocalRegion), a tool's neighbourhood at haptic rate, while the rest of each muscle
// holds where the last step left it. The region's springs and volume terms are gathered once into
// index arrays as large as the muscle, so that neither gathering again nor a step allocates.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>
#include <utility>

#include "MuscleSystemChecks.h"
#include "MuscleSystemImpl.h"
#include "contact/BodyContacts.h"
#include "dynamics/StrainLimit.h"
#include "integrators/Integrators.h"
#include "kernels/SpringForces.h"
#include "kernels/VolumeForces.h"

namespace fibremss {
namespace {

/// Lists particle i in the region's reach as part of the ring, unless it is listed already.
void reach(RegionState& region, uint32_t i) {
  if (region.regionMark[i] != 0) return;
  region.regionMark[i] = kInRing;
  region.regionReach.push_back(i);
}

/// Sizes the muscle's region arrays for its settings (the first gathering, or new settings after
/// a tear or a cut), or unmarks the last region's particles.
void resetRegion(const MuscleSettings& settings, RegionState& region) {
  if (region.regionSettings == &settings) {
    for (uint32_t i : region.regionReach) region.regionMark[i] = 0;
  } else {
    const size_t particles = settings.particleCount();
    region.regionMark.assign(particles, 0);
    region.regionParticles.reserve(particles);
    region.regionReach.reserve(particles);
    region.regionSprings.reserve(settings.springs.size());
    region.regionFans.reserve(settings.fanInverseVolume.size());
    region.regionSettings = &settings;
  }
  region.regionParticles.clear();
  region.regionReach.clear();
  region.regionSprings.clear();
  region.regionFans.clear();
}

/// The muscle's free particles within `radius` of `centre` (none for a radius < 0), the springs
/// and fans with one of them, and the ring those reach.
void gatherRegion(const MuscleSettings& settings, const ParticleState& particles,
                  RegionState& region, const btVector3& centre, btScalar radius) {
  resetRegion(settings, region);
  for (uint32_t i : particles.freeParticles)
    if (radius >= 0 && (particles.positions[i] - centre).length2() <= radius * radius) {
      region.regionMark[i] = kInRegion;
      region.regionParticles.push_back(i);
      region.regionReach.push_back(i);
    }
  for (uint32_t s = 0; s < settings.springs.size(); ++s) {
    const Spring& spring = settings.springs[s];
    if (region.regionMark[spring.a] != kInRegion && region.regionMark[spring.b] != kInRegion)
      continue;
    region.regionSprings.push_back(s);
    reach(region, spring.a);
    reach(region, spring.b);
  }
  for (uint32_t k = 0; k < settings.fanInverseVolume.size(); ++k) {
    const std::span<const uint32_t> fan = fanParticles(settings, k);
    bool inside = false;
    for (uint32_t i : fan) inside = inside || region.regionMark[i] == kInRegion;
    if (!inside) continue;
    region.regionFans.push_back(k);
    for (uint32_t i : fan) reach(region, i);
  }
}

/// Marks the boundary particles outside the region as already visited in the coming
/// collideMuscleBone call against a bone's true mesh (its next boneVisit), so that it queries
/// the mesh for the region's particles only: the others would not move.
void skipMeshOutside(const MuscleSettings& settings, const RegionState& region,
                     ContactState& contact, const BoneState& bone) {
  if (!bone.meshContact || contact.meshVisits.empty()) return;
  const uint32_t visit = contact.boneVisit + 1;
  for (uint32_t i : settings.boundaryParticles)
    if (region.regionMark[i] != kInRegion) contact.meshVisits[i] = visit;
}

/// Forgets the pushes of this iteration's collisions on particles outside the region: a local
/// step moves none of them.
void dropPushesOutside(const MuscleSettings& settings, const RegionState& region,
                       ContactState& contact) {
  for (uint32_t i : settings.boundaryParticles) {
    if (contact.pushCounts[i] == 0 || region.regionMark[i] == kInRegion) continue;
    contact.pushes[i].setZero();
    contact.pushCounts[i] = 0;
    contact.pinchBones[i] = -1;
    contact.firstBonePushes[i].setZero();
    contact.otherBonePushes[i].setZero();
  }
}

}  // namespace

bool MuscleSystem::Impl::bonesMove() const {
  return std::any_of(bones.order.begin(), bones.order.end(), [&](uint32_t slot) {
    return !(bones.states[slot]->last == bones.states[slot]->target);
  });
}

// The region's forces (its springs and fans, the whole enclosed volume, external forces), its
// particles' integration and strain limit, the tree's refit, the bones' pushes on the region.
void MuscleSystem::Impl::localIteration(MuscleState& state, const TimeIntegrator& integrator,
                                        btScalar dt, btScalar lastDt, unsigned thread) {
  const MuscleSettings& settings = *state.settings;
  MuscleIterationResult& result = results[state.slot];
  for (uint32_t i : state.regionReach) state.forces[i].setZero();
  result.forces = addSpringForces(settings, state.positions, state.forces, state.regionSprings);
  addLocalVolumeForces(settings, state.positions, state.forces, state.regionFans);
  addEnclosedVolumeForces(settings, state.positions, state.forces);
  addExternalForces(*state.settings, state, state, definition.gravity, state.forces);
  const IntegrationResult integration =
      integrator.advance(state.integrated(duration > 0), definition, dt, lastDt);
  const int passes = result.forces.nearLimit > 0 ? kIterationStrainPasses : 0;
  result.displacement = limitStrain(settings, state, state, passes) > 0 ? freeDisplacement(state)
                                                                        : integration.displacement;
  result.finite = integration.finite;
  if (definition.muscleMuscle || definition.muscleBone) refitTree(*state.settings, state, state);
  if (definition.muscleBone)
    for (uint32_t slot : bones.order) {
      skipMeshOutside(settings, state, state, *bones.states[slot]);
      collideMuscleBone(*state.settings, state, state, state, *bones.states[slot],
                        scratch[thread].stack, scratch[thread].contacts);
    }
  dropPushesOutside(settings, state, state);
  respond(settings, state, state, state, true);
}

// Every active muscle's region gathered (again for new settings) and made its free particles
// for the step (`begin`; at rest after another integrator's whole step), or its free particles
// given back.
void MuscleSystem::Impl::swapRegions(bool begin) {
  for (uint32_t slot : active) {
    MuscleState& state = *muscles.states[slot];
    if (begin && state.regionSettings != state.settings.get())
      gatherRegion(*state.settings, state, state, regionCentre, regionRadius);
    std::swap(state.freeParticles, state.regionParticles);
    if (begin && localFromRest)
      for (uint32_t i : state.freeParticles) state.previous[i] = state.positions[i];
  }
  if (!begin) localFromRest = false;
}

void MuscleSystem::Impl::localStep(const StepSize& size) {
  // Local steps are Verlet's whatever the system's integrator: its workspace (a factor) stays
  // prepared for the whole steps; Verlet needs none.
  const TimeIntegrator& integrator = integratorFor(Integrator::Verlet);
  readBoneTargets();
  if (definition.rebuildEveryStep || bonesMove()) return step(size);
  const Clock::time_point stepStart = Clock::now();
  stats = StepStats{};
  prepareWorkers();
  sortActive();
  resolveMuscles();
  beginBodyContacts();
  swapRegions(true);
  int iteration = 0;
  while (iteration < size.iterations && !stats.interrupted) {
    ++iteration;
    const btScalar dt = size.timeStep;
    const btScalar lastDt = previousDt > 0 ? previousDt : dt;
    contacts.clear();
    pushesPending = true;
    forEachMuscle("local", [&](MuscleState& state, uint32_t, unsigned thread) {
      localIteration(state, integrator, dt, lastDt, thread);
    });
    pushesPending = false;
    gatherContacts();
    sumIteration(dt);
    collideBodies(dt);
    stats.interrupted = cancel && cancel->load();
  }
  // The pushes may have stretched springs held at the limit (as step's end).
  for (uint32_t slot : active)
    if (results[slot].forces.nearLimit > 0)
      limitStrain(*muscles.states[slot]->settings, *muscles.states[slot], *muscles.states[slot],
                  kEndStrainPasses);
  swapRegions(false);
  stats.iterations = iteration;
  stats.contacts = contacts.found;
  endBodyContacts();
  stats.timing.total = std::chrono::duration<double, std::milli>(Clock::now() - stepStart).count();
}

void MuscleSystem::setLocalRegion(const btVector3& centre, btScalar radius) {
  if (!std::isfinite(centre.x()) || !std::isfinite(centre.y()) || !std::isfinite(centre.z()))
    throw InputError("MuscleSystem::setLocalRegion", "centre", "expected finite coordinates");
  if (!(radius >= 0) || !std::isfinite(radius))
    throw InputError("MuscleSystem::setLocalRegion", "radius",
                     "expected a finite radius >= 0 m, got " + std::to_string(radius));
  Impl& impl = *impl_;
  impl.regionCentre = centre;
  impl.regionRadius = radius;
  for (uint32_t slot : impl.muscles.order) {
    MuscleState& state = *impl.muscles.states[slot];
    gatherRegion(*state.settings, state, state, centre, radius);
  }
}

void MuscleSystem::stepLocal(btScalar duration) {
  if (!(duration > 0) || !std::isfinite(duration))
    throw InputError("MuscleSystem::stepLocal", "duration",
                     "expected a finite simulated time > 0 s, got " + std::to_string(duration));
  impl_->duration = duration;
  impl_->localStepping = true;
  impl_->guardedStep();
  impl_->localStepping = false;
  impl_->duration = 0;
}

}  // namespace fibremss
