// The numerical guard around one MuscleSystem step (MuscleSystemDef::onFailure). Every
// step saves the state it changes (muscles' positions, previous, velocities; bones' transforms;
// the last dt); a step whose stats report NaN/inf or an explosion is checked muscle by muscle,
// and unless the policy is Report it is rolled back and repeated: with half the dt cap and twice
// the iterations (Retry, up to maxRetries times), or with the failing muscles frozen at their last
// good state (StopBody, and Retry once its retries are spent). The other muscles always finish the
// step; nothing throws, so a host's Bullet world keeps running. A step the cancel flag ended
// (MuscleSystem::setCancelFlag) is not retried: a failed attempt is rolled back (unless Report)
// and nothing is blamed or frozen. A muscle whose springs burst while two bones press some of its
// particles from opposite sides (trapped: pinched in an iteration of the step, CollisionPairs.cpp,
// or a burst spring whose two ends different bones pushed in the step and that grew by no more
// than they moved apart there: its length is the bones' motion), not NaN nor spread far beyond
// its size, was torn by the bones, not by the numerics: its state is kept; while the bones go on
// moving its tear may grow by kTearGrowth a step, and once they stand still later steps fail it
// only for more burst springs than the trap left. A frozen
// muscle rides with its bones (their motion over the step) and is pushed out of them, so it never
// ends inside one.
#include "MuscleSystemGuard.h"

#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>

#include "MuscleSystemImpl.h"
#include "dynamics/Tearing.h"
#include "fibremss/Measures.h"
#include "integrators/Integrators.h"

namespace fibremss {
namespace {

using Clock = std::chrono::steady_clock;

/// Retries stop after this many halvings of the dt cap (1024× smaller), whatever maxRetries says.
constexpr int kMaxHalvings = 10;
/// Collision rounds that push a frozen muscle, carried with its bones, out of them.
constexpr int kFrozenRounds = 8;
/// How much a held trap's tear may grow in one step [burst springs / the most seen before]: on
/// pinch (resolution 12; 1, 3, 5, 8, 10, 12 iterations per pose) it grew at most 1.20× a step
/// once the blades had let go (1 457 → 1 748 springs); a numerical blow-up bursts it wholesale.
constexpr double kTearGrowth = 1.5;

bool finite(const btVector3& v) {
  return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z());
}

bool allFinite(const std::vector<btVector3>& points) {
  return std::all_of(points.begin(), points.end(), finite);
}

/// Diagonal of the bounding box of `points`.
double extent(const std::vector<btVector3>& points) {
  if (points.empty()) return 0;
  btVector3 lower = points.front(), upper = points.front();
  for (const btVector3& p : points) {
    lower.setMin(p);
    upper.setMax(p);
  }
  return double(lower.distance(upper));
}

/// The step size of `requested` with the dt cap (and the lower clamp) divided by 2^halvings and
/// the iterations multiplied by it, so that the step still covers the same bone motion, in
/// smaller iterations.
StepSize smallerSteps(const StepSettings& requested, int halvings) {
  const int factor = 1 << halvings;
  StepSize smaller;
  smaller.timeStep = requested.timeStep / static_cast<btScalar>(factor);
  smaller.minTimeStep = requested.minTimeStep / static_cast<btScalar>(factor);
  smaller.iterations = std::max(requested.iterations, 1) > INT_MAX / factor
                           ? INT_MAX
                           : std::max(requested.iterations, 1) * factor;
  return smaller;
}

/// Most iterations a duration step runs: a longer duration is cut short (StepStats::shortened).
constexpr double kMaxExactIterations = 1 << 14;

void add(StepTiming& sum, const StepTiming& part) {
  sum.mss += part.mss;
  sum.volume += part.volume;
  sum.muscleCd += part.muscleCd;
  sum.boneCd += part.boneCd;
  sum.response += part.response;
  sum.output += part.output;
}

/// How far bones `a` and `b` moved apart in the step so far at `atA` and `atB` (world, at the
/// step's start) [m]: the length of the difference of their motions there.
double boneSeparation(const BoneState& a, const BoneState& b, const btVector3& atA,
                      const btVector3& atB) {
  const btVector3 moveA = a.current * (a.goodCurrent.inverse() * atA) - atA;
  const btVector3 moveB = b.current * (b.goodCurrent.inverse() * atB) - atB;
  return double((moveA - moveB).length());
}

/// Whether `spring`, burst, was stretched by two bones: different bones pushed its ends in the
/// step, and it grew since the step's start (`start`) by no more than they moved apart there.
/// Two bones that hold still relative to each other explain no growth.
bool spannedByBones(const Spring& spring, const ParticleState& muscle, const ContactState& contact,
                    const GuardSnapshot& start, std::span<const std::unique_ptr<BoneState>> bones) {
  const int32_t boneA = contact.stepBones[spring.a], boneB = contact.stepBones[spring.b];
  if (boneA < 0 || boneB < 0 || boneA == boneB) return false;
  const btVector3 &a = start.goodPositions[spring.a], &b = start.goodPositions[spring.b];
  const double growth =
      muscle.positions[spring.a].distance(muscle.positions[spring.b]) - double(a.distance(b));
  return growth <= boneSeparation(*bones[size_t(boneA)], *bones[size_t(boneB)], a, b);
}

}  // namespace

MuscleHealth checkMuscle(const MuscleSettings& settings, const ParticleState& muscle,
                         const ContactState& contact, const GuardSnapshot& start,
                         std::span<const std::unique_ptr<BoneState>> bones, TearState& tear) {
  MuscleHealth health;
  health.nan =
      !allFinite(muscle.positions) || !allFinite(muscle.previous) || !allFinite(muscle.velocities);
  // Written so that a NaN extent counts as spread too.
  health.spread = tear.pieces > 1
                      ? piecesSpread(settings, muscle, tear, kTornSpread)
                      : !(extent(muscle.positions) <= kTornSpread * extent(settings.restPositions));
  if (settings.springs.empty()) return health;
  const double floor = muscle.restLengthSum / static_cast<double>(settings.springs.size());
  for (const Spring& spring : settings.springs) {
    const double length = muscle.positions[spring.a].distance(muscle.positions[spring.b]);
    if (!springExploded(length, spring.restLength, floor)) continue;
    ++health.explodedSprings;
    if (spannedByBones(spring, muscle, contact, start, bones)) ++health.spannedSprings;
  }
  return health;
}

void saveGoodState(const ParticleState& muscle, GuardSnapshot& good) {
  std::copy(muscle.positions.begin(), muscle.positions.end(), good.goodPositions.begin());
  std::copy(muscle.previous.begin(), muscle.previous.end(), good.goodPrevious.begin());
  std::copy(muscle.velocities.begin(), muscle.velocities.end(), good.goodVelocities.begin());
}

void restoreGoodState(const GuardSnapshot& good, ParticleState& muscle, ContactState& contact) {
  std::copy(good.goodPositions.begin(), good.goodPositions.end(), muscle.positions.begin());
  std::copy(good.goodPrevious.begin(), good.goodPrevious.end(), muscle.previous.begin());
  std::copy(good.goodVelocities.begin(), good.goodVelocities.end(), muscle.velocities.begin());
  forgetBoneSides(contact);
}

namespace {

/// What the guard did over the attempts of one step.
struct GuardOutcome {
  StepTiming spent;           ///< the attempts' timings summed [ms]
  int iterations = 0;         ///< the attempts' iterations summed
  int retries = 0;            ///< attempts repeated with a smaller dt
  size_t newlyFrozen = 0;     ///< muscles frozen in this step
  MuscleHandle failedMuscle;  ///< the first muscle blamed
  bool failedNan = false;     ///< it had NaN/inf
  bool rolledBack = false;    ///< some attempt was rolled back
  bool failed = false;        ///< a failure left in place (Report)
};

/// Saves the state a step changes: every muscle's (frozen ones too, carried with their bones
/// every step; a report-only guard reads the positions to judge burst springs) and the bones'
/// transforms (their motion over the step carries the frozen muscles).
void saveStepStart(Slots<MuscleState>& muscles, Slots<BoneState>& bones) {
  for (uint32_t slot : muscles.order) saveGoodState(*muscles.states[slot], *muscles.states[slot]);
  for (uint32_t slot : bones.order) {
    BoneState& bone = *bones.states[slot];
    bone.goodLast = bone.last;
    bone.goodCurrent = bone.current;
  }
}

/// Back to the start of the step: every muscle, frozen ones included (theirs is unchanged),
/// and the bones with their sphere trees.
void rollBackStep(Slots<MuscleState>& muscles, Slots<BoneState>& bones) {
  for (uint32_t slot : muscles.order) {
    MuscleState& state = *muscles.states[slot];
    restoreGoodState(state, state, state);
  }
  for (uint32_t slot : bones.order) {
    BoneState& bone = *bones.states[slot];
    bone.last = bone.goodLast;
    bone.current = bone.goodCurrent;
    bone.tree.place(bone.current, bone.settings->sphereCentres, bone.settings->sphereRadii);
  }
}

/// The bones after a step: how many held their own against a NaN/inf transform, and whether any
/// moved in it.
struct BoneSummary {
  size_t held = 0;     ///< bones that held their own against a NaN/inf transform
  bool moved = false;  ///< a bone moved in the step
};

BoneSummary summariseBones(const Slots<BoneState>& bones) {
  BoneSummary summary;
  for (uint32_t slot : bones.order) {
    const BoneState& bone = *bones.states[slot];
    summary.held += bone.heldNonFinite ? 1 : 0;
    summary.moved = summary.moved || !(bone.goodLast == bone.last);
  }
  return summary;
}

/// Attribution after a failed attempt: which muscles failed (frozen ones are out of the step and
/// of the blame), each counted in its failures, the first in `outcome`, each frozen when
/// `freeze`. A muscle torn by bones closing on it (`bones`) is kept. Returns how many were
/// blamed.
size_t blameMuscles(Slots<MuscleState>& muscles, const Slots<BoneState>& bones, bool freeze,
                    GuardOutcome& outcome) {
  size_t blamed = 0;
  for (uint32_t slot : muscles.order) {
    MuscleState& state = *muscles.states[slot];
    if (state.frozen) continue;
    const MuscleHealth health =
        checkMuscle(*state.settings, state, state, state, bones.states, state.tear);
    if (!health.failed()) continue;
    if (!health.nan && !health.spread) {
      // Torn by bones closing on it: no smaller dt opens the gap; kept, reported as trapped.
      // Caught in any response of the step (a particle pinched, or a burst spring stretched
      // between two bones), or held since: the bones that tore it carry its halves on apart
      // after the trap opens, so its tear may grow until they stand still.
      state.spannedInStep = health.spannedSprings;
      const bool held = state.trapHeld &&
                        double(health.explodedSprings) <= kTearGrowth * double(state.tornSprings);
      if (state.caughtInStep() || held) {
        state.tornSprings = std::max(state.tornSprings, health.explodedSprings);
        continue;
      }
      // What a trap tore stays torn once the bones let go: only more burst springs fail.
      if (health.explodedSprings <= state.tornSprings) continue;
    }
    ++state.failures.attempts;
    state.failures.nan += health.nan ? 1 : 0;
    if (blamed++ == 0) {
      outcome.failedMuscle = {slot, muscles.generations[slot]};
      outcome.failedNan = health.nan;
    }
    if (freeze) {
      state.frozen = true;
      ++outcome.newlyFrozen;
    }
  }
  return blamed;
}

/// The step's stats from the guard's outcome: `heldBones` given a NaN/inf transform held their
/// own (reported as NaN, the muscles stay finite), `frozen` muscles, the trapped ones.
void guardStats(const GuardOutcome& outcome, size_t heldBones, size_t frozen,
                size_t trappedParticles, size_t trappedMuscles, StepStats& stats) {
  stats.iterations = outcome.iterations;
  stats.heldBones = heldBones;
  stats.nan = stats.nan || heldBones > 0;
  stats.failedNan = outcome.failedNan || heldBones > 0;
  stats.failed = outcome.failed || heldBones > 0;
  stats.rolledBack = outcome.rolledBack;
  stats.retries = outcome.retries;
  stats.failedMuscle = outcome.failedMuscle;
  stats.newlyFrozen = outcome.newlyFrozen;
  stats.frozenMuscles = frozen;
  stats.trappedParticles = trappedParticles;
  stats.trappedMuscles = trappedMuscles;
}

}  // namespace

StepSize MuscleSystem::Impl::stepSize(int halvings) const {
  if (!(duration > 0)) return smallerSteps(stepSettings, halvings);
  // k = max(iterations, ⌈duration / dt⌉) iterations of duration / k, dt the smaller of
  // timeStep and every muscle's stable dt (springs and volume term: an exact step has no
  // adaptive bound), Verlet's in a local step.
  StepSettings exact = stepSettings;
  btScalar bound = stepSettings.timeStep;
  for (uint32_t slot : muscles.order) {
    const MuscleState& state = *muscles.states[slot];
    if (!state.frozen)
      bound = std::min(bound, localStepping ? state.verletTimeStep : state.stableTimeStep);
  }
  const double split = std::ceil(double(duration) / double(bound));
  const bool shortened = split > kMaxExactIterations;
  exact.iterations = std::max(stepSettings.iterations, int(std::min(split, kMaxExactIterations)));
  exact.timeStep = exact.minTimeStep =
      shortened ? bound : duration / static_cast<btScalar>(exact.iterations);
  StepSize size = smallerSteps(exact, halvings);
  size.exact = true;
  size.shortened = shortened;
  return size;
}

void MuscleSystem::Impl::breakMuscles() {
  for (uint32_t slot : muscles.order) {
    MuscleState& state = *muscles.states[slot];
    if (state.frozen) continue;
    bool changed = breakStretched(state, state.tear);
    for (const BladeState& blade : blades)
      changed = cutBySweep(state, state.tear, blade) || changed;
    if (changed && state.prepared)
      integratorFor(state.preparedFor)
          .springsChanged(*state.settings, state, state.workspace.get());
  }
  for (BladeState& blade : blades) {
    blade.before = blade.last;
    blade.last = blade.target;
  }
}

// A frozen muscle rides with its bones (each one's motion over the whole step, from where it
// started) and is pushed out of them.
void MuscleSystem::Impl::carryFrozen(const MuscleSettings& settings, ParticleState& particles,
                                     ContactState& contact, ResidualState& residual,
                                     TreeState& trees) {
  const bool velocities = integratorFor(definition.integrator).usesVelocities();
  resolveBones(particles);
  followBones(settings, particles, trees, BoneMotion::SinceStepStart);
  // The step's workers are idle now: the first thread's scratch is free; its log is not kept.
  ThreadScratch& thread = scratch.front();
  contact.pinched = contact.pinchedInStep = contact.spannedInStep = 0;
  if (definition.muscleBone && particles.bonesMoving)
    for (int round = 0; round < kFrozenRounds; ++round) {
      refitTree(settings, particles, trees);
      for (uint32_t slot : bones.order)
        collideMuscleBone(settings, particles, trees, contact, *bones.states[slot], thread.stack,
                          thread.contacts);
      recordPushes(settings, contact, residual);
      applyPushes(settings, particles, contact, velocities, definition.slidingContacts);
    }
  thread.contacts.clear();
  deform(settings, particles);
}

void MuscleSystem::Impl::guardedStep() {
  const Clock::time_point start = Clock::now();
  const uint64_t number = stepCount++;
  const FailurePolicy policy = definition.onFailure;
  const bool rollback = policy != FailurePolicy::Report;
  saveStepStart(muscles, bones);
  const btScalar goodPreviousDt = previousDt;
  // A local step after another integrator's whole step starts its region at rest; a repeated
  // attempt must too (the first attempt's end cleared the flag).
  const bool goodLocalFromRest = localFromRest;
  StepSize size = stepSize(0);

  GuardOutcome outcome;
  const auto rollBack = [&] {
    rollBackStep(muscles, bones);
    previousDt = goodPreviousDt;
    localFromRest = goodLocalFromRest;
    outcome.rolledBack = true;
  };
  while (true) {
    attempt(size);
    add(outcome.spent, stats.timing);
    outcome.iterations += stats.iterations;
    if (!stats.nan && !stats.exploded) break;
    if (stats.interrupted && rollback) {
      rollBack();
      for (uint32_t slot : muscles.order)  // surfaces as restored
        deform(*muscles.states[slot]->settings, *muscles.states[slot]);
      stats.nan = stats.exploded = false;
      break;
    }
    const bool retry = policy == FailurePolicy::Retry &&
                       outcome.retries < std::min(definition.maxRetries, kMaxHalvings);
    // Flagged, but no muscle fails the check (only tiny springs beyond 3×): the state is good.
    if (blameMuscles(muscles, bones, rollback && !retry, outcome) == 0) break;
    if (!rollback) {
      outcome.failed = true;
      break;
    }
    rollBack();
    size = stepSize(retry ? ++outcome.retries : 0);
  }

  breakMuscles();

  const BoneSummary boneSummary = summariseBones(bones);
  size_t frozen = 0, trappedParticles = 0, trappedMuscles = 0;
  for (uint32_t slot : muscles.order) {
    MuscleState& state = *muscles.states[slot];
    if (state.frozen) {
      ++frozen;
      carryFrozen(*state.settings, state, state, state, state);
    }
    trappedParticles += state.pinched;
    state.trapHeld = state.caughtInStep() || (state.trapHeld && boneSummary.moved);
    trappedMuscles += state.pinched > 0 || state.spannedInStep > 0 ? 1 : 0;
  }
  stats.timing = outcome.spent;
  stats.timing.total = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
  stats.step = number;
  guardStats(outcome, boneSummary.held, frozen, trappedParticles, trappedMuscles, stats);
  stats.shortened = size.shortened;
}

}  // namespace fibremss
