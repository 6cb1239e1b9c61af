#pragma once
// The FibreMSS solver: muscles (prepared MuscleSettings plus per-muscle state) and bones
// (BoneSettings plus a current transform), stepped as in method.md §5. It is independent of
// any world class; MuscleWorld and MuscleAction put it inside a Bullet world.
#include <LinearMath/btIDebugDraw.h>
#include <LinearMath/btTransform.h>
#include <LinearMath/btVector3.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "fibremss/MuscleSettings.h"
#include "fibremss/Parameters.h"
#include "fibremss/RigidContact.h"

class btCollisionObject;

namespace fibremss {

/// Identifies a muscle in a MuscleSystem; stale after removal (generation changes).
struct MuscleHandle {
  uint32_t index = UINT32_MAX;  ///< slot
  uint32_t generation = 0;      ///< slot generation at creation
  bool valid() const { return index != UINT32_MAX; }
};

/// Identifies a bone in a MuscleSystem.
struct BoneHandle {
  uint32_t index = UINT32_MAX;  ///< slot
  uint32_t generation = 0;      ///< slot generation at creation
  bool valid() const { return index != UINT32_MAX; }
};

/// Identifies a blade in a MuscleSystem (blades stay for the system's life).
struct BladeHandle {
  uint32_t index = UINT32_MAX;  ///< its number, in the order added
  bool valid() const { return index != UINT32_MAX; }
};

/// Milliseconds spent in each part of the last step, summed over its iterations.
struct StepTiming {
  double mss = 0;       ///< spring forces + volume term + dt + integration
  double volume = 0;    ///< the volume term, part of mss (its share of the force tasks' time)
  double muscleCd = 0;  ///< muscle–muscle collision detection
  double boneCd = 0;    ///< muscle–bone collision detection
  double response = 0;  ///< collision response
  double output = 0;    ///< fibres, surfaces
  double total = 0;     ///< the whole step
};

/// What tearing (MuscleSettings::breakStretch) did to a muscle.
struct MuscleTear {
  size_t brokenSprings = 0;      ///< springs broken so far
  size_t brokenVolumeTerms = 0;  ///< local volume terms broken or cut so far
  size_t cutSprings = 0;         ///< springs blades cut so far (MuscleSystem::addBlade)
  /// Pieces: components of its unbroken springs among the particles that had a spring at rest
  /// (1 for a muscle that does not tear).
  size_t pieces = 1;
};

/// What the last step did.
struct StepStats {
  int iterations = 0;             ///< iterations run
  btScalar lastTimeStep = 0;      ///< dt of the last iteration [s]
  double simulatedTime = 0;       ///< time the step advanced: Σ dt over its iterations [s]
  btScalar meanDisplacement = 0;  ///< mean free-particle displacement in the last iteration [m]
  size_t contacts = 0;            ///< sphere pairs found overlapping in the last iteration
  size_t candidates = 0;          ///< sphere pairs tested exactly in the last iteration
  /// Candidate lists or contact records that overflowed their capacity in this step (each pair fell
  /// back to a direct tree traversal: slower, the same contacts).
  size_t candidateOverflows = 0;
  btScalar springDeviationRatio = 0;  ///< Σ|l−L0| / ΣL0 over all muscles, last iteration
  StepTiming timing;                  ///< per-part wall time
  bool nan = false;                   ///< a NaN or inf appeared
  bool exploded = false;              ///< a spring beyond 3× its rest length in the last iteration
  size_t overstretchedSprings = 0;    ///< springs beyond 3× their rest length, last iteration

  // The numerical guard (MuscleSystemDef::onFailure): what it found and did in this step.
  uint64_t step = 0;          ///< index of this step in the system (0: the first)
  bool failed = false;        ///< the state is left failed (Report: a muscle has NaN/inf or burst)
  bool rolledBack = false;    ///< an attempt failed and the state went back to the step's start
  int retries = 0;            ///< attempts repeated with a smaller dt (Retry)
  MuscleHandle failedMuscle;  ///< the first muscle that failed in this step (invalid: none)
  bool failedNan = false;     ///< that muscle had NaN/inf (else: exploded springs)
  size_t newlyFrozen = 0;     ///< muscles this step froze at their last good state
  size_t frozenMuscles = 0;   ///< muscles frozen in the system after this step
  /// Bones whose target transform was NaN/inf (setBoneTransform, or a host's body): each held
  /// its last transform for this step, and the step reports nan, failed and failedNan.
  size_t heldBones = 0;

  // Bones closing on a muscle (pinch): particles two bones press from opposite sides.
  size_t trappedParticles = 0;  ///< such particles still caught in the last iteration
  /// Muscles with trapped particles, or with a burst spring whose ends two bones pushed in the
  /// step and stretched by moving apart; springs such a muscle burst do not fail the step (unless
  /// it has NaN or grew beyond twice its rest size): the bones tore it and no smaller dt opens the
  /// gap, so the guard keeps that state.
  size_t trappedMuscles = 0;

  /// The step stopped early at an iteration's end because the cancel flag was set
  /// (MuscleSystem::setCancelFlag): the bones jumped to their targets, the muscles stay where that
  /// iteration left them (at the step's start when the attempt had failed), with no retry.
  bool interrupted = false;
  /// step(duration) advanced less than its duration: that needed more than 16384 iterations of
  /// the muscles' stable dt, which the step runs instead (a bounded step; simulatedTime says how
  /// far it got).
  bool shortened = false;
};

/// How often the numerical guard found one muscle failing, over the system's life: each count is
/// one attempt of a step (a first try or a retry) that the muscle failed.
struct MuscleFailures {
  int attempts = 0;  ///< attempts it failed (NaN/inf or burst springs)
  int nan = 0;       ///< of them with NaN/inf (the others: springs beyond 3× their rest length)
};

/// How far the particles are from a static equilibrium of the model (MuscleSystem::forceResidual):
/// the net force on each free particle from everything the model's energy contains (springs, the
/// volume terms, gravity and external forces; not damping or inertia), with the reactions of the
/// last collision response's frictionless contacts added: a bone contact pushes its particle out
/// along the bone's push with any force ≥ 0; a contact of two muscles' particles gives them equal
/// and opposite forces along the pair's normal (Newton's third law), so two muscles that press
/// into each other with unequal forces keep the difference. The reactions (≥ 0) are those that
/// leave the smallest Σ (|r_i|/k_i)², found by a fixed number of Gauss–Seidel sweeps: an upper
/// bound on the best set's residual. Attached particles are not counted.
struct ForceResidual {
  size_t particles = 0;         ///< free particles counted
  size_t contactParticles = 0;  ///< of them pushed by the last collision response
  double rmsForce = 0;          ///< RMS over the particles of |r_i| [N]
  double maxForce = 0;          ///< largest |r_i| [N]
  /// RMS of |r_i| / k_i [m]: the move that cancels r_i of a particle alone, its neighbours held,
  /// k_i its stiffness averaged over directions (a third of the trace of its diagonal block of the
  /// energy's Hessian at rest: Σ k/3 of its springs plus the volume terms'); one Jacobi step.
  double rmsDisplacement = 0;
  double maxDisplacement = 0;  ///< largest |r_i| / k_i [m]
};

/// What debugDraw draws (bit flags).
enum DebugDrawFlag : int {
  kDrawParticles = 1,    ///< boundary particle spheres
  kDrawSprings = 2,      ///< springs
  kDrawFibres = 4,       ///< fibres
  kDrawBoneSpheres = 8,  ///< bone spheres
  kDrawContacts = 16,    ///< colliding pairs of the last iteration
};

class MuscleSystem {
 public:
  /// InputError for a definition no step can run with (dt not finite > 0, no iterations, ...).
  explicit MuscleSystem(const MuscleSystemDef& def = defaultMuscleSystemDef());
  ~MuscleSystem();
  MuscleSystem(const MuscleSystem&) = delete;
  MuscleSystem& operator=(const MuscleSystem&) = delete;

  /// Adds a bone. With `body`, its world transform is read at every step (a kinematic
  /// btRigidBody or any collision object whose transform maps rest to current coordinates);
  /// without, setBoneTransform moves it. InputError for spheres or a body transform that are
  /// not finite or lie beyond kMaxCoordinate.
  BoneHandle addBone(std::shared_ptr<const BoneSettings> settings,
                     const btCollisionObject* body = nullptr);
  /// InputError for a stale or unknown handle, and while a muscle is attached to the bone.
  void removeBone(BoneHandle bone);
  /// Target transform (rest → current) reached at the end of the next step. A non-finite one is
  /// not followed: the bone holds its transform and the step reports it (StepStats::heldBones).
  void setBoneTransform(BoneHandle bone, const btTransform& transform);
  btTransform boneTransform(BoneHandle bone) const;

  /// Adds a muscle; `bones[i]` is the handle of the settings' bone index i (fixedBone,
  /// nearestBone). Its particles start at their rest positions moved by their nearest bone.
  /// InputError for a stale or unknown bone handle, a bone whose transform is not finite, and
  /// particles (as placed, with initialNoise) or radii not finite or beyond kMaxCoordinate.
  MuscleHandle addMuscle(std::shared_ptr<const MuscleSettings> settings,
                         std::span<const BoneHandle> bones);
  void removeMuscle(MuscleHandle muscle);  ///< InputError for a stale or unknown handle
  bool contains(MuscleHandle muscle) const;
  /// Whether the numerical guard stopped this muscle (it keeps its last good state).
  bool frozen(MuscleHandle muscle) const;
  /// Lets a frozen muscle move again from the state it was frozen in.
  void unfreeze(MuscleHandle muscle);
  /// Step attempts the numerical guard found this muscle failing (a rollback, a retry or a
  /// freeze followed each, except with FailurePolicy::Report).
  MuscleFailures failures(MuscleHandle muscle) const;
  /// What tearing (MuscleSettings::breakStretch) and blades broke of this muscle so far and its
  /// pieces.
  MuscleTear tear(MuscleHandle muscle) const;

  /// Adds a blade: the straight edge `from`–`to` (blade frame [m]) at `transform`. After each
  /// kept step, every spring and local volume term of every muscle whose segment crosses the
  /// surface the edge swept in that step (from its transform at the last step's end to its
  /// target, two triangles) is cut for good, as tearing breaks them (docs/decisions.md,
  /// "Cutting"); particles are neither split nor removed, fixed ones stay fixed. Allocates (each
  /// muscle its own settings). InputError for points or a transform that are not finite, an
  /// edge of no length, and a muscle with an enclosed-volume term.
  BladeHandle addBlade(const btVector3& from, const btVector3& to,
                       const btTransform& transform = btTransform::getIdentity());
  /// The transform the blade reaches at the end of the next step (its edge sweeps there from
  /// where the last step left it). InputError for an unknown handle or a non-finite transform.
  void setBladeTransform(BladeHandle blade, const btTransform& transform);

  /// One simulation step: bones move from their last to their target transforms split over
  /// the iterations; pre-transform; iterations of forces, integration, collision detection and
  /// response until the stop rule says; then output (fibres, surfaces). A step that produces
  /// NaN/inf or explodes is handled as definition().onFailure says (StepStats reports it); it
  /// never throws.
  void step();
  /// A step that advances the muscles by exactly `duration` of simulated time [s]: k =
  /// max(iterations, ⌈duration / dt⌉) iterations of duration/k, dt the smaller of timeStep and
  /// every muscle's stable dt (springs and volume term) (fixed, whatever the stop
  /// rule and adaptiveTimeStep say), bones moving over all of them (MuscleTime::Dynamic). A
  /// duration beyond 16384 such dt is cut short to that (StepStats::shortened). InputError for a
  /// duration that is not finite and > 0.
  void step(btScalar duration);
  /// Gathers the local region stepLocal advances: in every muscle the free particles within
  /// `radius` [m] of `centre` [m], the springs and local volume terms that reach them, and the
  /// ring, their other particles, held where they are. Gathered from the particles as they are
  /// now, kept until the next call; allocates only the first time (index arrays as large as the
  /// muscles). InputError for a centre or radius not finite, or a radius < 0.
  void setLocalRegion(const btVector3& centre, btScalar radius);
  /// step(duration) in which only the local region's particles move (setLocalRegion; none
  /// gathered: none moves): per muscle (one task each) the region's springs and volume terms on
  /// the scalar kernel, the muscle's enclosed volume, Verlet's integration (whatever the
  /// definition's integrator, in as many iterations as Verlet's stable time step needs; after a
  /// whole step of another integrator the region starts at rest), the pushes of the bones on
  /// the region; then the contact bodies, which the caller keeps inside the region (HapticTool
  /// does). Every other particle keeps its position, the muscles' surfaces stay as the last
  /// step left them, and muscle pairs do not collide. A step in which a bone moves, or with
  /// rebuildEveryStep, runs as step(duration). The numerical guard and the contact bodies'
  /// results as step(duration); no allocation (but a muscle's first gathering). InputError for
  /// a duration that is not finite and > 0.
  void stepLocal(btScalar duration);
  /// A flag the steps poll after every iteration (null: none, the default): once it reads true,
  /// the running step ends there and reports StepStats::interrupted, so a long step (a large
  /// iteration cap, the guard's retries) stops within an iteration. Meant to be set from a signal
  /// handler (Ctrl-C, SIGTERM) or another thread; the system keeps the pointer until the next
  /// call, and never writes the flag.
  void setCancelFlag(const std::atomic<bool>* flag);

  /// The rigid bodies the muscles collide with from the next step on (fibremss/RigidContact.h):
  /// shapes convex, compound or static planes (others never touch); pose, velocities and mass
  /// read at each step's start. The system keeps the pointers until the next call: clear it
  /// (setContactBodies({})) before deleting a body. MuscleWorld and MuscleAction set them from
  /// their world before every step. InputError for a null body. Allocates (not step()).
  void setContactBodies(std::span<const btCollisionObject* const> bodies);
  /// What `body` received from the muscles in the last step (zero when it was no contact body);
  /// the caller applies the impulses to it (MuscleWorld and MuscleAction do).
  BodyContact bodyContact(const btCollisionObject* body) const;
  /// The haptic query (seed 003 §5.2): the force and torque (about `transform`'s origin, a
  /// btRigidBody's centre of mass) the muscles exert on `body` if it stood at `transform`: the
  /// last step's mean reaction plus, for every free boundary particle sphere its shape overlaps
  /// there, Hooke's law with the particle's local stiffness (Σ k/3 of its springs) along the
  /// contact normal. At the pose the last step ended with that term is about 0; as a tool moves
  /// in between steps it follows at once. Reads the particles as of the last step; no allocation;
  /// not concurrently with step(). InputError for a transform with NaN or inf.
  ContactWrench contactWrench(const btCollisionObject& body, const btTransform& transform) const;
  /// An external force [N] held on one particle of a muscle (added to its spring forces every
  /// iteration, until changed or cleared; fixed particles ignore it; Pbd and Xpbd too, which
  /// predict without forces). InputError for a particle index beyond the muscle or a non-finite
  /// force. Allocates on the muscle's first one.
  void setExternalForce(MuscleHandle muscle, uint32_t particle, const btVector3& force);
  /// Removes every external force of the muscle (MuscleSystemDef::gravity stays).
  void clearExternalForces(MuscleHandle muscle);

  /// The force residual of every muscle together at its current particles (ForceResidual), as
  /// of the last step; each muscle's per-particle residual kept for residualForces. Bit-identical
  /// for any thread count; no allocation; not concurrently with step().
  ForceResidual forceResidual();
  /// The force residual of one muscle (ForceResidual). InputError for a stale or unknown handle.
  ForceResidual forceResidual(MuscleHandle muscle);
  /// The muscle's share of the last forceResidual call that covered it, without computing it
  /// again (no particles before any call). InputError for a stale or unknown handle.
  ForceResidual lastForceResidual(MuscleHandle muscle) const;
  /// The per-particle residual r_i [N] of the last forceResidual call that covered the muscle
  /// (zero for attached particles; all zero before any call).
  std::span<const btVector3> residualForces(MuscleHandle muscle) const;

  const StepStats& lastStep() const;
  /// What the system was built with (its stepSettings those it started with).
  const MuscleSystemDef& definition() const;
  /// The settings the next step runs with.
  const StepSettings& stepSettings() const;
  /// Settings for the steps from the next on. InputError for settings no step can run with (dt
  /// not finite > 0, no iterations, ...); the previous settings are then kept.
  void setStepSettings(const StepSettings& settings);
  /// Threads a step computes with: definition().threads, or the machine's hardware threads for 0;
  /// with a host scheduler (MuscleSystemDef::scheduler) its workerCount.
  unsigned threads() const;

  std::span<const btVector3> positions(MuscleHandle muscle) const;  ///< current particles
  /// Moves a muscle's particles to `positions` [m], one per particle, at rest there (x(t−dt) = x,
  /// velocities zero), and its surface with them; fixed particles return to their bones at the
  /// next step. InputError for a stale handle, another count, or a point not finite or beyond
  /// kMaxCoordinate. Not concurrently with step().
  void setPositions(MuscleHandle muscle, std::span<const btVector3> positions);
  const MuscleSettings& settings(MuscleHandle muscle) const;
  /// The deformed surface vertices (method.md §7), as of the last step.
  std::span<const btVector3> surface(MuscleHandle muscle) const;
  /// Handles of all muscles / bones currently in the system, in insertion order.
  std::vector<MuscleHandle> muscles() const;
  std::vector<BoneHandle> bones() const;

  /// Draws particles, springs, fibres, bone spheres, contacts (DebugDrawFlag bits).
  void debugDraw(btIDebugDraw* drawer, int flags = kDrawParticles | kDrawBoneSpheres) const;

 private:
  friend struct MuscleSystemAccess;  ///< the kernel benchmarks reach the state (internal)
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace fibremss
