#pragma once
// Per-body state of a MuscleSystem (internal): everything a step changes, structure-of-arrays,
// allocated once when the body is added. The immutable settings are shared, never copied.
#include <LinearMath/btTransform.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "InteractionState.h"
#include "SurfacePushState.h"
#include "TearState.h"
#include "fibremss/MuscleSettings.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Pretransform.h"
#include "geometry/BoneDistanceField.h"
#include "geometry/CollisionTrees.h"
#include "geometry/SurfaceContact.h"
#include "kernels/ForceChunks.h"
#include "kernels/Skin.h"

class btCollisionObject;

namespace fibremss {

/// A bone: settings, the transforms of one step and its sphere tree (static topology, bounds
/// placed at the current transform).
struct BoneState {
  std::shared_ptr<const BoneSettings> settings;   ///< shared, immutable
  const btCollisionObject* body = nullptr;        ///< transform source, or null (setBoneTransform)
  btTransform last = btTransform::getIdentity();  ///< at the end of the previous step
  btTransform target = btTransform::getIdentity();   ///< to reach at the end of this step
  btTransform current = btTransform::getIdentity();  ///< in the running iteration
  btTransform delta = btTransform::getIdentity();    ///< current · previous-iteration⁻¹
  bool moving = false;  ///< delta differs from the identity in this iteration
  /// The target of this step was not finite (a host's body gone NaN, a NaN setBoneTransform):
  /// the bone holds its transform for the step, which reports NaN.
  bool heldNonFinite = false;
  BoneSphereTree tree;  ///< bone spheres, static topology, bounds placed in world space
  uint32_t slot = 0;    ///< the bone's slot in its system (names it in per-particle memory)
  /// Signed distance field of the mesh, bone frame (BoneCollision::DistanceField), or null.
  std::unique_ptr<const BoneDistanceField> field;
  /// The true mesh as the surface-contact stage queries it (liftOutOfBone), bone frame.
  std::unique_ptr<const ContactMesh> mesh;
  /// The spheres' pairs push against `mesh` (BoneCollision::Mesh or SharpMesh, and a mesh).
  bool meshContact = false;
  /// The pushes against `mesh` keep its edges sharp (BoneCollision::SharpMesh).
  bool sharpEdges = false;
  btTransform goodLast = btTransform::getIdentity();     ///< `last` at the step's start (guard)
  btTransform goodCurrent = btTransform::getIdentity();  ///< `current` at the step's start (guard)
};

/// A muscle's particles as every iteration reads and writes them (the hot part), structure of
/// arrays, size particleCount() unless said otherwise.
struct ParticleState {
  std::vector<btVector3> positions;     ///< x(t) [m]
  std::vector<btVector3> previous;      ///< x(t−dt) [m]
  std::vector<btVector3> velocities;    ///< for velocity-based integrators [m/s]
  std::vector<btVector3> forces;        ///< spring forces of this iteration [N]
  std::vector<btScalar> stepRadius;     ///< eq 5.1's r [m]: own, ≥ meanRadius/10; inner: mean
  std::vector<uint32_t> freeParticles;  ///< indices of particles that are not fixed
  btScalar stableTimeStep = 0;          ///< largest dt for which its integrator stays stable [s]
  btScalar verletTimeStep = 0;          ///< largest dt for which damped Verlet stays stable [s]
  btScalar meanRadius = 0;              ///< mean boundary radius [m]
  double restLengthSum = 0;             ///< Σ L0 over the springs [m]
  std::vector<BoneHandle> bones;        ///< system handle of the settings' bone index i
  std::vector<int32_t> boneSlots;  ///< bones[i] resolved to a bone slot for this step (-1: gone)
  std::vector<btTransform> boneTransforms;  ///< current transform of bones[i] (identity: gone)
  std::vector<btTransform> boneDeltas;      ///< motion of bones[i] in this iteration (identity)
  /// boneDeltas as dual quaternions, for PretransformBlend::DualQuaternion (rotation; [m])
  std::vector<DualQuaternion> boneDualDeltas;
  bool bonesMoving = false;        ///< some bone of the muscle moves in this iteration
  std::vector<btVector3> surface;  ///< deformed surface vertices (output)
  SkinFrames skin;                 ///< local frames of the surface (empty: no surface)

  /// Sized for `settings`' particles on the bones of `handles` (their slots unresolved):
  /// velocities and forces zero, every bone at the identity, the free particles listed; positions
  /// still to be placed.
  void init(const MuscleSettings& settings, std::span<const BoneHandle> handles);
};

/// A muscle's contact scratch: the pushes of this iteration's collision pairs and what the
/// response remembers between iterations.
struct ContactState {
  std::vector<btVector3> pushes;     ///< collision pushes accumulated this iteration [m]
  std::vector<uint32_t> pushCounts;  ///< pairs that pushed each particle this iteration
  /// 1 for a particle the last response pushed, until the projective integrator reads it (it
  /// clears every flag it reads; other integrators leave them set) [flag].
  std::vector<uint8_t> pushedLast;

  /// Penetration recovery (seed 001 eq 1), empty when off: the bone slot whose field last saw
  /// the particle near (-1: none) and the unit direction out of that bone there (bone frame).
  std::vector<int32_t> sideBones;
  std::vector<btVector3> boneSides;  ///< see sideBones
  std::vector<uint32_t> sideStamps;  ///< contactRound when the side was last seen (else stale)
  uint32_t contactRound = 0;         ///< responses applied so far (applyPushes)
  /// BoneCollision::Mesh and SharpMesh: the boneVisit in which each particle was last pushed
  /// against a bone's true mesh (one closest-point query per particle, bone and iteration), empty
  /// when off.
  std::vector<uint32_t> meshVisits;
  uint32_t boneVisit = 0;  ///< collideMuscleBone calls on the muscle so far (meshVisits)
  /// MuscleSystemDef::surfacePush: the skinned surface pushed out of the bones' true meshes
  /// (empty when off).
  SurfacePushState surfacePush;

  /// Pinch (CollisionPairs.cpp): this iteration's bone pushes of each particle split into the
  /// first bone's and the others', to tell a particle two bones push opposite ways. Slot of the
  /// first bone that pushed the particle in this iteration (-1: none).
  std::vector<int32_t> pinchBones;
  std::vector<btVector3> firstBonePushes;  ///< Σ pushes of that bone this iteration [m]
  std::vector<btVector3> otherBonePushes;  ///< Σ pushes of every other bone this iteration [m]
  size_t pinched = 0;        ///< particles caught between two bones in the last response
  size_t pinchedInStep = 0;  ///< most particles caught in one response of this step's attempt
  /// Per particle, the bone (slot) that pushed it in the latest response of this step's attempt
  /// that a bone pushed it in (of two in one response, the first: pinchBones; -1: none; cleared
  /// as the attempt begins): a burst spring whose ends two bones pushed was torn by them.
  std::vector<int32_t> stepBones;
  /// Burst springs whose ends two different bones pushed and moved apart by at least their
  /// growth, as the guard's check of this step's attempt found them (0 until it checks; cleared
  /// as the attempt begins).
  size_t spannedInStep = 0;
  /// Caught in some step since the bones last stood still: the bones that tore it may still be
  /// carrying its torn halves apart (the guard's) [flag].
  bool trapHeld = false;
  size_t tornSprings = 0;  ///< most springs found burst while it was trapped (the guard's)

  /// Whether bones caught it in this step's attempt: a particle pinched, or springs kept as torn
  /// by two bones (spannedInStep).
  bool caughtInStep() const { return pinchedInStep > 0 || spannedInStep > 0; }

  /// Sized for `n` particles with nothing pushed; the true-mesh visits with `meshContact`, the
  /// sides of penetration recovery with `recovery`.
  void init(size_t n, bool meshContact, bool recovery);
};

/// A muscle's sphere tree and the candidate lists of its leaf pairs (CollisionPairs.h).
struct TreeState {
  SphereTree tree;  ///< boundary particle spheres, world frame (refitTree)
  /// Verlet skin of the tree (refitTree): leaves are the spheres around treeSnapshot grown by
  /// treeReach, treeSkin/2 or 0 while the muscle moves faster than that every iteration [m].
  btScalar treeSkin = 0;
  btScalar treeReach = 0;    ///< what the tree's leaves are grown by; refit past it [m]
  bool refitStreak = false;  ///< the last refitTree call refitted
  btScalar treeMotion = 0;   ///< largest squared move of a particle per iteration, last refit [m²]
  /// followBones moved the particles, and their bones have yet to arrive (refitTree may skip the
  /// snapshot of a tight tree).
  bool treeFollowed = false;
  uint32_t snapshotSkips = 0;  ///< tight refits without the snapshot since it was taken
  /// Positions of the boundary particles at the last refit (by particle; inner ones unused) [m].
  std::vector<btVector3> treeSnapshot;
  /// Leaf pairs with each later-added muscle, by its slot (collideMuscles; empty when unlisted).
  std::vector<CandidateList> muscleLists;
  std::vector<CandidateList> boneLists;  ///< leaf pairs with each bone, by bone slot
  size_t candidateOverflows = 0;  ///< listings or pair contact records that overflowed, unsummed
};

/// A muscle as the stages that test its spheres against others read it (CollisionPairs.h,
/// BodyContacts.h): its settings, positions and sphere tree (MuscleState::colliding).
struct CollidingMuscle {
  const MuscleSettings& settings;  ///< radii [m], fixed and boundary particles
  const ParticleState& particles;  ///< positions [m], mean radius [m]
  const TreeState& trees;          ///< sphere tree, snapshot [m] and reach [m]
};

/// Scratch an integrator keeps per muscle (Jacobian structure, CG vectors, stage buffers);
/// made by TimeIntegrator::prepare, never state a rollback must restore.
struct IntegratorWorkspace {
  virtual ~IntegratorWorkspace() = default;
};

/// The integrator a muscle is prepared for and its scratch (TimeIntegrator::prepare).
struct IntegratorState {
  std::unique_ptr<IntegratorWorkspace> workspace;  ///< the integrator's scratch, or null
  Integrator preparedFor = Integrator::Verlet;     ///< the integrator `workspace` was made for
  bool prepared = false;                           ///< workspace made for `preparedFor`

  /// Whether its steps take Verlet's centred damping (prepared for Verlet; adaptiveTimeStep).
  bool centredDamping() const { return preparedFor == Integrator::Verlet; }
};

/// A muscle's forces pass in chunks (ForceChunks.h): one task per chunk; the task that finishes
/// the muscle's last chunk adds the chunks' buffers to `forces` in chunk order.
struct ChunkState {
  std::vector<ForceChunk> forceChunks;  ///< at least one; chunk 0 sums into ParticleState::forces
  size_t chunkWork = 0;                 ///< the work per chunk forceChunks was made for
  /// The forces of chunks c ≥ 1 [N]: chunk c's particle i at chunkForces[chunkBase[c] + i] for
  /// i in its [lower, upper), the windows one after the other (a window may start later than
  /// the last ended, never earlier than its chunk's lower: the base is never negative). Zero
  /// between passes: finishForces moves each window out (moveForces), no chunk clears its own.
  std::vector<btVector3> chunkForces;
  std::vector<size_t> chunkBase;                ///< see chunkForces (chunk 0: unused)
  std::vector<SpringForceResult> chunkSprings;  ///< what each chunk's springs measured
  std::vector<double> chunkMs;                  ///< thread time of each chunk's task [ms]
  std::vector<double> chunkVolumeMs;            ///< thread time of each chunk's volume term [ms]
  std::atomic<size_t> chunksLeft{0};            ///< chunks of the running pass not yet done
};

/// The last good state (MuscleSystemGuard.cpp): saved at the start of a step, same sizes.
struct GuardSnapshot {
  std::vector<btVector3> goodPositions;   ///< positions at the start of the step [m]
  std::vector<btVector3> goodPrevious;    ///< previous at the start of the step [m]
  std::vector<btVector3> goodVelocities;  ///< velocities at the start of the step [m/s]

  /// Sized for `n` particles (saved at each step's start).
  void init(size_t n);
};

/// What the force residual keeps per particle (Residual.h), size particleCount().
struct ResidualState {
  std::vector<btVector3> residual;  ///< the last forceResidual's r_i [N]
  /// k_i of the force residual's equivalent displacement (residualStiffness) [N/m]
  std::vector<btScalar> residualStiffness;
  /// The push the last recorded response (recordPushes) gave each particle [m], valid where
  /// pushRounds[i] == contactRound (that response was the last and pushed it).
  std::vector<btVector3> lastPushes;
  std::vector<uint32_t> pushRounds;  ///< contactRound of each particle's last push (0: none)
  /// The bones' share of lastPushes (the sum of every bone's push on the particle) [m], valid
  /// where lastPushes is; zero for a particle only muscles pushed.
  std::vector<btVector3> lastBonePushes;

  /// Sized for `n` particles with no residual and no push recorded, with the particles' `stiffness`
  /// (residualStiffness) [N/m].
  void init(size_t n, std::vector<btScalar> stiffness);
};

/// A muscle as an integrator's step reads and writes it (Integrators.h): its settings and the
/// parts of its state the integrators use (MuscleState::integrated).
struct IntegratedMuscle {
  const MuscleSettings& settings;  ///< springs, particle mass [kg], damping [N·s/m]
  ParticleState& particles;  ///< positions [m], previous [m], velocities [m/s], forces [N], bones
  /// pushedLast, which the projective integrator reads and clears; contactRound
  ContactState& contact;
  const ResidualState& residual;        ///< the pushes of the last response [m] (contactNormal)
  const InteractionState& interaction;  ///< forces held on particles [N]
  IntegratorWorkspace* workspace;       ///< the integrator's scratch, or null
  /// The running step is a duration step (MuscleSystem::step(duration)): the contacts move with
  /// time, and the projective integrator holds a pushed particle only until an iteration without
  /// a push (kMovingContactHold) [flag].
  bool movingContacts;
};

/// The local region of MuscleSystem::stepLocal in one muscle (MuscleSystem::setLocalRegion):
/// the particles a local step moves and the springs and local volume terms whose forces it takes.
/// Sized to the muscle's counts at its first gathering, so that gathering again does not allocate.
struct RegionState {
  std::vector<uint32_t> regionParticles;  ///< free particles within the region's radius
  /// Particles a local step's forces reach: the region's, then the ring (the other ends of their
  /// springs and volume terms, held where they are)
  std::vector<uint32_t> regionReach;
  std::vector<uint32_t> regionSprings;  ///< springs with an end in the region, ascending
  std::vector<uint32_t> regionFans;     ///< local volume fans with a particle in the region
  /// Per particle: kInRegion, kInRing or 0 (sized at the first gathering) [flag]
  std::vector<uint8_t> regionMark;
  const MuscleSettings* regionSettings = nullptr;  ///< the settings gathered from (null: none)
};

/// RegionState::regionMark of a particle a local step moves.
constexpr uint8_t kInRegion = 1;
/// RegionState::regionMark of a particle a local step holds whose forces it takes.
constexpr uint8_t kInRing = 2;

/// A muscle: settings and slot, and the state a step changes in nine parts (stages that need
/// one part can take it alone). Solver settings are not here: the step passes them to the stages.
struct MuscleState : ParticleState,
                     ChunkState,
                     ContactState,
                     TreeState,
                     GuardSnapshot,
                     InteractionState,
                     ResidualState,
                     RegionState,
                     IntegratorState {
  std::shared_ptr<const MuscleSettings> settings;  ///< shared, immutable
  uint32_t slot = 0;        ///< the muscle's slot in its system (names it in pair lists)
  bool frozen = false;      ///< stopped by the numerical guard: skipped by every part of a step
  MuscleFailures failures;  ///< attempts of steps the guard found this muscle failing
  TearState tear;           ///< its own settings and pieces when it tears (TearState.h)

  /// The muscle as an integrator steps it in a step whose contacts move with time or not
  /// (IntegratedMuscle::movingContacts).
  IntegratedMuscle integrated(bool movingContacts) {
    return {*settings, *this, *this, *this, *this, workspace.get(), movingContacts};
  }
  /// The muscle as the sphere tests read it.
  CollidingMuscle colliding() const { return {*settings, *this, *this}; }
};

}  // namespace fibremss
