#include "fibremss/MuscleSystem.h"

#include <BulletCollision/CollisionDispatch/btCollisionObject.h>

#include <algorithm>
#include <random>
#include <stdexcept>
#include <string>

#include "MuscleSystemChecks.h"
#include "MuscleSystemImpl.h"
#include "collision/SurfacePush.h"
#include "dynamics/Residual.h"
#include "dynamics/Tearing.h"
#include "dynamics/TimeStep.h"
#include "fibremss/Error.h"
#include "integrators/Integrators.h"
#include "kernels/Skin.h"
#include "kernels/SpringForces.h"
#include "kernels/VolumeForces.h"

namespace fibremss {
namespace {
/// The smallest r of eq 5.1, as a share of the muscle's mean boundary radius. Shrinking at rest
/// leaves a sphere that touches a bone or another muscle as small as 3e-8 m (hip-pelvis' iliacus
/// over the femoral head); bounding the step by it holds every muscle's dt on `min_dt` and the
/// iliacus 3.5 % short of its volume (docs/performance.md, "What the step does for speed"). Any
/// share from 0.05 to 1 gives hip-pelvis the same bits; 0.01 does not lift every iteration.
constexpr btScalar kLeastStepRadiusShare = btScalar(0.1);

/// `settings`, or a laid-out copy where its spring blocks (the AVX2 spring kernel reads them,
/// and only the count of springs is checked) or its fans' byte offsets (the volume kernels read
/// them) are not those of its springs and fans: settings made or changed by hand.
std::shared_ptr<const MuscleSettings> laidOut(std::shared_ptr<const MuscleSettings> settings) {
  if (fastestSpringKernel() == SpringKernel::avx2) {
    SpringBlocks blocks = springBlocksFor(*settings);
    if (!(blocks == settings->springBlocks)) {
      auto copy = std::make_shared<MuscleSettings>(*settings);
      copy->springBlocks = std::move(blocks);
      settings = std::move(copy);
    }
  }
  checkFans(*settings, "MuscleSystem::addMuscle");
  if (std::vector<uint32_t> bytes = fanBytes(settings->fanParticles); bytes != settings->fanBytes) {
    auto copy = std::make_shared<MuscleSettings>(*settings);
    copy->fanBytes = std::move(bytes);
    settings = std::move(copy);
  }
  return settings;
}

/// Checks a muscle's particle arrays, mass, strain limit, bone and blend indices (against
/// `boneCount` handles), springs and boundary particles; InputError on the first fault.
void checkMuscleArrays(const MuscleSettings& s, size_t boneCount) {
  const char* source = "MuscleSystem::addMuscle";
  const std::string where = "muscle '" + s.name + "'";
  const size_t n = s.particleCount();
  if (s.radii.size() != n || s.flags.size() != n || s.fixedBone.size() != n ||
      s.nearestBone.size() != n)
    throw InputError(source, where, "particle arrays differ in size");
  if (!(s.particleMass > 0)) throw InputError(source, where, "particle mass must be > 0");
  if (!(s.strainLimit == 0 || s.strainLimit > 1))
    throw InputError(source, where, "strain limit must be 0 (none) or > 1");
  if (!(s.breakStretch == 0 || s.breakStretch > 1) ||
      (s.breakStretch > 0 && s.strainLimit > 0 && !(s.breakStretch < s.strainLimit)))
    throw InputError(source, where,
                     "break stretch must be 0 (none) or > 1 and below the strain limit");
  if (s.breakStretch > 0 && s.enclosedModulus > 0)
    throw InputError(source, where, "a muscle that tears cannot keep an enclosed-volume term");
  const int32_t limit = static_cast<int32_t>(boneCount);
  for (size_t i = 0; i < n; ++i) {
    if (s.fixedBone[i] >= limit || s.nearestBone[i] >= limit)
      throw InputError(source, where,
                       "particle " + std::to_string(i) + " refers to bone " +
                           std::to_string(std::max(s.fixedBone[i], s.nearestBone[i])) +
                           " but only " + std::to_string(boneCount) + " bone handles were given");
    if (s.isFixed(static_cast<uint32_t>(i)) && s.fixedBone[i] < 0)
      throw InputError(source, where, "fixed particle " + std::to_string(i) + " has no bone");
  }
  const bool blend = !s.blendWeight.empty();
  if (blend && (s.blendWeight.size() != n || s.blendBoneA.size() != n || s.blendBoneB.size() != n))
    throw InputError(source, where, "blend arrays differ in size from the particles");
  for (size_t i = 0; blend && i < n; ++i)
    if (s.blendBoneA[i] >= limit || s.blendBoneB[i] >= limit || !(s.blendWeight[i] >= 0) ||
        !(s.blendWeight[i] <= 1))
      throw InputError(source, where,
                       "particle " + std::to_string(i) +
                           " has a blend bone beyond the bone handles or a weight outside "
                           "[0, 1]");
  for (const Spring& spring : s.springs)
    if (spring.a >= n || spring.b >= n)
      throw InputError(source, where, "a spring refers to a particle beyond " + std::to_string(n));
  for (uint32_t p : s.boundaryParticles)
    if (p >= n) throw InputError(source, where, "boundary particle beyond the particles");
}

/// Checks that every handle is of a bone in `slots` with finite transforms (`call` names the
/// muscle in the error).
void checkMuscleBones(const Slots<BoneState>& slots, std::span<const BoneHandle> bones,
                      const std::string& call) {
  for (size_t b = 0; b < bones.size(); ++b) {
    const BoneState* bone = slots.find(bones[b]);
    if (!bone)
      throw InputError(call, "bones[" + std::to_string(b) + "]",
                       "expected a handle of a bone in this system; the handle is unknown or "
                       "its bone was removed");
    if (!finiteTransform(bone->current) || !finiteTransform(bone->target))
      throw InputError(call, "bones[" + std::to_string(b) + "]",
                       "bone '" + bone->settings->name +
                           "' has a non-finite transform; the muscle cannot be placed on it");
  }
}

/// A new muscle's state for `s` on `bones`: its per-particle arrays sized and zeroed, its free
/// particles listed; not yet placed.
std::unique_ptr<MuscleState> newMuscleState(const MuscleSettings& s,
                                            std::span<const BoneHandle> bones,
                                            const MuscleSystemDef& def) {
  const size_t n = s.particleCount();
  auto state = std::make_unique<MuscleState>();
  state->ParticleState::init(s, bones);
  state->GuardSnapshot::init(n);
  // Recovery follows the bones' distance fields: without them it has nothing to remember.
  state->ContactState::init(
      n, def.boneCollision == BoneCollision::Mesh || def.boneCollision == BoneCollision::SharpMesh,
      def.penetrationRecovery && def.boneCollision == BoneCollision::DistanceField);
  state->ResidualState::init(n, residualStiffness(s));
  return state;
}

/// A muscle's step bounds: the mean boundary radius, each particle's r of eq 5.1, the stable
/// time step and the springs' rest length sum.
void setStepBounds(const MuscleSettings& s, ParticleState& particles) {
  const size_t n = s.particleCount();
  double radiusSum = 0;
  for (uint32_t p : s.boundaryParticles) radiusSum += s.radii[p];
  if (!s.boundaryParticles.empty()) radiusSum /= static_cast<double>(s.boundaryParticles.size());
  if (!(radiusSum > 0)) {
    // No collision spheres: half the mean spring length bounds the motion per iteration.
    double lengthSum = 0;
    for (const Spring& spring : s.springs) lengthSum += spring.restLength;
    radiusSum = s.springs.empty() ? 1e-3 : 0.5 * lengthSum / static_cast<double>(s.springs.size());
  }
  particles.meanRadius = static_cast<btScalar>(radiusSum);
  particles.stepRadius.resize(n);
  const btScalar leastStepRadius = kLeastStepRadiusShare * particles.meanRadius;
  for (uint32_t i = 0; i < n; ++i)
    particles.stepRadius[i] = s.isBoundary(i) && s.radii[i] > 0
                                  ? std::max(s.radii[i], leastStepRadius)
                                  : particles.meanRadius;
  particles.stableTimeStep = particles.verletTimeStep = stableTimeStep(s);
  for (const Spring& spring : s.springs) particles.restLengthSum += spring.restLength;
}

/// Moves a muscle's free particles by uniform noise in ±def.initialNoise, seeded by the
/// system's seed and the count of muscles added (`added`).
void addInitialNoise(const MuscleSystemDef& def, uint32_t added, ParticleState& particles) {
  std::seed_seq seed{def.seed, added};
  std::mt19937 random(seed);
  std::uniform_real_distribution<btScalar> noise(-def.initialNoise, def.initialNoise);
  for (uint32_t i : particles.freeParticles) {
    const btVector3 offset(noise(random), noise(random), noise(random));
    particles.positions[i] += offset;
    particles.previous[i] = particles.positions[i];
  }
}

/// Candidate lists of the muscle just added at `addedSlot` (its `settings`, `particles` and
/// `trees`), sized from the pairs at the placed positions: with every bone, and every earlier
/// muscle with it (a reused slot's lists were another muscle's).
void addCandidateLists(Slots<MuscleState>& muscles, const Slots<BoneState>& bones,
                       const MuscleSettings& settings, const ParticleState& particles,
                       TreeState& trees, uint32_t addedSlot) {
  trees.boneLists.resize(bones.states.size());
  for (uint32_t slot : bones.order)
    trees.boneLists[slot] = boneList(settings, trees, *bones.states[slot]);
  trees.muscleLists.resize(muscles.states.size());
  const CollidingMuscle added{settings, particles, trees};
  for (uint32_t slot : muscles.order) {
    if (slot == addedSlot) continue;
    TreeState& earlier = *muscles.states[slot];
    earlier.muscleLists.resize(muscles.states.size());
    earlier.muscleLists[addedSlot] = muscleList(muscles.states[slot]->colliding(), added);
  }
}
}  // namespace

MuscleSystem::MuscleSystem(const MuscleSystemDef& def) : impl_(std::make_unique<Impl>()) {
  checkDefinition(def, "MuscleSystem");
  impl_->definition = def;
  impl_->stepSettings = def.stepSettings;
  impl_->prepareWorkers();
}

MuscleSystem::~MuscleSystem() = default;

void MuscleSystem::Impl::deform(const MuscleSettings& settings, ParticleState& particles) const {
  if (particles.surface.empty()) return;
  deformSurface(settings, particles.positions, particles.boneTransforms,
                definition.blendedPretransform, definition.pretransformBlend, particles.skin,
                particles.surface);
  if (!definition.surfaceContact) return;
  measureLayer(settings, particles.positions, particles.surface, particles.skin);
  btVector3 lower, upper;
  pointBounds(particles.surface, lower, upper);
  const btScalar reach =
      *std::max_element(particles.skin.layer.begin(), particles.skin.layer.end());
  const btVector3 margin(reach, reach, reach);
  for (uint32_t slot : bones.order) {
    const BoneState& bone = *bones.states[slot];
    liftOutOfBone(*bone.mesh, bone.current, particles.skin.layer, lower - margin, upper + margin,
                  particles.surface);
  }
}

BoneHandle MuscleSystem::addBone(std::shared_ptr<const BoneSettings> settings,
                                 const btCollisionObject* body) {
  if (!settings) throw InputError("MuscleSystem::addBone", "", "null settings");
  if (settings->sphereCentres.size() != settings->sphereRadii.size())
    throw InputError("MuscleSystem::addBone", "bone '" + settings->name + "'",
                     "different numbers of sphere centres and radii");
  const std::string call = "MuscleSystem::addBone: bone '" + settings->name + "'";
  checkPoints(settings->sphereCentres, call, "sphere centre");
  checkRadii(settings->sphereRadii, call);
  if (body && !finiteTransform(body->getWorldTransform()))
    throw InputError(call, "body", "expected a finite world transform within 1e6 m");
  auto state = std::make_unique<BoneState>();
  state->body = body;
  if (body) state->last = state->target = state->current = body->getWorldTransform();
  state->tree.build(settings->sphereCentres, settings->sphereRadii);
  state->tree.place(state->current, settings->sphereCentres, settings->sphereRadii);
  state->mesh = std::make_unique<const ContactMesh>(settings->mesh);
  const BoneCollision collision = impl_->definition.boneCollision;
  state->meshContact =
      (collision == BoneCollision::Mesh || collision == BoneCollision::SharpMesh) &&
      !settings->mesh.empty();
  state->sharpEdges = collision == BoneCollision::SharpMesh;
  if (impl_->definition.boneCollision == BoneCollision::DistanceField)
    state->field = std::make_unique<const BoneDistanceField>(
        state->mesh->distance, impl_->definition.distanceFieldCell,
        kDistanceFieldMargin * impl_->definition.distanceFieldCell);
  state->settings = std::move(settings);
  const BoneHandle handle = impl_->bones.add<BoneHandle>(std::move(state));
  const BoneState& bone = *impl_->bones.states[handle.index];
  impl_->bones.states[handle.index]->slot = handle.index;
  // Every muscle's candidate list for this slot starts over (a reused slot's is another bone's).
  for (uint32_t slot : impl_->muscles.order) {
    MuscleState& muscle = *impl_->muscles.states[slot];
    muscle.boneLists.resize(impl_->bones.states.size());
    muscle.boneLists[handle.index] = boneList(*muscle.settings, muscle, bone);
  }
  return handle;
}

void MuscleSystem::removeBone(BoneHandle bone) {
  const BoneState& removed = impl_->bone(bone);  // InputError for a stale or unknown handle
  for (uint32_t slot : impl_->muscles.order) {
    const MuscleState& muscle = *impl_->muscles.states[slot];
    for (const BoneHandle& attached : muscle.bones)
      if (attached.index == bone.index && attached.generation == bone.generation)
        throw InputError(
            "MuscleSystem::removeBone", "bone '" + removed.settings->name + "'",
            "muscle '" + muscle.settings->name + "' is attached to it; remove the muscle first");
  }
  impl_->bones.remove(bone);
}

void MuscleSystem::setBoneTransform(BoneHandle bone, const btTransform& transform) {
  impl_->bone(bone).target = transform;
}

btTransform MuscleSystem::boneTransform(BoneHandle bone) const {
  return impl_->bone(bone).current;
}

MuscleHandle MuscleSystem::addMuscle(std::shared_ptr<const MuscleSettings> settings,
                                     std::span<const BoneHandle> bones) {
  if (!settings) throw InputError("MuscleSystem::addMuscle", "", "null settings");
  settings = laidOut(std::move(settings));
  const MuscleSettings& s = *settings;
  checkMuscleArrays(s, bones.size());
  const std::string call = "MuscleSystem::addMuscle: muscle '" + s.name + "'";
  checkPoints(s.restPositions, call, "rest position");
  checkRadii(s.radii, call);
  checkMuscleBones(impl_->bones, bones, call);

  std::unique_ptr<MuscleState> state = newMuscleState(s, bones, impl_->definition);
  setStepBounds(s, *state);
  state->settings = settings;
  if (!impl_->blades.empty() && s.enclosedModulus > 0)
    throw InputError(call, "", "a muscle that blades cut cannot keep an enclosed-volume term");
  prepareTearing(state->settings, state->tear, !impl_->blades.empty());
  impl_->resolveBones(*state);
  impl_->placeAtBones(s, *state);
  ++impl_->musclesAdded;
  if (impl_->definition.initialNoise > 0)
    addInitialNoise(impl_->definition, impl_->musclesAdded, *state);
  // Before the tree: btDbvt's build breaks on non-finite or huge bounds.
  checkPoints(state->positions, call + " (placed on its bones, with initialNoise)", "particle");
  buildTree(*state->settings, *state, *state, impl_->definition.rebuildEveryStep);
  ensurePrepared(integratorFor(impl_->definition.integrator), s, *state, *state);
  const size_t skinCount = s.restSurface.vertices.size() * static_cast<size_t>(s.skinNeighbours);
  if (!s.restSurface.vertices.empty() && s.skinNeighbours > 0 &&
      s.skinParticles.size() == skinCount && s.skinWeights.size() == skinCount) {
    state->surface.resize(s.restSurface.vertices.size());
    prepareSkinFrames(s, state->skin);
    const MuscleSystemDef& def = impl_->definition;
    if (def.surfacePush && !state->meshVisits.empty())
      prepareSurfacePush(s, def.blendedPretransform, def.pretransformBlend, state->surfacePush);
    impl_->deform(s, *state);
  }

  size_t boundaryTotal = s.boundaryParticles.size();
  for (uint32_t slot : impl_->muscles.order)
    boundaryTotal += impl_->muscles.states[slot]->settings->boundaryParticles.size();
  impl_->contacts.ends.resize(std::max(impl_->contacts.ends.size(), 4 * boundaryTotal));
  MuscleState& added = *state;
  const MuscleHandle handle = impl_->muscles.add<MuscleHandle>(std::move(state));
  added.slot = handle.index;
  addCandidateLists(impl_->muscles, impl_->bones, s, added, added, added.slot);
  impl_->prepareWorkers();  // threads and their scratch start here, not in step()
  return handle;
}

void MuscleSystem::removeMuscle(MuscleHandle muscle) {
  impl_->muscle(muscle);  // InputError for a stale or unknown handle
  impl_->muscles.remove(muscle);
}

bool MuscleSystem::contains(MuscleHandle muscle) const {
  return impl_->muscles.find(muscle) != nullptr;
}

bool MuscleSystem::frozen(MuscleHandle muscle) const {
  return impl_->muscle(muscle).frozen;
}

void MuscleSystem::unfreeze(MuscleHandle muscle) {
  impl_->muscle(muscle).frozen = false;
}

MuscleFailures MuscleSystem::failures(MuscleHandle muscle) const {
  return impl_->muscle(muscle).failures;
}

MuscleTear MuscleSystem::tear(MuscleHandle muscle) const {
  const TearState& tear = impl_->muscle(muscle).tear;
  return {tear.brokenSprings, tear.brokenVolumeTerms, tear.cutSprings, tear.pieces};
}

BladeHandle MuscleSystem::addBlade(const btVector3& from, const btVector3& to,
                                   const btTransform& transform) {
  const std::string call = "MuscleSystem::addBlade";
  const btVector3 ends[] = {from, to};
  checkPoints(ends, call, "edge end");
  if (from == to) throw InputError(call, "", "the blade's edge has no length");
  if (!finiteTransform(transform))
    throw InputError(call, "transform", "expected a finite transform within 1e6 m");
  for (uint32_t slot : impl_->muscles.order)
    if (impl_->muscles.states[slot]->settings->enclosedModulus > 0)
      throw InputError(call, "", "a muscle that blades cut cannot keep an enclosed-volume term");
  for (uint32_t slot : impl_->muscles.order) {
    MuscleState& state = *impl_->muscles.states[slot];
    prepareTearing(state.settings, state.tear, true);
  }
  impl_->blades.push_back({from, to, transform, transform, transform});
  return {uint32_t(impl_->blades.size() - 1)};
}

void MuscleSystem::setBladeTransform(BladeHandle blade, const btTransform& transform) {
  if (blade.index >= impl_->blades.size())
    throw InputError("MuscleSystem::setBladeTransform", "", "unknown blade handle");
  if (!finiteTransform(transform))
    throw InputError("MuscleSystem::setBladeTransform", "transform",
                     "expected a finite transform within 1e6 m");
  impl_->blades[blade.index].target = transform;
}

void MuscleSystem::step() {
  impl_->guardedStep();
}

void MuscleSystem::setCancelFlag(const std::atomic<bool>* flag) {
  impl_->cancel = flag;
}

const StepStats& MuscleSystem::lastStep() const {
  return impl_->stats;
}
const MuscleSystemDef& MuscleSystem::definition() const {
  return impl_->definition;
}
const StepSettings& MuscleSystem::stepSettings() const {
  return impl_->stepSettings;
}
void MuscleSystem::setStepSettings(const StepSettings& settings) {
  checkStepSettings(settings, "MuscleSystem::setStepSettings");
  impl_->stepSettings = settings;
}

unsigned MuscleSystem::threads() const {
  return TaskPool::resolve(impl_->definition.threads, impl_->definition.scheduler);
}

ForceResidual MuscleSystem::forceResidual() {
  return impl_->residualOf(impl_->muscles.order).summary();
}

ForceResidual MuscleSystem::forceResidual(MuscleHandle muscle) {
  impl_->muscle(muscle);  // InputError for a stale handle
  const uint32_t slot = muscle.index;
  return impl_->residualOf(std::span(&slot, 1)).summary();
}

ForceResidual MuscleSystem::lastForceResidual(MuscleHandle muscle) const {
  impl_->muscle(muscle);  // InputError for a stale handle
  const std::vector<ResidualSums>& residuals = impl_->residuals;
  return muscle.index < residuals.size() ? residuals[muscle.index].summary() : ForceResidual{};
}

std::span<const btVector3> MuscleSystem::residualForces(MuscleHandle muscle) const {
  return impl_->muscle(muscle).residual;
}

std::span<const btVector3> MuscleSystem::positions(MuscleHandle muscle) const {
  return impl_->muscle(muscle).positions;
}

void MuscleSystem::setPositions(MuscleHandle muscle, std::span<const btVector3> positions) {
  MuscleState& state = impl_->muscle(muscle);
  const std::string call = "MuscleSystem::setPositions: muscle '" + state.settings->name + "'";
  if (positions.size() != state.positions.size())
    throw InputError(call, "positions",
                     "expected " + std::to_string(state.positions.size()) + " points, got " +
                         std::to_string(positions.size()));
  checkPoints(positions, call, "position");
  std::copy(positions.begin(), positions.end(), state.positions.begin());
  std::copy(positions.begin(), positions.end(), state.previous.begin());
  std::fill(state.velocities.begin(), state.velocities.end(), btVector3(0, 0, 0));
  forgetBoneSides(state);
  rebuildTree(*state.settings, state, state);
  impl_->deform(*state.settings, state);
}

const MuscleSettings& MuscleSystem::settings(MuscleHandle muscle) const {
  return *impl_->muscle(muscle).settings;
}

std::span<const btVector3> MuscleSystem::surface(MuscleHandle muscle) const {
  return impl_->muscle(muscle).surface;
}

std::vector<MuscleHandle> MuscleSystem::muscles() const {
  std::vector<MuscleHandle> handles;
  for (uint32_t slot : impl_->muscles.order)
    handles.push_back({slot, impl_->muscles.generations[slot]});
  return handles;
}

std::vector<BoneHandle> MuscleSystem::bones() const {
  std::vector<BoneHandle> handles;
  for (uint32_t slot : impl_->bones.order)
    handles.push_back({slot, impl_->bones.generations[slot]});
  return handles;
}

}  // namespace fibremss
