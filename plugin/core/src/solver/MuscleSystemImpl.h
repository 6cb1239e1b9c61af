#pragma once
// MuscleSystem's private state (internal): body slots, scratch buffers, stats, and the step
// pipeline of method.md §5 (MuscleSystemStep.cpp).
#include <algorithm>
#include <array>
#include <chrono>
#include <initializer_list>
#include <memory>
#include <string>
#include <vector>

#include "Cutting.h"
#include "collision/CollisionPairs.h"
#include "contact/BodyContacts.h"
#include "dynamics/Residual.h"
#include "fibremss/Error.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/TaskPool.h"
#include "kernels/SpringForces.h"
#include "state/MuscleState.h"

namespace fibremss {

class TimeIntegrator;

/// Slots with generations (Box2D style ids): a removed slot is reused with a new generation.
template <typename State>
struct Slots {
  std::vector<std::unique_ptr<State>> states;  ///< null: free slot
  std::vector<uint32_t> generations;           ///< generation of each slot
  std::vector<uint32_t> order;                 ///< occupied slots in insertion order

  template <typename Handle>
  Handle add(std::unique_ptr<State> state) {
    uint32_t slot = 0;
    while (slot < states.size() && states[slot]) ++slot;
    if (slot == states.size()) {
      states.emplace_back();
      generations.push_back(0);
    }
    states[slot] = std::move(state);
    order.push_back(slot);
    return Handle{slot, generations[slot]};
  }
  template <typename Handle>
  State* find(Handle handle) const {
    if (handle.index >= states.size() || generations[handle.index] != handle.generation)
      return nullptr;
    return states[handle.index].get();
  }
  template <typename Handle>
  void remove(Handle handle) {
    if (!find(handle)) return;
    states[handle.index].reset();
    ++generations[handle.index];
    order.erase(std::find(order.begin(), order.end(), handle.index));
  }
};

/// Scratch of one thread of the step: what a task may write that is not its muscle's.
struct ThreadScratch {
  TreeTraversalStack stack;  ///< traversal stack of the tree queries
  ContactLog contacts;       ///< contacts this thread found in the running phase
};

/// What the per-muscle tasks of one iteration measured, reduced in insertion order afterwards
/// so that the sums do not depend on which thread ran which muscle.
struct MuscleIterationResult {
  SpringForceResult forces;   ///< deviation and overstretched springs
  btScalar safeTimeStep = 0;  ///< eq 5.1 bound of this muscle (adaptive dt only)
  double displacement = 0;    ///< Σ |Δx| of the integration
  bool finite = true;         ///< the integration stayed finite
  double responseMs = 0;      ///< thread time of the last iteration's response
  double forcesMs = 0;        ///< thread time of bone motion, springs, volume term and dt bound
  double volumeMs = 0;        ///< thread time of the volume term
  double integrateMs = 0;     ///< thread time of the integration
  double refitMs = 0;         ///< thread time of the tree refit
  double pushesMs = 0;        ///< thread time of the muscle pairs' pushes
  double boneMs = 0;          ///< thread time of the muscle–bone pairs
};

/// One task of the forces phase: a chunk of a muscle's forces pass (ForceChunks.h).
struct ForceTask {
  uint32_t slot = 0;   ///< the muscle's slot
  uint32_t chunk = 0;  ///< its chunk
  size_t work = 0;     ///< the chunk's work (larger first)
};

/// Two muscles whose bounds meet in this iteration and the contacts their pair task recorded.
struct MusclePairTask {
  uint32_t a = 0;           ///< slot of the first muscle (earlier in insertion order)
  uint32_t b = 0;           ///< slot of the second muscle
  MuscleContacts contacts;  ///< in pairContacts, sized by the pair's candidate list
  uint32_t roundA = 0;      ///< `a`'s contactRound once the response applies these contacts
  uint32_t roundB = 0;      ///< `b`'s contactRound once the response applies these contacts
};

/// What a handle that finds no body is (Slots::find compares the slot's generation).
constexpr const char* kStaleHandle =
    "unknown handle, or its body was removed (the slot's generation differs)";

/// "muscle handle {slot 3, generation 1}" for messages.
template <typename Handle>
std::string handleText(const char* kind, const Handle& handle) {
  return std::string(kind) + " handle {slot " + std::to_string(handle.index) + ", generation " +
         std::to_string(handle.generation) + "}";
}

/// The sizes of one step attempt: the step settings', or smaller while the guard retries a failed
/// step (the settings themselves are never changed by a step).
struct StepSize {
  btScalar timeStep = 0;     ///< largest dt (StepSettings::timeStep) [s]
  btScalar minTimeStep = 0;  ///< smallest adaptive dt (StepSettings::minTimeStep) [s]
  int iterations = 1;        ///< iteration cap (StepSettings::iterations, at least 1)
  /// MuscleTime::Dynamic: exactly `iterations` iterations of the fixed dt `timeStep`, bones
  /// moving over all of them, whatever the stop rule and adaptiveTimeStep say.
  bool exact = false;
  /// The duration needed more iterations than a step runs: cut short (StepStats::shortened).
  bool shortened = false;
};

/// The private state of a MuscleSystem; the step pipeline lives in MuscleSystemStep.cpp.
struct MuscleSystem::Impl {
  MuscleSystemDef definition;                  ///< what the system was built with
  StepSettings stepSettings;                   ///< what the next step runs with
  StepStats stats;                             ///< what the last step did
  Slots<MuscleState> muscles;                  ///< muscle states by slot
  Slots<BoneState> bones;                      ///< bone states by slot
  std::vector<BladeState> blades;              ///< blades, in the order added (Cutting.h)
  ContactLog contacts;                         ///< contacts of the last iteration, for drawing
  std::unique_ptr<TaskPool> pool;              ///< worker threads (MuscleSystemDef::threads)
  std::vector<ThreadScratch> scratch;          ///< per thread of the pool
  std::vector<uint32_t> active;                ///< unfrozen muscle slots, largest first
  std::vector<MuscleIterationResult> results;  ///< per muscle slot, this iteration
  std::vector<ResidualSums> residuals;         ///< per muscle slot, the last force residual
  std::vector<ForceTask> forceTasks;           ///< every chunk of the active muscles, largest first
  bool chunked = false;  ///< an active muscle's forces pass has more than one chunk
  /// Work per chunk of the forces pass (ForceChunks.h); tests set less to split small muscles.
  size_t forceChunkWork = kForceChunkWork;
  std::vector<MusclePairTask> pairTasks;  ///< muscle pairs of this iteration, in pair order
  /// Per slot: its pairTasks in insertion order of the partners (the order its pushes sum in).
  std::vector<std::vector<uint32_t>> musclePairs;
  std::vector<MuscleContact> pairContacts;  ///< room for every muscle pair's contacts
  /// Per entry of pairContacts: the reaction its contact holds (addContactReactions) [N].
  std::vector<btScalar> pairReactions;
  /// A bone contact addContactReactions relaxes.
  struct BoneContact {
    uint32_t slot;      ///< the muscle's slot
    uint32_t particle;  ///< the pushed particle
    btScalar reaction;  ///< what the contact holds along the unit bone push [N]
  };
  std::vector<BoneContact> boneContacts;  ///< room for every boundary particle
  uint32_t musclesAdded = 0;              ///< counts additions, seeds each muscle's noise
  btScalar previousDt = 0;                ///< dt of the last iteration (0: none yet)
  uint64_t stepCount = 0;                 ///< steps taken (the guard numbers them)
  bool pushesPending = false;  ///< collide() left pushes that the next forces phase applies
  /// Iterations over which the equilibrium stop rule measures how fast the steps shrink.
  static constexpr size_t kEquilibriumWindow = 16;
  /// Mean displacements of the last two windows of iterations since the bones arrived.
  std::array<double, 2 * kEquilibriumWindow + 1> recentDisplacements{};
  /// Simulated time the running step must advance (MuscleSystem::step(duration)); 0: a pose step.
  btScalar duration = 0;
  const std::atomic<bool>* cancel = nullptr;  ///< MuscleSystem::setCancelFlag's flag (null: none)
  std::vector<const btCollisionObject*> contactSources;  ///< setContactBodies' bodies
  std::vector<ContactBodyState> contactBodies;  ///< those bodies as the running step sees them
  std::vector<BodyContact> bodyResults;         ///< what each received in the last step
  mutable TreeTraversalStack queryStack;        ///< contactWrench's traversal stack
  bool localStepping = false;                   ///< the running guardedStep is stepLocal's
  /// The last step was a whole one with an integrator other than Verlet: the next local step
  /// starts its region at rest (x(t−dt) = x), the other integrator's x(t−dt) no Verlet velocity.
  bool localFromRest = false;
  btVector3 regionCentre{0, 0, 0};  ///< setLocalRegion's centre [m]
  btScalar regionRadius = -1;       ///< setLocalRegion's radius (< 0: none) [m]

  MuscleState& muscle(MuscleHandle handle) const {
    MuscleState* state = muscles.find(handle);
    if (!state) throw InputError("MuscleSystem", handleText("muscle", handle), kStaleHandle);
    return *state;
  }
  BoneState& bone(BoneHandle handle) const {
    BoneState* state = bones.find(handle);
    if (!state) throw InputError("MuscleSystem", handleText("bone", handle), kStaleHandle);
    return *state;
  }

  /// Starts the pool for definition.threads and sizes the per-thread and per-muscle scratch;
  /// allocates only when the thread count or the bodies changed (never in the iterations).
  void prepareWorkers();
  /// Runs task(state, thread) for every active muscle on the pool (`phase` names the run in
  /// a TaskProfile).
  template <typename Task>
  void forEachMuscle(const char* phase, Task&& task) {
    pool->run(
        active.size(),
        [&](size_t k, unsigned thread) { task(*muscles.states[active[k]], active[k], thread); },
        phase);
  }
  /// Moves the contacts each thread logged into `contacts` (counts always; ends while room).
  void gatherContacts();

  /// The muscle's bones resolved to slots for this step (`boneSlots`, -1 for a removed bone) and
  /// their current transforms copied.
  void resolveBones(ParticleState& particles) const;
  /// The particles at rest moved by their pre-transform (fixed ones by their bone), at rest.
  void placeAtBones(const MuscleSettings& settings, ParticleState& particles) const;
  /// The free particles moved by their bones' motion of this iteration (velocities turned too
  /// when `rotateVelocities`).
  void pretransform(const MuscleSettings& settings, ParticleState& particles,
                    bool rotateVelocities) const;
  /// One free particle moved by its bones' motion of this iteration.
  void movePretransformed(const MuscleSettings& settings, ParticleState& particles, uint32_t i,
                          bool rotateVelocities) const;
  /// pretransform's dual-quaternion blend, the bones' motions converted once.
  void pretransformDualQuaternions(const MuscleSettings& settings, ParticleState& particles,
                                   bool rotateVelocities) const;
  /// The fixed particles on their bones (those of bones gone, `boneSlots` -1, left where they are).
  void followFixed(const MuscleSettings& settings, std::span<const int32_t> boneSlots,
                   ParticleState& particles) const;
  /// The muscle's output surface (if it has one): the skin, then surface contact.
  void deform(const MuscleSettings& settings, ParticleState& particles) const;
  void moveBones(btScalar share, bool arrive);
  /// The bone motion a muscle follows: this iteration's, or all of it since the step began (what
  /// carries a frozen muscle, which skipped the iterations).
  enum class BoneMotion { Iteration, SinceStepStart };
  /// The muscle's bone transforms and deltas for `motion`, the pre-transform, the fixed particles;
  /// the tree told that they followed bones still in motion (TreeState::treeFollowed).
  void followBones(const MuscleSettings& settings, ParticleState& particles, TreeState& trees,
                   BoneMotion motion = BoneMotion::Iteration) const;
  btScalar timeStep(const StepSize& size) const;
  using Clock = std::chrono::steady_clock;
  double distanceToEquilibrium(int settled);
  /// Whether stepSettings.stopRule ends the step after this iteration (the cap aside).
  bool stopRuleMet(bool arrived, int settled, Clock::time_point stepStart);
  /// Iterations between two checks of the residual stop rule (each costs about a forces pass).
  static constexpr int kResidualCheckEvery = 16;
  /// The force residual of the muscles in `slots` (one task per muscle on the pool when it runs,
  /// else in order), summed in the order of `slots`: the same for any thread count.
  ResidualSums residualOf(std::span<const uint32_t> slots);
  double threadShare(double MuscleIterationResult::*part,
                     std::initializer_list<double MuscleIterationResult::*> phase) const;
  void collideMusclePairs();
  /// Adds to each muscle's `forces` (its `forces` member or `residual`) the reactions of the
  /// contacts the last response applied (ContactReactions.cpp): muscle pairs of pairTasks, and
  /// the bone contacts of the muscles in `slots`. No allocation; one fixed order.
  void addContactReactions(std::vector<btVector3> MuscleState::*forces,
                           std::span<const uint32_t> slots);
  /// The pushes of the pairs of the muscle at `slot` into its `contact`, in insertion order of its
  /// partners; an overflow counted in its `trees`.
  void pushMusclePairs(ContactState& contact, TreeState& trees, uint32_t slot,
                       TreeTraversalStack& stack);
  void collide();
  /// The pushes of the last collide() on the muscle; `record` (or an integrator that holds
  /// contacts): kept for the force residual and the integrator (recordPushes).
  void respond(const MuscleSettings& settings, ParticleState& particles, ContactState& contact,
               ResidualState& residual, bool record) const;
  /// The pushes of the last collide() applied to every muscle and recorded for the force residual
  /// (after the last iteration, before a residual check, or with contact bodies every iteration).
  void applyResponse();
  /// The muscle's force chunks for forceChunkWork and their buffers (allocates only when the
  /// work per chunk changed or the muscle is new).
  void planChunks(const MuscleSettings& settings, ChunkState& chunks) const;
  /// forceTasks of the active muscles, largest first.
  void orderForceTasks();
  /// The muscle's last response and this iteration's bone motion, timed into `result`.
  void moveMuscle(const MuscleSettings& settings, ParticleState& particles, ContactState& contact,
                  ResidualState& residual, TreeState& trees, MuscleIterationResult& result,
                  bool bonesMove) const;
  /// One chunk of a muscle's forces; the muscle's last chunk to finish runs finishForces.
  void forceTask(const ForceTask& task, bool bonesMove);
  /// The chunks' buffers added in chunk order, external forces, the muscle's eq 5.1 bound.
  void finishForces(const MuscleSettings& settings, ChunkState& chunks, ParticleState& particles,
                    const InteractionState& interaction, const IntegratorState& integration,
                    MuscleIterationResult& result);
  void forcesPhase(bool bonesMove);
  void integrateAndRefit(const TimeIntegrator& integrator, btScalar dt);
  /// The iteration's per-muscle results reduced in insertion order: displacement, NaN, the
  /// simulated time and dt.
  void sumIteration(btScalar dt);
  void step(const StepSize& size);
  /// The non-frozen muscles into `active`, largest first (springs + particles): handed out in
  /// this order, the threads finish close together.
  void sortActive();
  /// Each bone's target transform read from its body (a non-finite one held at its current).
  void readBoneTargets();
  /// Places the bones at their targets for rebuildEveryStep, or, when a bone moves, the
  /// iterations that move the bones (raising `cap` for a turning bone): 0 when none moves.
  int planBoneMotion(const StepSize& size, int& cap);
  /// Each active muscle's bones resolved for the step and its step counts cleared.
  void resolveMuscles();
  /// Each active muscle prepared for `integrator` and resolved (resolveMuscles); with
  /// rebuildEveryStep placed at its bones from rest.
  void beginMuscles(const TimeIntegrator& integrator);
  /// After the last iteration: bones still in motion jump to their targets and the muscles
  /// follow them, the last response is applied, the strain limited.
  void endIterations(bool arrived);
  /// The muscles' surfaces deformed and the bones at rest at their targets.
  void outputSurfaces();
  /// The iterations of a step in which bones move: `requested`, or with the default solver
  /// (projective) one per kMaxTurnPerIteration of the largest bone turn when that is more.
  int iterationsFor(int requested) const;
  /// The sizes of a step attempt after `halvings` retries (smaller dt, more iterations): the
  /// step settings', or those of a `duration` step (StepSize::exact).
  StepSize stepSize(int halvings) const;
  // Contact bodies (MuscleSystemContact.cpp): read at each attempt's start, collided after every
  // iteration's response, their totals made into bodyResults at the end.
  void beginBodyContacts();
  void collideBodies(btScalar dt);
  void endBodyContacts();
  /// Breaks what is stretched beyond its limit in every tearing muscle after a kept step
  /// (Tearing.h), cuts what the blades swept through (Cutting.h), and brings the integrators'
  /// workspaces up to date.
  void breakMuscles();
  void guardedStep();  ///< step() under the numerical guard (MuscleSystemGuard.cpp)
  /// A muscle the guard froze carried with its bones over the whole step and pushed out of them.
  void carryFrozen(const MuscleSettings& settings, ParticleState& particles, ContactState& contact,
                   ResidualState& residual, TreeState& trees);
  /// Whether some bone's target differs from where it ended the last step.
  bool bonesMove() const;
  // Local steps (MuscleSystemLocal.cpp, MuscleSystem::stepLocal).
  /// One iteration of the muscle's region on `thread`'s scratch, its bones' pushes applied.
  void localIteration(MuscleState& state, const TimeIntegrator& integrator, btScalar dt,
                      btScalar lastDt, unsigned thread);
  /// The active muscles' regions made their free particles (`begin`), or given back.
  void swapRegions(bool begin);
  /// A step of `size` (a duration's) in which only the regions move; as step() when it cannot.
  void localStep(const StepSize& size);
  /// One attempt of the guarded step: localStep while stepLocal runs, else step.
  void attempt(const StepSize& size) { localStepping ? localStep(size) : step(size); }
};

}  // namespace fibremss
