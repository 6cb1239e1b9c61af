// One MuscleSystem step (method.md §5). Bones move from their last to their target transform
// over the first motionFraction·iterations iterations (translation lerp, rotation slerp); in each
// of those iterations every free particle is moved by its bones' motion of that iteration (the
// pre-transform: a blend of the two bones of a muscle spanning a joint, or the nearest bone's
// as in the thesis; x and x(t−dt) alike, split like the bones so that muscles and bones stay in
// step) and fixed particles are set to T·rest. Then per iteration: spring forces → dt (eq 5.1 or
// fixed) → integration → strain limit (StrainLimit.h) → tree refit (only past the skin) →
// muscle–muscle and muscle–bone pairs → response; after the last response the strain limit
// again. The thesis mode (rebuildEveryStep) instead jumps the bones, restarts particles from
// rest moved by their pre-transform, and rebuilds the trees. Output: deformed surfaces (the skin,
// then surface contact).
#include <BulletCollision/CollisionDispatch/btCollisionObject.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>

#include "MuscleSystemChecks.h"
#include "MuscleSystemImpl.h"
#include "dynamics/StrainLimit.h"
#include "dynamics/TimeStep.h"
#include "integrators/Integrators.h"
#include "kernels/MuscleSystemPretransform.h"
#include "kernels/SpringForces.h"
#include "kernels/VolumeForces.h"

namespace fibremss {
namespace {

using Clock = std::chrono::steady_clock;

double millisecondsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

/// Rigid transform a share `s` of the way from `from` to `to`: linear translation, slerp rotation.
btTransform interpolate(const btTransform& from, const btTransform& to, btScalar s) {
  const btVector3 origin = from.getOrigin().lerp(to.getOrigin(), s);
  const btQuaternion rotation = from.getRotation().slerp(to.getRotation(), s);
  return btTransform(rotation, origin);
}

/// The largest bone turn per iteration of a projective step [rad]: a step takes at least one
/// iteration per this much of its largest turn. Measured on hip-pelvis (sub-poses of 5°, every
/// contact on) with 1 or 2 iterations per pose: 4 and 2 of 18 steps rolled back, a muscle frozen;
/// 3 iterations per pose, or 1 per sub-pose of at most 2° (`max_step_deg=2`), none.
constexpr double kMaxTurnPerIteration = 2 * SIMD_PI / 180;

}  // namespace

void MuscleSystem::Impl::resolveBones(ParticleState& particles) const {
  for (size_t b = 0; b < particles.bones.size(); ++b) {
    const BoneState* bone = bones.find(particles.bones[b]);
    particles.boneSlots[b] = bone ? static_cast<int32_t>(particles.bones[b].index) : -1;
    particles.boneTransforms[b] = bone ? bone->current : btTransform::getIdentity();
  }
}

// Rest positions moved by their pre-transform (fixed ones by their bone); no velocity.
void MuscleSystem::Impl::placeAtBones(const MuscleSettings& settings,
                                      ParticleState& particles) const {
  for (uint32_t i = 0; i < settings.particleCount(); ++i) {
    const btTransform* fixed =
        settings.isFixed(i) ? boneTransformOf(particles.boneTransforms, settings.fixedBone[i])
                            : nullptr;
    particles.positions[i] =
        fixed ? *fixed * settings.restPositions[i]
              : pretransformPoint(settings, particles.boneTransforms, i, settings.restPositions[i],
                                  definition.blendedPretransform, definition.pretransformBlend);
    particles.previous[i] = particles.positions[i];
    particles.velocities[i].setZero();
  }
}

// Moves free particles by their bones' motion in this iteration (blended, or the nearest
// bone's), x and x(t−dt) alike, so the motion injects no velocity.
void MuscleSystem::Impl::pretransform(const MuscleSettings& settings, ParticleState& particles,
                                      bool rotateVelocities) const {
  if (!particles.bonesMoving) return;
  const bool blended = definition.blendedPretransform;
  const PretransformBlend blend = definition.pretransformBlend;
  if (blended && !settings.blendWeight.empty() && blend == PretransformBlend::DualQuaternion)
    return pretransformDualQuaternions(settings, particles, rotateVelocities);
#if FIBREMSS_SSE_PRETRANSFORM
  // The common case (Verlet, blended, a few bones) with the transforms packed once.
  const size_t count = particles.boneDeltas.size();
  if (blended && !settings.blendWeight.empty() && !rotateVelocities && count <= kPackedBones) {
    PackedTransform packed[kPackedBones];
    for (size_t b = 0; b < count; ++b) packed[b] = packTransform(particles.boneDeltas[b]);
#if FIBREMSS_AVX2_PARTICLES
    if (fastestSpringKernel() == SpringKernel::avx2)
      return pretransformPackedAvx2(settings, packed, count, particles.freeParticles,
                                    particles.positions.data(), particles.previous.data());
#endif
    for (uint32_t i : particles.freeParticles)
      pretransformPacked(settings, packed, count, i, particles.positions[i], particles.previous[i]);
    return;
  }
#endif
  for (uint32_t i : particles.freeParticles)
    movePretransformed(settings, particles, i, rotateVelocities);
}

// One free particle's x, x(t−dt) and (rotateVelocities) velocity by pretransformPoint/Direction.
void MuscleSystem::Impl::movePretransformed(const MuscleSettings& settings,
                                            ParticleState& particles, uint32_t i,
                                            bool rotateVelocities) const {
  const bool blended = definition.blendedPretransform;
  const PretransformBlend blend = definition.pretransformBlend;
  const std::vector<btTransform>& deltas = particles.boneDeltas;
  particles.positions[i] =
      pretransformPoint(settings, deltas, i, particles.positions[i], blended, blend);
  particles.previous[i] =
      pretransformPoint(settings, deltas, i, particles.previous[i], blended, blend);
  if (rotateVelocities)
    particles.velocities[i] =
        pretransformDirection(settings, deltas, i, particles.velocities[i], blended, blend);
}

// The dual-quaternion pre-transform with the bones' motions converted once: one blend per
// particle moves x, x(t−dt) and the velocity; particles on one bone take pretransformPoint's.
void MuscleSystem::Impl::pretransformDualQuaternions(const MuscleSettings& settings,
                                                     ParticleState& particles,
                                                     bool rotateVelocities) const {
  for (size_t b = 0; b < particles.boneDeltas.size(); ++b)
    particles.boneDualDeltas[b] = dualQuaternionOf(&particles.boneDeltas[b]);
  const DualQuaternion identity = dualQuaternionOf(nullptr);
  const auto motionOf = [&](int32_t bone) -> const DualQuaternion& {
    const DualQuaternion* motion = boneTransformOf(particles.boneDualDeltas, bone);
    return motion ? *motion : identity;
  };
  for (uint32_t i : particles.freeParticles) {
    if (!blendsDualQuaternions(settings, i, PretransformBlend::DualQuaternion)) {
      movePretransformed(settings, particles, i, rotateVelocities);
      continue;
    }
    const RigidMotion motion =
        blendDualQuaternions(motionOf(settings.blendBoneA[i]), motionOf(settings.blendBoneB[i]),
                             settings.blendWeight[i]);
    particles.positions[i] = moveRigidly(motion, particles.positions[i]);
    particles.previous[i] = moveRigidly(motion, particles.previous[i]);
    if (rotateVelocities)
      particles.velocities[i] = rotateByQuaternion(motion.rotation, particles.velocities[i]);
  }
}

// Fixed particles sit exactly on their bone: x = T · rest.
void MuscleSystem::Impl::followFixed(const MuscleSettings& settings,
                                     std::span<const int32_t> boneSlots,
                                     ParticleState& particles) const {
  for (uint32_t i : settings.fixedParticles) {
    const int32_t b = settings.fixedBone[i];
    if (b < 0 || boneSlots[b] < 0) continue;
    particles.previous[i] = particles.positions[i];
    particles.positions[i] = particles.boneTransforms[b] * settings.restPositions[i];
  }
}

void MuscleSystem::Impl::prepareWorkers() {
  const TaskScheduler& host = definition.scheduler;
  const unsigned threads = TaskPool::resolve(definition.threads, host);
  if (!pool || pool->threads() != threads || !(pool->host() == host))
    pool = std::make_unique<TaskPool>(threads, host);
  scratch.resize(threads);
  // Each thread logs an even share of the drawing capacity; a full log still counts.
  const size_t share = (contacts.ends.size() / threads + 1) & ~size_t{1};
  for (ThreadScratch& thread : scratch) {
    if (thread.contacts.ends.size() < share) thread.contacts.ends.resize(share);
    thread.stack.reserve(4096);
  }
  const size_t slots = muscles.states.size();
  size_t chunks = 0;
  for (uint32_t slot : muscles.order) {
    planChunks(*muscles.states[slot]->settings, *muscles.states[slot]);
    chunks += muscles.states[slot]->forceChunks.size();
  }
  forceTasks.reserve(chunks);
  active.reserve(slots);
  results.resize(slots);
  residuals.resize(slots);
  pairTasks.reserve(slots * (slots - std::min<size_t>(slots, 1)) / 2);
  musclePairs.resize(slots);
  for (std::vector<uint32_t>& pairs : musclePairs) pairs.reserve(slots);
  // Room for the contacts of every pair at once: its candidate list's capacity.
  size_t room = 0;
  for (uint32_t a : muscles.order)
    for (const CandidateList& list : muscles.states[a]->muscleLists) room += list.pairs.size();
  if (pairContacts.size() < room) pairContacts.resize(room);
  if (pairReactions.size() < room) pairReactions.resize(room);
  size_t boundary = 0;
  for (uint32_t slot : muscles.order)
    boundary += muscles.states[slot]->settings->boundaryParticles.size();
  boneContacts.reserve(boundary);
}

void MuscleSystem::Impl::planChunks(const MuscleSettings& settings, ChunkState& chunks) const {
  if (chunks.chunkWork == forceChunkWork && !chunks.forceChunks.empty()) return;
  chunks.forceChunks = forceChunks(settings, fastestSpringKernel(), forceChunkWork);
  chunks.chunkWork = forceChunkWork;
  const size_t count = chunks.forceChunks.size();
  chunks.chunkBase.assign(count, 0);
  size_t end = 0;  // of the last window in chunkForces
  for (size_t c = 1; c < count; ++c) {
    const ForceChunk& chunk = chunks.forceChunks[c];
    const size_t start = std::max<size_t>(end, chunk.lower);
    chunks.chunkBase[c] = start - chunk.lower;
    end = start + (chunk.upper - chunk.lower);
  }
  chunks.chunkForces.assign(end, btVector3(0, 0, 0));
  chunks.chunkSprings.assign(count, SpringForceResult{});
  chunks.chunkMs.assign(count, 0);
  chunks.chunkVolumeMs.assign(count, 0);
}

void MuscleSystem::Impl::orderForceTasks() {
  forceTasks.clear();
  chunked = false;
  for (uint32_t slot : active) {
    const std::vector<ForceChunk>& chunks = muscles.states[slot]->forceChunks;
    chunked = chunked || chunks.size() > 1;
    for (uint32_t c = 0; c < chunks.size(); ++c) forceTasks.push_back({slot, c, chunks[c].work});
  }
  // Largest first: handed out in this order, the threads finish close together.
  std::sort(forceTasks.begin(), forceTasks.end(), [](const ForceTask& x, const ForceTask& y) {
    if (x.work != y.work) return x.work > y.work;
    return x.slot != y.slot ? x.slot < y.slot : x.chunk < y.chunk;
  });
}

void MuscleSystem::Impl::gatherContacts() {
  for (ThreadScratch& thread : scratch) {
    ContactLog& log = thread.contacts;
    const size_t moved = std::min(log.stored, contacts.ends.size() / 2 - contacts.stored);
    std::copy_n(log.ends.begin(), 2 * moved, contacts.ends.begin() + 2 * contacts.stored);
    contacts.stored += moved;
    contacts.found += log.found;
    contacts.candidates += log.candidates;
    log.clear();
  }
}

// Bones to `share` of the way from last to target (exactly the target when arriving); the
// muscles follow in followBones.
void MuscleSystem::Impl::moveBones(btScalar share, bool arrive) {
  for (uint32_t slot : bones.order) {
    BoneState& bone = *bones.states[slot];
    const btTransform before = bone.current;
    bone.current = arrive ? bone.target : interpolate(bone.last, bone.target, share);
    bone.delta = bone.current * before.inverse();
    bone.moving = !(bone.current == before);
    if (bone.moving)
      bone.tree.place(bone.current, bone.settings->sphereCentres, bone.settings->sphereRadii);
  }
}

void MuscleSystem::Impl::followBones(const MuscleSettings& settings, ParticleState& particles,
                                     TreeState& trees, BoneMotion motion) const {
  const bool sinceStart = motion == BoneMotion::SinceStepStart;
  particles.bonesMoving = false;
  bool arrived = true;
  for (size_t b = 0; b < particles.bones.size(); ++b) {
    particles.boneDeltas[b].setIdentity();
    if (particles.boneSlots[b] < 0) continue;
    const BoneState& bone = *bones.states[particles.boneSlots[b]];
    particles.boneTransforms[b] = bone.current;
    arrived = arrived && bone.current == bone.target;
    if (sinceStart ? bone.current == bone.goodLast : !bone.moving) continue;
    particles.boneDeltas[b] = sinceStart ? bone.current * bone.goodLast.inverse() : bone.delta;
    particles.bonesMoving = true;
  }
  trees.treeFollowed = particles.bonesMoving && !arrived;
  pretransform(settings, particles, integratorFor(definition.integrator).usesVelocities());
  followFixed(settings, particles.boneSlots, particles);
}

// The share of a phase's wall time that `part` took: its thread time over all active muscles
// divided by the thread time of every part of the phase (parts of one task are not timed apart
// on the wall clock: they run in the same task).
double MuscleSystem::Impl::threadShare(
    double MuscleIterationResult::*part,
    std::initializer_list<double MuscleIterationResult::*> phase) const {
  double partMs = 0, phaseMs = 0;
  for (uint32_t slot : active) {
    partMs += results[slot].*part;
    for (double MuscleIterationResult::*member : phase) phaseMs += results[slot].*member;
  }
  return phaseMs > 0 ? partMs / phaseMs : 0;
}

// The dt of this iteration: fixed, or eq 5.1 over all muscles clamped to [min, max].
btScalar MuscleSystem::Impl::timeStep(const StepSize& size) const {
  if (size.exact || !stepSettings.adaptiveTimeStep) return size.timeStep;
  btScalar dt = size.timeStep;
  for (uint32_t slot : active) dt = std::min(dt, results[slot].safeTimeStep);
  return std::max(dt, size.minTimeStep);
}

// Pairs of muscles whose bounds meet, in two phases without waiting: every pair records its
// contacts (any thread, any order; muscles are only read), then every muscle adds its pairs'
// pushes in insertion order of its partners, each pair's in the order found. The sums have one
// fixed order whatever the thread count.
void MuscleSystem::Impl::collideMusclePairs() {
  pairTasks.clear();
  for (std::vector<uint32_t>& pairs : musclePairs) pairs.clear();
  size_t room = 0;
  for (size_t i = 0; i < muscles.order.size(); ++i) {
    const uint32_t a = muscles.order[i];
    const MuscleState& first = *muscles.states[a];
    if (first.frozen || first.tree.empty()) continue;
    for (size_t j = i + 1; j < muscles.order.size(); ++j) {
      const uint32_t b = muscles.order[j];
      const MuscleState& second = *muscles.states[b];
      if (second.frozen || second.tree.empty() ||
          !boundsOverlap(first.tree.bounds(0), second.tree.bounds(0)))
        continue;
      const size_t capacity = b < first.muscleLists.size() ? first.muscleLists[b].pairs.size() : 0;
      musclePairs[a].push_back(static_cast<uint32_t>(pairTasks.size()));
      musclePairs[b].push_back(static_cast<uint32_t>(pairTasks.size()));
      pairTasks.push_back({a,
                           b,
                           {pairContacts.data() + room, capacity},
                           first.contactRound + 1,
                           second.contactRound + 1});
      room += capacity;
    }
  }
  pool->run(
      pairTasks.size(),
      [&](size_t k, unsigned thread) {
        MusclePairTask& pair = pairTasks[k];
        MuscleState& first = *muscles.states[pair.a];
        const MuscleState& second = *muscles.states[pair.b];
        collideMuscles(first.colliding(), second.colliding(),
                       candidateList(first.muscleLists, pair.b), scratch[thread].stack,
                       scratch[thread].contacts, pair.contacts);
      },
      "muscle pairs");
}

void MuscleSystem::Impl::pushMusclePairs(ContactState& contact, TreeState& trees, uint32_t slot,
                                         TreeTraversalStack& stack) {
  for (uint32_t k : musclePairs[slot]) {
    const MusclePairTask& pair = pairTasks[k];
    const bool onFirst = pair.a == slot;
    if (pushMuscleContacts(muscles.states[pair.a]->colliding(), muscles.states[pair.b]->colliding(),
                           onFirst, contact, stack, pair.contacts) &&
        onFirst)
      ++trees.candidateOverflows;
  }
}

// Collision of one iteration after every muscle's tree is refitted (integrateAndRefit): the
// muscle pairs (one task per pair), then per muscle its pairs' pushes and its bones. The pushes
// are applied by the next forces phase (or applyResponse after the last iteration).
void MuscleSystem::Impl::collide() {
  contacts.clear();
  if (!definition.muscleMuscle && !definition.muscleBone) {
    // A round without contacts: what the last response pushed holds no longer (contactNormal).
    for (uint32_t slot : active) ++muscles.states[slot]->contactRound;
    return;
  }
  Clock::time_point start = Clock::now();
  if (definition.muscleMuscle) collideMusclePairs();
  stats.timing.muscleCd += millisecondsSince(start);
  start = Clock::now();
  forEachMuscle("pushes and bones", [&](MuscleState& state, uint32_t slot, unsigned thread) {
    MuscleIterationResult& result = results[slot];
    const Clock::time_point pushesStart = Clock::now();
    if (definition.muscleMuscle) pushMusclePairs(state, state, slot, scratch[thread].stack);
    const Clock::time_point boneStart = Clock::now();
    if (definition.muscleBone)
      for (uint32_t boneSlot : bones.order)
        collideMuscleBone(*state.settings, state, state, state, *bones.states[boneSlot],
                          scratch[thread].stack, scratch[thread].contacts);
    result.pushesMs =
        millisecondsSince(pushesStart) - (result.boneMs = millisecondsSince(boneStart));
  });
  gatherContacts();
  const double wall = millisecondsSince(start);
  const double pushes =
      threadShare(&MuscleIterationResult::pushesMs,
                  {&MuscleIterationResult::pushesMs, &MuscleIterationResult::boneMs});
  stats.timing.muscleCd += pushes * wall;
  stats.timing.boneCd += (1 - pushes) * wall;
  stats.contacts = contacts.found;
  stats.candidates = contacts.candidates;
  for (uint32_t slot : muscles.order)
    stats.candidateOverflows += std::exchange(muscles.states[slot]->candidateOverflows, 0);
  pushesPending = true;
}

// The pushes of the last collide() on a muscle (response), once.
void MuscleSystem::Impl::respond(const MuscleSettings& settings, ParticleState& particles,
                                 ContactState& contact, ResidualState& residual,
                                 bool record) const {
  if (!pushesPending) return;
  const TimeIntegrator& integrator = integratorFor(definition.integrator);
  const bool holds = integrator.holdsContacts(definition);
  if (record || holds) recordPushes(settings, contact, residual);
  applyPushes(settings, particles, contact, integrator.usesVelocities(),
              definition.slidingContacts);
  if (holds) leaveContactSlop(settings, contact, residual, particles, kContactSlop);
}

void MuscleSystem::Impl::applyResponse() {
  forEachMuscle("response", [this](MuscleState& state, uint32_t, unsigned) {
    respond(*state.settings, state, state, state, true);
  });
  pushesPending = false;
}

// The last iteration's response, then this iteration's bone motion (timed as forces).
void MuscleSystem::Impl::moveMuscle(const MuscleSettings& settings, ParticleState& particles,
                                    ContactState& contact, ResidualState& residual,
                                    TreeState& trees, MuscleIterationResult& result,
                                    bool bonesMove) const {
  const Clock::time_point start = Clock::now();
  respond(settings, particles, contact, residual, false);
  const Clock::time_point followStart = Clock::now();
  if (bonesMove)
    followBones(settings, particles, trees);
  else
    particles.bonesMoving = false;
  result.forcesMs += millisecondsSince(followStart);
  result.responseMs = millisecondsSince(start) - millisecondsSince(followStart);
}

void MuscleSystem::Impl::forceTask(const ForceTask& task, bool bonesMove) {
  MuscleState& state = *muscles.states[task.slot];
  MuscleIterationResult& result = results[task.slot];
  const MuscleSettings& settings = *state.settings;
  if (state.forceChunks.size() == 1)  // whole: moved here
    moveMuscle(settings, state, state, state, state, result, bonesMove);
  const Clock::time_point start = Clock::now();
  const ForceChunk& chunk = state.forceChunks[task.chunk];
  std::span<btVector3> forces = state.forces;
  if (task.chunk == 0)
    clearForces(forces);
  else  // clear: finishForces moved its last pass out
    forces = std::span(state.chunkForces).subspan(state.chunkBase[task.chunk], chunk.upper);
  const SpringKernel kernel = fastestSpringKernel();
  state.chunkSprings[task.chunk] = addSpringForces(settings, state.positions, forces, kernel,
                                                   chunk.springBegin, chunk.springEnd);
  const Clock::time_point volumeStart = Clock::now();
  addLocalVolumeForces(settings, state.positions, forces, kernel, chunk.fanClasses);
  if (task.chunk == 0) addEnclosedVolumeForces(settings, state.positions, forces);
  state.chunkVolumeMs[task.chunk] = millisecondsSince(volumeStart);
  state.chunkMs[task.chunk] = millisecondsSince(start);
  if (state.chunksLeft.fetch_sub(1, std::memory_order_acq_rel) == 1)
    finishForces(settings, state, state, state, state, result);
}

void MuscleSystem::Impl::finishForces(const MuscleSettings& settings, ChunkState& chunks,
                                      ParticleState& particles, const InteractionState& interaction,
                                      const IntegratorState& integration,
                                      MuscleIterationResult& result) {
  const Clock::time_point start = Clock::now();
  result.forces = SpringForceResult{};
  result.volumeMs = 0;
  for (size_t c = 0; c < chunks.forceChunks.size(); ++c) {
    if (c > 0) {
      const ForceChunk& chunk = chunks.forceChunks[c];
      const size_t count = chunk.upper - chunk.lower;
      moveForces(std::span(particles.forces).subspan(chunk.lower, count),
                 std::span(chunks.chunkForces).subspan(chunks.chunkBase[c] + chunk.lower, count));
    }
    result.forces.deviation += chunks.chunkSprings[c].deviation;
    result.forces.overstretched += chunks.chunkSprings[c].overstretched;
    result.forces.nearLimit += chunks.chunkSprings[c].nearLimit;
    result.forcesMs += chunks.chunkMs[c];
    result.volumeMs += chunks.chunkVolumeMs[c];
  }
  result.forces.exploded = result.forces.overstretched > 0;
  if (settings.fanInverseVolume.empty() && settings.enclosedFaces.empty()) result.volumeMs = 0;
  addExternalForces(settings, particles, interaction, definition.gravity, particles.forces);
  if (stepSettings.adaptiveTimeStep)
    result.safeTimeStep =
        adaptiveTimeStep(settings, particles, integration.centredDamping(), previousDt);
  result.forcesMs += millisecondsSince(start);
}

// Per chunk of every muscle (the largest first): spring and volume forces; the muscle's last
// chunk adds them up and takes the muscle's eq 5.1 bound. The last iteration's response and this
// iteration's bone motion come first: in the task of a muscle in one chunk, in a run of their
// own for muscles in more (their chunks read every particle). Then the reductions (in insertion
// order: the same sums for every thread count).
void MuscleSystem::Impl::forcesPhase(bool bonesMove) {
  const Clock::time_point start = Clock::now();
  for (uint32_t slot : active) {
    MuscleState& state = *muscles.states[slot];
    state.chunksLeft.store(state.forceChunks.size(), std::memory_order_relaxed);
    results[slot].forcesMs = 0;
  }
  if (chunked)
    forEachMuscle("move chunked muscles", [&](MuscleState& state, uint32_t slot, unsigned) {
      if (state.forceChunks.size() > 1)
        moveMuscle(*state.settings, state, state, state, state, results[slot], bonesMove);
    });
  pool->run(
      forceTasks.size(), [&](size_t k, unsigned) { forceTask(forceTasks[k], bonesMove); },
      "forces");
  pushesPending = false;
  double deviation = 0;
  double restSum = 0;
  // Judged on the last iteration: tearing while bones move heals.
  stats.exploded = false;
  stats.overstretchedSprings = 0;
  for (uint32_t slot : muscles.order) {
    if (muscles.states[slot]->frozen) continue;
    const SpringForceResult& forces = results[slot].forces;
    deviation += forces.deviation;
    stats.exploded = stats.exploded || forces.exploded;
    stats.overstretchedSprings += forces.overstretched;
    restSum += muscles.states[slot]->restLengthSum;
  }
  stats.springDeviationRatio = restSum > 0 ? static_cast<btScalar>(deviation / restSum) : 0;
  const double wall = millisecondsSince(start);
  const std::initializer_list<double MuscleIterationResult::*> phase = {
      &MuscleIterationResult::responseMs, &MuscleIterationResult::forcesMs};
  const double response = threadShare(&MuscleIterationResult::responseMs, phase);
  stats.timing.response += response * wall;
  stats.timing.mss += (1 - response) * wall;
  stats.timing.volume += threadShare(&MuscleIterationResult::volumeMs, phase) * wall;
}

// Per muscle: the integrator's advance by dt, then the refit of its sphere tree; the mean
// displacement reduced in insertion order.
void MuscleSystem::Impl::integrateAndRefit(const TimeIntegrator& integrator, btScalar dt) {
  const Clock::time_point start = Clock::now();
  const btScalar lastDt = previousDt > 0 ? previousDt : dt;
  const bool refit = definition.muscleMuscle || definition.muscleBone;
  forEachMuscle("integrate and refit", [&](MuscleState& state, uint32_t slot, unsigned) {
    MuscleIterationResult& result = results[slot];
    const Clock::time_point integrateStart = Clock::now();
    const IntegrationResult integration =
        integrator.advance(state.integrated(duration > 0), definition, dt, lastDt);
    // The projection runs where the forces found a spring near the limit. The iteration's
    // displacement is the projection's end's when it moved particles: at a limited equilibrium
    // the two cancel, as the stop rules expect.
    const int passes = result.forces.nearLimit > 0 ? kIterationStrainPasses : 0;
    result.displacement = limitStrain(*state.settings, state, state, passes) > 0
                              ? freeDisplacement(state)
                              : integration.displacement;
    result.finite = integration.finite;
    const Clock::time_point refitStart = Clock::now();
    if (refit) refitTree(*state.settings, state, state);
    result.refitMs = millisecondsSince(refitStart);
    result.integrateMs = millisecondsSince(integrateStart) - result.refitMs;
  });
  sumIteration(dt);
  const double wall = millisecondsSince(start);
  const double refitShare =
      threadShare(&MuscleIterationResult::refitMs,
                  {&MuscleIterationResult::integrateMs, &MuscleIterationResult::refitMs});
  stats.timing.mss += (1 - refitShare) * wall;
  stats.timing.muscleCd += refitShare * wall;
}

void MuscleSystem::Impl::sumIteration(btScalar dt) {
  double displacement = 0;
  size_t freeCount = 0;
  for (uint32_t slot : muscles.order) {
    if (muscles.states[slot]->frozen) continue;
    displacement += results[slot].displacement;
    freeCount += muscles.states[slot]->freeParticles.size();
    if (!results[slot].finite) stats.nan = true;
  }
  stats.lastTimeStep = previousDt = dt;
  stats.simulatedTime += dt;
  stats.meanDisplacement =
      freeCount ? static_cast<btScalar>(displacement / static_cast<double>(freeCount)) : 0;
}

// The estimated distance to equilibrium after `settled` iterations since the bones arrived: the
// mean displacement d times r/(1 − r), r = (d / d of W iterations ago)^(1/W) (the remaining
// steps of a linearly converging iteration), W = kEquilibriumWindow. Infinity until two windows
// are full, while d does not shrink, or while the rate still slows down (1 − r less than half
// what it was a window earlier): a slow mode is then still emerging from under faster ones that
// dominate d, and d alone would miss its distance.
double MuscleSystem::Impl::distanceToEquilibrium(int settled) {
  constexpr size_t kWindow = kEquilibriumWindow;
  const size_t slots = recentDisplacements.size();
  const size_t k = static_cast<size_t>(settled);
  const double d = stats.meanDisplacement;
  recentDisplacements[k % slots] = d;
  if (k < 2 * kWindow) return HUGE_VAL;
  const double middle = recentDisplacements[(k - kWindow) % slots];
  const double first = recentDisplacements[(k - 2 * kWindow) % slots];
  if (!(d < middle) || !(middle < first)) return HUGE_VAL;
  const double rate = std::pow(d / middle, 1.0 / kWindow);
  const double before = std::pow(middle / first, 1.0 / kWindow);
  if (1 - rate < (1 - before) / 2) return HUGE_VAL;
  return d * rate / (1 - rate);
}

bool MuscleSystem::Impl::stopRuleMet(bool arrived, int settled, Clock::time_point stepStart) {
  switch (stepSettings.stopRule) {
    case StopRule::Converged:
      return arrived && stats.meanDisplacement < stepSettings.epsilon;
    case StopRule::TimeBudget:
      return millisecondsSince(stepStart) >= stepSettings.budgetMs;
    case StopRule::SpringDeviation:
      return arrived && stats.springDeviationRatio < stepSettings.deviationEpsilon;
    case StopRule::Equilibrium:
      return arrived && distanceToEquilibrium(settled) < stepSettings.tolerance;
    case StopRule::Residual:
      if (!arrived || settled % kResidualCheckEvery != 0) return false;
      applyResponse();  // the residual of the state this iteration leaves (bit for bit as later)
      return residualOf(active).summary().rmsDisplacement < stepSettings.tolerance;
    default:
      return false;
  }
}

ResidualSums MuscleSystem::Impl::residualOf(std::span<const uint32_t> slots) {
  if (residuals.size() < muscles.states.size()) residuals.resize(muscles.states.size());
  // Every muscle's forces: a contact pair's reaction depends on both muscles'.
  const std::vector<uint32_t>& all = muscles.order;
  const auto task = [&](size_t k, unsigned) {
    MuscleState& state = *muscles.states[all[k]];
    muscleForceResidual(*state.settings, state, state, state, definition.gravity);
  };
  if (pool) {
    pool->run(all.size(), task, "residual");
  } else {
    for (size_t k = 0; k < all.size(); ++k) task(k, 0);
  }
  addContactReactions(&MuscleState::residual, all);
  ResidualSums total;
  for (uint32_t slot : slots) {
    const MuscleState& state = *muscles.states[slot];
    total.add(residuals[slot] = residualSums(state, state, state));
  }
  return total;
}

int MuscleSystem::Impl::iterationsFor(int requested) const {
  if (definition.integrator != Integrator::Projective) return requested;
  double turn = 0;
  for (uint32_t slot : bones.order) {
    const BoneState& bone = *bones.states[slot];
    const btQuaternion motion = bone.target.getRotation() * bone.last.getRotation().inverse();
    turn = std::max(turn, double(motion.getAngleShortestPath()));
  }
  return std::max(requested, static_cast<int>(std::ceil(turn / kMaxTurnPerIteration)));
}

void MuscleSystem::Impl::sortActive() {
  active.clear();
  for (uint32_t slot : muscles.order)
    if (!muscles.states[slot]->frozen) active.push_back(slot);
  const auto cost = [this](uint32_t slot) {
    const MuscleSettings& settings = *muscles.states[slot]->settings;
    return settings.springs.size() + settings.particleCount();
  };
  std::sort(active.begin(), active.end(),
            [&](uint32_t x, uint32_t y) { return cost(x) != cost(y) ? cost(x) > cost(y) : x < y; });
}

void MuscleSystem::Impl::readBoneTargets() {
  for (uint32_t slot : bones.order) {
    BoneState& bone = *bones.states[slot];
    if (bone.body) bone.target = bone.body->getWorldTransform();
    // NaN here would spread into every muscle on the bone and break its sphere tree.
    bone.heldNonFinite = !finiteTransform(bone.target);
    if (bone.heldNonFinite) bone.target = bone.current;
  }
}

int MuscleSystem::Impl::planBoneMotion(const StepSize& size, int& cap) {
  // The thesis rebuilt everything each step: bones jump, particles restart from rest.
  if (definition.rebuildEveryStep) {
    for (uint32_t slot : bones.order) {
      BoneState& bone = *bones.states[slot];
      bone.current = bone.last = bone.target;
      bone.moving = false;
      bone.tree.place(bone.current, bone.settings->sphereCentres, bone.settings->sphereRadii);
    }
    return 0;
  }
  // No bone moves in this step: the stop rules need not wait for an arrival.
  if (!bonesMove()) return 0;
  if (size.exact) return cap;
  cap = iterationsFor(cap);
  return std::clamp(static_cast<int>(std::lround(stepSettings.motionFraction * cap)), 1, cap);
}

void MuscleSystem::Impl::resolveMuscles() {
  for (uint32_t slot : active) {
    MuscleState& state = *muscles.states[slot];
    resolveBones(state);
    state.pinchedInStep = state.spannedInStep = 0;
    std::fill(state.stepBones.begin(), state.stepBones.end(), -1);
  }
}

void MuscleSystem::Impl::beginMuscles(const TimeIntegrator& integrator) {
  for (uint32_t slot : active) {
    MuscleState& state = *muscles.states[slot];
    ensurePrepared(integrator, *state.settings, state, state);
  }
  resolveMuscles();
  if (definition.rebuildEveryStep)
    forEachMuscle("rebuild", [this](MuscleState& state, uint32_t, unsigned) {
      placeAtBones(*state.settings, state);
      rebuildTree(*state.settings, state, state);
    });
}

void MuscleSystem::Impl::endIterations(bool arrived) {
  const Clock::time_point start = Clock::now();
  // A spent budget ends the step where it is: the bones jump the rest of the way.
  if (!arrived) moveBones(1, true);
  applyResponse();
  stats.timing.response += millisecondsSince(start);
  forEachMuscle("end", [this, arrived](MuscleState& state, uint32_t, unsigned) {
    if (!arrived) followBones(*state.settings, state, state);
    // The response's pushes may have stretched springs held at the limit.
    limitStrain(*state.settings, state, state, kEndStrainPasses);
  });
}

void MuscleSystem::Impl::outputSurfaces() {
  const Clock::time_point outputStart = Clock::now();
  forEachMuscle("output",
                [this](MuscleState& state, uint32_t, unsigned) { deform(*state.settings, state); });
  for (uint32_t slot : bones.order) {
    BoneState& bone = *bones.states[slot];
    bone.last = bone.current = bone.target;
    bone.moving = false;
  }
  stats.timing.output = millisecondsSince(outputStart);
}

void MuscleSystem::Impl::step(const StepSize& size) {
  const Clock::time_point stepStart = Clock::now();
  stats = StepStats{};
  const TimeIntegrator& integrator = integratorFor(definition.integrator);
  // The solve holds what the contacts' reactions hold (ContactReactions.cpp).
  const bool pairReactionsHeld = integrator.holdsContacts(definition) && definition.pairReactions;
  prepareWorkers();
  sortActive();
  orderForceTasks();
  readBoneTargets();
  int cap = size.iterations;
  const int motionIterations = planBoneMotion(size, cap);
  beginMuscles(integrator);
  beginBodyContacts();

  int iteration = 0;
  while (true) {
    ++iteration;
    const bool bonesMove = iteration <= motionIterations;
    if (bonesMove)
      moveBones(static_cast<btScalar>(iteration) / motionIterations, iteration == motionIterations);
    forcesPhase(bonesMove);
    if (pairReactionsHeld) addContactReactions(&MuscleState::forces, active);
    const btScalar dt = timeStep(size);
    integrateAndRefit(integrator, dt);
    collide();
    // Contact bodies meet the particles after this iteration's response.
    if (!contactBodies.empty()) applyResponse();
    collideBodies(dt);

    const bool arrived = iteration >= motionIterations;
    // A duration step runs all its iterations.
    const bool ruled = !size.exact && stopRuleMet(arrived, iteration - motionIterations, stepStart);
    stats.interrupted = cancel && cancel->load();
    if (iteration >= cap || ruled || stats.interrupted) {
      endIterations(arrived);
      break;
    }
  }
  stats.iterations = iteration;
  endBodyContacts();
  outputSurfaces();
  localFromRest = integrator.kind() != Integrator::Verlet;
  stats.timing.total = millisecondsSince(stepStart);
}

}  // namespace fibremss
