// The numerical guard (MuscleSystemDef::onFailure): a step that produces NaN/inf or bursts
// springs is rolled back to the exact last good state, retried with a smaller dt, or the failing
// muscle is frozen while the others (and a host's Bullet world) keep going; Report leaves it.
#include <BulletCollision/BroadphaseCollision/btDbvtBroadphase.h>
#include <BulletCollision/CollisionShapes/btSphereShape.h>
#include <BulletDynamics/ConstraintSolver/btSequentialImpulseConstraintSolver.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <memory>
#include <vector>

#include "dynamics/TimeStep.h"
#include "fibremss/BoneBody.h"
#include "fibremss/Measures.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/MuscleWorld.h"
#include "kernels/MuscleSystemPretransform.h"
#include "solver/MuscleSystemAccess.h"
#include "solver/MuscleSystemGuard.h"
#include "support/GridMuscle.h"
#include "support/SolverFixtures.h"

namespace fibremss {
namespace {

using testing::cubeBone;
using testing::gridMuscle;

/// κ of the stiff muscle relative to the soft one: its stable dt is about eight times smaller.
constexpr btScalar kStiff = 100;
/// A fixed dt this many times the stiff muscle's stable bound bursts it, even halved (the
/// bound is conservative: up to √3 below the true limit), and keeps the soft one stable.
constexpr btScalar kBursting = 6;

const std::shared_ptr<const BoneSettings>& leftBone() {
  static const auto bone = cubeBone("left", btVector3(-0.02f, 0, 0));
  return bone;
}
const std::shared_ptr<const BoneSettings>& rightBone() {
  static const auto bone = cubeBone("right", btVector3(0.02f, 0, 0));
  return bone;
}
const std::shared_ptr<const MuscleSettings>& softMuscle() {
  static const auto muscle = gridMuscle("soft", 0, 1);
  return muscle;
}
const std::shared_ptr<const MuscleSettings>& stiffMuscle() {
  static const auto muscle = gridMuscle("stiff", btScalar(0.03), kStiff);
  return muscle;
}

/// Fixed dt (no adaptive bound) `ofStiffLimit` times the stiff muscle's stable dt, 10
/// iterations, light noise so that an unstable step has something to amplify.
MuscleSystemDef fixedStep(btScalar ofStiffLimit, FailurePolicy policy) {
  MuscleSystemDef parameters = testing::verletDef();
  parameters.stepSettings.adaptiveTimeStep = false;
  parameters.stepSettings.timeStep = ofStiffLimit * stableTimeStep(*stiffMuscle());
  parameters.stepSettings.iterations = 10;
  parameters.initialNoise = btScalar(1e-4);
  parameters.onFailure = policy;
  return parameters;
}

/// A system with two bones (the right one moves a little each step) and the given muscles.
struct Rig {
  MuscleSystem system;
  std::vector<BoneHandle> bones;
  std::vector<MuscleHandle> muscles;
  int steps = 0;

  Rig(const MuscleSystemDef& parameters,
      const std::vector<std::shared_ptr<const MuscleSettings>>& settings)
      : system(parameters) {
    bones = {system.addBone(leftBone()), system.addBone(rightBone())};
    for (const auto& muscle : settings) muscles.push_back(system.addMuscle(muscle, bones));
  }
  /// The right bone's transform after `step` steps: 0.5 mm further along x each step.
  static btTransform rightAt(int step) {
    btTransform moved = btTransform::getIdentity();
    moved.setOrigin(btVector3(btScalar(0.0005) * static_cast<btScalar>(step), 0, 0));
    return moved;
  }
  /// Steps from the next on with `factor` times the dt.
  void scaleTimeStep(btScalar factor) {
    StepSettings settings = system.stepSettings();
    settings.timeStep *= factor;
    system.setStepSettings(settings);
  }
  void step() {
    ++steps;
    system.setBoneTransform(bones[1], rightAt(steps));
    system.step();
  }
  std::vector<btVector3> positions(size_t m) const {
    const auto x = system.positions(muscles[m]);
    return {x.begin(), x.end()};
  }
};

/// Where a frozen grid muscle at `x` goes in the Rig's step `step`: it rides with its bones (the
/// grid has no blend: each free particle with its nearest bone's motion over the step, fixed ones
/// at T·rest); no bone touches it there, so no push changes that.
std::vector<btVector3> carried(const MuscleSettings& muscle, std::vector<btVector3> x, int step) {
  const btTransform transforms[2] = {btTransform::getIdentity(), Rig::rightAt(step)};
  const btTransform deltas[2] = {btTransform::getIdentity(),
                                 Rig::rightAt(step) * Rig::rightAt(step - 1).inverse()};
  for (uint32_t i = 0; i < x.size(); ++i)
    x[i] = muscle.isFixed(i)
               ? transforms[muscle.fixedBone[i]] * muscle.restPositions[i]
               : pretransformPoint(muscle, deltas, i, x[i], true, PretransformBlend::Linear);
  return x;
}

bool sameHandle(MuscleHandle a, MuscleHandle b) {
  return a.index == b.index && a.generation == b.generation;
}

bool allFinite(const std::vector<btVector3>& points) {
  for (const btVector3& p : points)
    if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || !std::isfinite(p.z())) return false;
  return true;
}

/// Bit-for-bit equality of two particle arrays.
::testing::AssertionResult identical(const std::vector<btVector3>& a,
                                     const std::vector<btVector3>& b) {
  if (a.size() != b.size()) return ::testing::AssertionFailure() << "sizes differ";
  for (size_t i = 0; i < a.size(); ++i)
    if (a[i].x() != b[i].x() || a[i].y() != b[i].y() || a[i].z() != b[i].z())
      return ::testing::AssertionFailure() << "particle " << i << " differs";
  return ::testing::AssertionSuccess();
}

TEST(Guard, TheChosenTimeStepsAreStableForTheSoftAndUnstableForTheStiffMuscle) {
  // The premise of the other tests, checked with the guard only reporting.
  Rig soft(fixedStep(kBursting, FailurePolicy::Report), {softMuscle()});
  Rig stiff(fixedStep(kBursting / 2, FailurePolicy::Report), {stiffMuscle()});
  Rig quarter(fixedStep(btScalar(0.75), FailurePolicy::Report), {stiffMuscle()});
  for (int s = 0; s < 3; ++s) {
    soft.step();
    EXPECT_FALSE(soft.system.lastStep().failed);
    quarter.step();
    EXPECT_FALSE(quarter.system.lastStep().failed);
  }
  stiff.step();
  EXPECT_TRUE(stiff.system.lastStep().failed);
  EXPECT_TRUE(stiff.system.lastStep().nan || stiff.system.lastStep().exploded);
}

TEST(Guard, ReportLeavesTheFailedStateAndNamesTheMuscle) {
  Rig rig(fixedStep(kBursting, FailurePolicy::Report), {softMuscle(), stiffMuscle()});
  const std::vector<btVector3> before = rig.positions(1);
  rig.step();
  const StepStats& stats = rig.system.lastStep();
  EXPECT_TRUE(stats.failed);
  EXPECT_FALSE(stats.rolledBack);
  EXPECT_EQ(stats.retries, 0);
  EXPECT_EQ(stats.newlyFrozen, 0u);
  EXPECT_EQ(stats.step, 0u);
  EXPECT_TRUE(sameHandle(stats.failedMuscle, rig.muscles[1]));
  EXPECT_FALSE(rig.system.frozen(rig.muscles[1]));
  EXPECT_FALSE(identical(rig.positions(1), before));  // the burst state is left in place
  double longest = 0;
  const auto x = rig.system.positions(rig.muscles[1]);
  for (const Spring& spring : stiffMuscle()->springs)
    longest = std::max(longest, double(x[spring.a].distance(x[spring.b]) / spring.restLength));
  EXPECT_TRUE(!allFinite(rig.positions(1)) || longest > 3);
}

TEST(Guard, StopBodyRestoresTheExactLastGoodStateAndFreezesOnlyTheFailingMuscle) {
  // Two good steps at a small dt, then a dt at which the stiff muscle bursts.
  Rig rig(fixedStep(btScalar(0.5), FailurePolicy::StopBody), {softMuscle(), stiffMuscle()});
  rig.step();
  rig.step();
  ASSERT_FALSE(rig.system.lastStep().rolledBack);
  const std::vector<btVector3> stiffGood = rig.positions(1);
  const std::vector<btVector3> softGood = rig.positions(0);
  rig.scaleTimeStep(2 * kBursting);
  rig.step();
  const StepStats& stats = rig.system.lastStep();
  EXPECT_TRUE(stats.rolledBack);
  EXPECT_FALSE(stats.failed);
  EXPECT_EQ(stats.step, 2u);
  EXPECT_EQ(stats.retries, 0);
  EXPECT_EQ(stats.newlyFrozen, 1u);
  EXPECT_EQ(stats.frozenMuscles, 1u);
  EXPECT_TRUE(sameHandle(stats.failedMuscle, rig.muscles[1]));
  EXPECT_TRUE(rig.system.frozen(rig.muscles[1]));
  EXPECT_FALSE(rig.system.frozen(rig.muscles[0]));
  // The last good state, carried rigidly with the bones over the step.
  EXPECT_TRUE(identical(rig.positions(1), carried(*stiffMuscle(), stiffGood, rig.steps)));
  EXPECT_FALSE(identical(rig.positions(1), stiffGood));  // the right bone moved it
  EXPECT_FALSE(identical(rig.positions(0), softGood));   // the soft one finished the step
  EXPECT_TRUE(allFinite(rig.positions(0)));

  // Later steps: the frozen muscle only rides with its bones, the other one deforms.
  for (int s = 0; s < 3; ++s) {
    const std::vector<btVector3> soft = rig.positions(0);
    const std::vector<btVector3> stiff = rig.positions(1);
    rig.step();
    EXPECT_FALSE(rig.system.lastStep().rolledBack);
    EXPECT_EQ(rig.system.lastStep().newlyFrozen, 0u);
    EXPECT_EQ(rig.system.lastStep().frozenMuscles, 1u);
    EXPECT_TRUE(identical(rig.positions(1), carried(*stiffMuscle(), stiff, rig.steps)));
    EXPECT_FALSE(identical(rig.positions(0), soft));
  }
  rig.system.unfreeze(rig.muscles[1]);
  EXPECT_FALSE(rig.system.frozen(rig.muscles[1]));
}

TEST(Guard, TheOtherMuscleMovesExactlyAsIfTheFrozenOneWereNotThere) {
  Rig both(fixedStep(kBursting, FailurePolicy::StopBody), {softMuscle(), stiffMuscle()});
  Rig alone(fixedStep(kBursting, FailurePolicy::StopBody), {softMuscle()});
  for (int s = 0; s < 3; ++s) {
    both.step();
    alone.step();
    EXPECT_TRUE(identical(both.positions(0), alone.positions(0))) << "step " << s;
  }
  EXPECT_TRUE(both.system.frozen(both.muscles[1]));
}

TEST(Guard, RetrySucceedsWithASmallerTimeStepWhereTheFullOneBursts) {
  Rig retried(fixedStep(3, FailurePolicy::Retry), {stiffMuscle()});
  retried.step();
  const StepStats& stats = retried.system.lastStep();
  EXPECT_TRUE(stats.rolledBack);
  EXPECT_FALSE(stats.failed);
  ASSERT_GE(stats.retries, 1);
  ASSERT_LE(stats.retries, retried.system.definition().maxRetries);
  EXPECT_EQ(stats.frozenMuscles, 0u);
  EXPECT_TRUE(sameHandle(stats.failedMuscle, retried.muscles[0]));
  EXPECT_TRUE(allFinite(retried.positions(0)));
  EXPECT_EQ(retried.system.stepSettings().timeStep,
            fixedStep(3, FailurePolicy::Retry).stepSettings.timeStep)
      << "the requested settings are back after the step";

  // The same step run directly with the retry's dt and iterations gives the very same state:
  // the rollback left nothing of the failed attempts behind.
  const int factor = 1 << stats.retries;
  MuscleSystemDef smaller = fixedStep(3, FailurePolicy::Report);
  smaller.stepSettings.timeStep /= static_cast<btScalar>(factor);
  smaller.stepSettings.iterations *= factor;
  Rig direct(smaller, {stiffMuscle()});
  direct.step();
  EXPECT_FALSE(direct.system.lastStep().failed);
  EXPECT_TRUE(identical(retried.positions(0), direct.positions(0)));
  EXPECT_EQ(stats.iterations, 10 * (2 * factor - 1)) << "every attempt's iterations counted";
}

TEST(Guard, RetryFreezesTheMuscleOnceItsRetriesAreSpent) {
  MuscleSystemDef parameters = fixedStep(kBursting, FailurePolicy::Retry);
  parameters.maxRetries = 1;  // dt/2 is still unstable
  Rig rig(parameters, {softMuscle(), stiffMuscle()});
  const std::vector<btVector3> start = rig.positions(1);
  rig.step();
  const StepStats& stats = rig.system.lastStep();
  EXPECT_TRUE(stats.rolledBack);
  EXPECT_EQ(stats.retries, 1);
  EXPECT_EQ(stats.newlyFrozen, 1u);
  EXPECT_TRUE(rig.system.frozen(rig.muscles[1]));
  EXPECT_FALSE(rig.system.frozen(rig.muscles[0]));
  EXPECT_TRUE(identical(rig.positions(1), carried(*stiffMuscle(), start, rig.steps)));
  EXPECT_TRUE(allFinite(rig.positions(0)));
}

/// A host scheduler that runs every task at once on the caller's thread and sets `cancel` when
/// it is handed its `cancelAt`-th task: a cancel that arrives inside a step, at a point that is
/// the same in every run.
struct CancellingScheduler {
  std::atomic<bool> cancel{false};
  int tasks = 0;
  int cancelAt = 0;

  static void* enqueue(TaskCallback task, uint32_t items, uint32_t, void* context, void* self) {
    auto& scheduler = *static_cast<CancellingScheduler*>(self);
    if (++scheduler.tasks == scheduler.cancelAt) scheduler.cancel.store(true);
    task(0, items, 0, context);
    return nullptr;
  }
  static void finish(void*, void*) {}
  TaskScheduler handle() { return {enqueue, finish, this, 1}; }
};

// A cancel flag (MuscleSystem::setCancelFlag) ends the running step at the end of an iteration:
// StepStats::interrupted. Here the step's dt bursts the muscle within its first iterations and
// the cancel comes after a few: the step goes back to its start with no retry, nothing blamed
// and nothing frozen; cleared, the same step is retried (so that rollback was the cancel's). Set
// before a step, the flag ends it after one iteration.
TEST(Guard, ACancelledStepStopsWithinItsIterationsAndIsNeitherRetriedNorFrozen) {
  CancellingScheduler scheduler;
  scheduler.cancelAt = 12;
  MuscleSystemDef parameters = fixedStep(1000, FailurePolicy::Retry);
  parameters.scheduler = scheduler.handle();
  Rig rig(parameters, {stiffMuscle()});
  rig.system.setCancelFlag(&scheduler.cancel);
  const std::vector<btVector3> start = rig.positions(0);
  rig.step();
  const StepStats& stats = rig.system.lastStep();
  EXPECT_TRUE(stats.interrupted);
  EXPECT_GT(stats.iterations, 1);
  EXPECT_LT(stats.iterations, parameters.stepSettings.iterations);
  EXPECT_TRUE(stats.rolledBack);
  EXPECT_EQ(stats.retries, 0);
  EXPECT_FALSE(stats.failed);
  EXPECT_FALSE(stats.nan || stats.exploded);
  EXPECT_EQ(stats.newlyFrozen, 0u);
  EXPECT_FALSE(rig.system.frozen(rig.muscles[0]));
  EXPECT_EQ(rig.system.failures(rig.muscles[0]).attempts, 0);
  EXPECT_TRUE(identical(rig.positions(0), start));

  scheduler.cancel = false;
  rig.step();
  EXPECT_FALSE(rig.system.lastStep().interrupted);
  EXPECT_TRUE(rig.system.lastStep().rolledBack);
  EXPECT_GE(rig.system.lastStep().retries, 1);

  // At a stable dt: set before the step, one iteration; cleared, the step's ten.
  std::atomic<bool> cancel{true};
  Rig stable(fixedStep(btScalar(0.5), FailurePolicy::Retry), {stiffMuscle()});
  stable.system.setCancelFlag(&cancel);
  stable.step();
  EXPECT_TRUE(stable.system.lastStep().interrupted);
  EXPECT_EQ(stable.system.lastStep().iterations, 1);
  EXPECT_FALSE(stable.system.lastStep().rolledBack);
  cancel = false;
  stable.step();
  EXPECT_FALSE(stable.system.lastStep().interrupted);
  EXPECT_EQ(stable.system.lastStep().iterations, 10);
}

/// Deepest overlap of the free boundary particles of `muscle` at `x` with the spheres of `plate`
/// placed at `transform` (0 when none overlaps).
btScalar deepestOverlap(const MuscleSettings& muscle, const std::vector<btVector3>& x,
                        const BoneSettings& plate, const btTransform& transform) {
  btScalar deepest = 0;
  for (uint32_t i : muscle.boundaryParticles) {
    if (muscle.isFixed(i)) continue;
    for (size_t s = 0; s < plate.sphereCentres.size(); ++s)
      deepest = std::max(deepest, muscle.radii[i] + plate.sphereRadii[s] -
                                      x[i].distance(transform * plate.sphereCentres[s]));
  }
  return deepest;
}

TEST(Guard, AFrozenMuscleIsPushedOutOfABoneThatMovesIntoIt) {
  // The stiff muscle (top layer of particles at y = 34 mm, radius 1.5 mm) is frozen; then a
  // plate of bone spheres (radius 3 mm, 2 mm apart; not one of its bones, so it does not carry
  // the muscle) comes down to y = 33 mm in one step, 2.5 mm into that layer.
  Rig rig(fixedStep(btScalar(0.5), FailurePolicy::StopBody), {stiffMuscle()});
  rig.step();
  rig.scaleTimeStep(2 * kBursting);
  rig.step();
  ASSERT_TRUE(rig.system.frozen(rig.muscles[0]));
  auto plate = std::make_shared<BoneSettings>();
  plate->name = "plate";
  for (int i = -7; i <= 7; ++i)
    for (int k = -4; k <= 4; ++k) {
      plate->sphereCentres.emplace_back(btScalar(0.002) * btScalar(i), btScalar(0.053),
                                        btScalar(0.002) * btScalar(k));
      plate->sphereRadii.push_back(btScalar(0.003));
    }
  const BoneHandle bone = rig.system.addBone(plate);
  btTransform down = btTransform::getIdentity();
  down.setOrigin(btVector3(0, btScalar(-0.017), 0));
  rig.system.setBoneTransform(bone, down);
  const std::vector<btVector3> before = rig.positions(0);
  rig.step();
  EXPECT_EQ(rig.system.lastStep().frozenMuscles, 1u);
  // Carried with its own bones only, it would be 2.5 mm inside the plate; it is pushed out.
  EXPECT_GT(
      deepestOverlap(*stiffMuscle(), carried(*stiffMuscle(), before, rig.steps), *plate, down),
      btScalar(0.002));
  EXPECT_LE(deepestOverlap(*stiffMuscle(), rig.positions(0), *plate, down), btScalar(1e-5));
  EXPECT_TRUE(allFinite(rig.positions(0)));
}

/// The guard's check of the muscle in `state` with the bones of `rig`'s system.
MuscleHealth check(Rig& rig, MuscleState& state) {
  return checkMuscle(*state.settings, state, state, state,
                     MuscleSystemAccess::impl(rig.system).bones.states, state.tear);
}

TEST(Guard, AMuscleSpreadFarBeyondItsSizeIsDivergingNotTorn) {
  // The guard keeps a trapped muscle's burst springs only while it is not spread: a torn muscle
  // stays between its bones, a diverging one grows without bound.
  Rig rig(fixedStep(btScalar(0.5), FailurePolicy::Retry), {softMuscle()});
  MuscleState& state = *MuscleSystemAccess::impl(rig.system).muscles.states[rig.muscles[0].index];
  EXPECT_FALSE(check(rig, state).spread);
  EXPECT_FALSE(check(rig, state).failed());
  for (btVector3& x : state.positions) x *= btScalar(2 * kTornSpread);
  const MuscleHealth grown = check(rig, state);
  EXPECT_TRUE(grown.spread);
  EXPECT_TRUE(grown.failed());  // its springs are beyond 3× as well
}

TEST(Guard, ABurstSpringIsTornByBonesOnlyWhenTwoBonesThatMovedApartPushedItsEnds) {
  // One particle 30 mm off its place bursts every spring it has (rest lengths up to 6.9 mm)
  // without spreading the muscle; of those, only a spring whose ends different bones pushed in
  // the step, and which grew by no more than those bones moved apart at its ends, counts as
  // spanned by them (its length is the bones' motion, not the solver's).
  Rig rig(fixedStep(btScalar(0.5), FailurePolicy::Retry), {softMuscle()});
  auto& impl = MuscleSystemAccess::impl(rig.system);
  MuscleState& state = *impl.muscles.states[rig.muscles[0].index];
  BoneState& left = *impl.bones.states[rig.bones[0].index];
  BoneState& right = *impl.bones.states[rig.bones[1].index];
  // The step starts here.
  saveGoodState(state, state);
  for (BoneState* bone : {&left, &right}) bone->goodCurrent = bone->current;
  const Spring spring = state.settings->springs.front();
  const btVector3 offset(0, btScalar(0.03), 0);
  state.positions[spring.b] += offset;
  const MuscleHealth burst = check(rig, state);
  ASSERT_GT(burst.explodedSprings, 1u);
  ASSERT_FALSE(burst.spread);
  EXPECT_EQ(burst.spannedSprings, 0u);  // no bone pushed it
  state.stepBones[spring.b] = static_cast<int32_t>(left.slot);
  EXPECT_EQ(check(rig, state).spannedSprings, 0u);  // one end pushed, the other not
  state.stepBones[spring.a] = static_cast<int32_t>(left.slot);
  EXPECT_EQ(check(rig, state).spannedSprings, 0u);  // both ends pushed by the same bone
  state.stepBones[spring.a] = static_cast<int32_t>(right.slot);
  // Two bones, standing still: they explain no growth, the numerics burst it.
  EXPECT_EQ(check(rig, state).spannedSprings, 0u);
  // The two moved together: still no growth of theirs.
  for (BoneState* bone : {&left, &right})
    bone->current.setOrigin(bone->current.getOrigin() + offset);
  EXPECT_EQ(check(rig, state).spannedSprings, 0u);
  // The bone at b carried it off by the offset, the bone at a held still: that spring alone.
  right.current = right.goodCurrent;
  EXPECT_EQ(check(rig, state).spannedSprings, 1u);
  // Half that way apart: less than the spring grew.
  left.current.setOrigin(left.goodCurrent.getOrigin() + offset / 2);
  EXPECT_EQ(check(rig, state).spannedSprings, 0u);
}

TEST(Guard, AMuscleTheNumericsBurstBetweenTwoBonesThatPushItStillFails) {
  // The stiff grid between the two cubes moved 2 mm closer to it, each pushing the free particles
  // next to it (x = ∓8 mm), at a dt that bursts it. The blow-up flings particles, so that burst
  // springs end on both bones; the bones stand still, so none is spanned by them, and the grid
  // spreads beyond twice its size too: the step fails as a numerical one, not kept as torn.
  static const auto between = gridMuscle("between", 0, kStiff);
  MuscleSystem system(fixedStep(kBursting, FailurePolicy::Report));
  const std::vector<BoneHandle> bones{
      system.addBone(cubeBone("left", btVector3(btScalar(-0.018), 0, 0))),
      system.addBone(cubeBone("right", btVector3(btScalar(0.018), 0, 0)))};
  const MuscleHandle muscle = system.addMuscle(between, bones);
  system.step();
  const StepStats& stats = system.lastStep();
  auto& impl = MuscleSystemAccess::impl(system);
  MuscleState& state = *impl.muscles.states[muscle.index];
  const auto onTwoBones = [&](const Spring& spring) {
    const int32_t a = state.stepBones[spring.a], b = state.stepBones[spring.b];
    return a >= 0 && b >= 0 && a != b &&
           springExploded(state.positions[spring.a].distance(state.positions[spring.b]),
                          spring.restLength,
                          state.restLengthSum / double(state.settings->springs.size()));
  };
  ASSERT_TRUE(
      std::any_of(state.settings->springs.begin(), state.settings->springs.end(), onTwoBones));
  const MuscleHealth health =
      checkMuscle(*state.settings, state, state, state, impl.bones.states, state.tear);
  EXPECT_GT(health.explodedSprings, 0u);
  EXPECT_EQ(health.spannedSprings, 0u);
  EXPECT_TRUE(health.spread);
  EXPECT_EQ(stats.trappedMuscles, 0u);
  EXPECT_TRUE(stats.failed);
  EXPECT_TRUE(sameHandle(stats.failedMuscle, muscle));
}

TEST(Guard, TheHostsBulletWorldKeepsRunningBesideABurstingMuscle) {
  btSoftBodyRigidBodyCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher(&configuration);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  MuscleSystemDef parameters = fixedStep(kBursting, FailurePolicy::Retry);
  parameters.maxRetries = 1;
  MuscleWorld world(&dispatcher, &broadphase, &solver, &configuration, parameters);
  world.setGravity(btVector3(0, btScalar(-9.81), 0));
  BoneBody left(leftBone()), right(rightBone());
  const std::vector<BoneHandle> bones = {world.addBone(left.settings(), left.body()),
                                         world.addBone(right.settings(), right.body())};
  const MuscleHandle soft = world.addMuscle(softMuscle(), bones);
  const MuscleHandle stiff = world.addMuscle(stiffMuscle(), bones);

  // A falling ball well away from the muscles.
  btSphereShape shape(btScalar(0.05));
  btVector3 inertia(0, 0, 0);
  shape.calculateLocalInertia(1, inertia);
  btTransform start = btTransform::getIdentity();
  start.setOrigin(btVector3(1, 1, 0));
  btDefaultMotionState motion(start);
  btRigidBody ball(btRigidBody::btRigidBodyConstructionInfo(1, &motion, &shape, inertia));
  world.addRigidBody(&ball);

  const int steps = 30;
  for (int s = 0; s < steps; ++s) ASSERT_NO_THROW(world.stepSimulation(btScalar(1.0 / 60), 0));
  EXPECT_EQ(world.muscleSteps(), steps);
  EXPECT_TRUE(world.muscleSystem().frozen(stiff));
  EXPECT_FALSE(world.muscleSystem().frozen(soft));
  EXPECT_EQ(world.muscleSystem().lastStep().frozenMuscles, 1u);
  EXPECT_TRUE(allFinite(
      {world.muscleSystem().positions(soft).begin(), world.muscleSystem().positions(soft).end()}));
  // Half a second of free fall: ½·g·t² = 1.23 m; Bullet's symplectic Euler falls a little more.
  const btScalar fallen = 1 - ball.getWorldTransform().getOrigin().y();
  const btScalar seconds = btScalar(steps) / 60;
  EXPECT_NEAR(fallen, 0.5 * 9.81 * seconds * seconds, 0.05);
  EXPECT_GT(ball.getLinearVelocity().y(), btScalar(-9.81 * seconds) - btScalar(0.01));
  world.removeRigidBody(&ball);
  world.removeMuscle(soft);
  world.removeMuscle(stiff);
  for (BoneHandle bone : bones) world.removeBone(bone);
}

}  // namespace
}  // namespace fibremss
