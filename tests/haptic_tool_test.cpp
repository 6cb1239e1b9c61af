// A tool at haptic rate (HapticTool, the probe scene's tool run): the force on the tool tick by
// tick — zero before contact, non-zero in contact, continuous while it slides, close to the force
// of ticks that step the whole muscle by Verlet — the same bits for any thread count, no
// allocation in a tick, and a local tick moves no particle outside the region around the tool.
// The probe's own ticks settle the whole muscle quasi-statically (projective) every few ticks
// and step the region around the tool by Verlet between; the reference ticks step the whole
// muscle by Verlet every tick.
#include <BulletCollision/CollisionShapes/btSphereShape.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "fibremss/Error.h"
#include "fibremss/HapticTool.h"
#include "fibremss/SceneSystem.h"
#include "fibremss/ToolRun.h"
#include "support/AllocationCounter.h"

namespace fibremss {
namespace {

/// `tool`'s region settings for a HapticTool, with whole ticks every `wholeEvery`.
HapticRegion region(const ToolScript& tool, int wholeEvery) {
  return {wholeEvery, btScalar(tool.regionMargin), btScalar(tool.regionDrift)};
}

/// `tool` ending after `ticks` ticks: its last segment cut there at the same speed, so that the
/// ticks before it go where the whole script's go.
ToolScript endingAfter(ToolScript tool, int ticks) {
  const double end = ticks * tool.tickTime;
  const btVector3 there = tool.position(ticks);
  while (tool.times.size() > 1 && tool.times[tool.times.size() - 2] >= end) {
    tool.times.pop_back();
    tool.positions.pop_back();
    tool.phases.pop_back();
  }
  tool.times.back() = end;
  tool.positions.back() = there;
  return tool;
}

/// The probe scene as built in, and with whole Verlet ticks, loaded and prepared once for every
/// test here.
class ProbeScene : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = new LoadedScene(loadScene("probe", {}));
    prepared_ = new PreparedScene(prepareScene(*scene_));
    verlet_ = new LoadedScene(
        loadScene("probe", {"integrator=verlet", "iterations=1", "tool.whole_every=1"}));
    preparedVerlet_ = new PreparedScene(prepareScene(*verlet_));
  }
  static void TearDownTestSuite() {
    delete preparedVerlet_;
    delete verlet_;
    delete prepared_;
    delete scene_;
  }
  /// The probe's run (its quasi-static far field) on `threads` threads, once per thread count.
  static const ToolRunResult& run(int threads) {
    static ToolRunResult runs[3];
    static bool done[3] = {false, false, false};
    if (!done[threads]) runs[threads] = runTool(*scene_, *prepared_, threads);
    done[threads] = true;
    return runs[threads];
  }
  /// The probe's run with whole Verlet ticks on one thread, computed once.
  static const ToolRunResult& wholeRun() {
    static const ToolRunResult whole = runTool(*verlet_, *preparedVerlet_, 1);
    return whole;
  }
  /// The Verlet probe's run on `threads` threads with local ticks (the whole muscle every
  /// kLocalEvery-th tick) and the region `margin` beyond the sphere [m], once per thread count
  /// at the scene's margin, once on one thread at another over the script's first `ticks`.
  static const ToolRunResult& localRun(int threads, double margin = -1, int ticks = 0) {
    static ToolRunResult runs[3], other;
    static bool done[3] = {false, false, false};
    LoadedScene local = *verlet_;
    local.tool.wholeEvery = kLocalEvery;
    if (margin >= 0) {
      local.tool.regionMargin = margin;
      local.tool = endingAfter(local.tool, ticks);
      return other = runTool(local, *preparedVerlet_, 1);
    }
    if (!done[threads]) runs[threads] = runTool(local, *preparedVerlet_, threads);
    done[threads] = true;
    return runs[threads];
  }
  /// Ticks per whole-muscle tick of the local runs.
  static constexpr int kLocalEvery = 16;
  static LoadedScene* scene_;
  static PreparedScene* prepared_;
  static LoadedScene* verlet_;
  static PreparedScene* preparedVerlet_;
};
LoadedScene* ProbeScene::scene_ = nullptr;
PreparedScene* ProbeScene::prepared_ = nullptr;
LoadedScene* ProbeScene::verlet_ = nullptr;
PreparedScene* ProbeScene::preparedVerlet_ = nullptr;

/// The RMS over the ticks of phase `slide` of |F − F_reference| [N].
double slideRms(const ToolScript& script, const ToolRunResult& run,
                const ToolRunResult& reference) {
  double sum = 0;
  int count = 0;
  for (size_t t = 0; t < run.ticks.size(); ++t) {
    if (script.phase(int(t) + 1) != "slide") continue;
    sum += run.ticks[t].force.distance2(reference.ticks[t].force);
    ++count;
  }
  return count > 0 ? std::sqrt(sum / count) : 0;
}

TEST_F(ProbeScene, TheForceIsZeroBeforeContactAndPressesTheProbeBackInContact) {
  const ToolRunResult& whole = wholeRun();
  for (const ToolRunResult* result : {&run(1), &whole}) {
    ASSERT_EQ(result->ticks.size(), size_t(scene_->tool.ticks()));
    EXPECT_FALSE(result->failed);
    // The probe starts 10 mm above the belly: nothing touches it for the first ticks.
    ASSERT_GT(result->firstContact, 50);
    for (int t = 0; t + 1 < result->firstContact; ++t) {
      EXPECT_EQ(result->ticks[size_t(t)].force.length2(), 0) << "tick " << t + 1;
      EXPECT_EQ(result->ticks[size_t(t)].contacts, 0u) << "tick " << t + 1;
    }
    EXPECT_GT(result->peakForce, 0);
  }
  // Held 8 mm deep and sliding: the muscle pushes the probe back up (+z) every tick, and never
  // pulls it down; the quasi-static far field keeps the probe in contact to the slide's end too,
  // where the whole ticks' force falls to a few hundredths of its peak.
  for (size_t t = 0; t < whole.ticks.size(); ++t) {
    const std::string& phase = scene_->tool.phase(int(t) + 1);
    if (phase != "hold" && phase != "slide") continue;
    EXPECT_GT(whole.ticks[t].force.z(), 0) << "tick " << t + 1 << " (" << phase << ")";
    const btScalar far = run(1).ticks[t].force.z();
    EXPECT_GE(far, 0) << "tick " << t + 1 << " (" << phase << ")";
    if (whole.ticks[t].force.length() > 0.02 * whole.peakForce) {
      EXPECT_GT(far, 0) << "tick " << t + 1 << " (" << phase << ")";
    }
  }
}

TEST_F(ProbeScene, NoTickToTickJumpWhileSlidingExceedsATenthOfThePeakForce) {
  for (const ToolRunResult* result : {&run(1), &wholeRun()}) {
    ASSERT_GT(result->peakForce, 0);
    EXPECT_GT(result->slideJump, 0);  // it did slide, and the force changed
    EXPECT_LE(result->slideJump, 0.1 * result->peakForce);
  }
}

TEST_F(ProbeScene, TheQuasiStaticFarFieldGivesTheForceOfWholeVerletTicks) {
  const ToolRunResult& far = run(1);
  const ToolRunResult& whole = wholeRun();
  EXPECT_FALSE(far.failed);
  const int every = scene_->tool.wholeEvery;
  ASSERT_GT(every, 1);  // the probe's ticks are mostly local
  EXPECT_EQ(far.wholeTicks, (long(far.ticks.size()) + every - 1) / every);
  EXPECT_EQ(far.firstContact, whole.firstContact);
  ASSERT_EQ(far.ticks.size(), whole.ticks.size());
  // Local ticks against a far field that lags (the whole muscle by Verlet every 16th tick) were
  // 1.5 peaks off while sliding; the far field settled every few ticks is within a tenth.
  EXPECT_LE(slideRms(scene_->tool, far, whole), 0.1 * whole.peakForce);
  EXPECT_NEAR(far.peakForce, whole.peakForce, 0.25 * whole.peakForce);
}

TEST_F(ProbeScene, LocalTicksKeepTheForceContinuousAndTheSameForOneAndTwoThreads) {
  const ToolRunResult& one = localRun(1);
  const ToolRunResult& two = localRun(2);
  EXPECT_FALSE(one.failed);
  EXPECT_EQ(one.wholeTicks, (long(one.ticks.size()) + kLocalEvery - 1) / kLocalEvery);
  EXPECT_EQ(one.firstContact, wholeRun().firstContact);
  ASSERT_GT(one.peakForce, 0);
  EXPECT_GT(one.slideJump, 0);
  EXPECT_LE(one.slideJump, 0.1 * one.peakForce);
  ASSERT_EQ(one.ticks.size(), two.ticks.size());
  for (size_t t = 0; t < one.ticks.size(); ++t)
    ASSERT_EQ(std::memcmp(&one.ticks[t].force, &two.ticks[t].force, sizeof(btVector3)), 0)
        << "tick " << t + 1;
}

TEST_F(ProbeScene, LocalTicksOfARegionAsLargeAsTheMuscleGiveTheWholeMusclesForce) {
  // The local step's own forces, integration and contacts, with nothing held: the force of the
  // whole muscle's ticks up to the rounding of the scalar kernels. Through the press, the hold
  // and the slide's first 10 mm (five gatherings of the region; the whole muscle as a region
  // costs a whole tick's work on the scalar kernels, so not the whole slide).
  const int ticks = 650;
  const ToolRunResult& covering = localRun(1, 1.0, ticks);
  const ToolRunResult& whole = wholeRun();
  ASSERT_EQ(covering.ticks.size(), size_t(ticks));
  ASSERT_EQ(verlet_->tool.phase(ticks), "slide");
  double peak = 0, largest = 0;
  for (size_t t = 0; t < covering.ticks.size(); ++t) {
    peak = std::max(peak, double(whole.ticks[t].force.length()));
    largest = std::max(largest, double(covering.ticks[t].force.distance(whole.ticks[t].force)));
  }
  EXPECT_NEAR(covering.peakForce, peak, 1e-3 * peak);
  EXPECT_LE(largest, 1e-2 * peak);
}

TEST_F(ProbeScene, ALocalStepMovesNoParticleOutsideTheRegionAroundTheTool) {
  MuscleSystemDef def = scene_->simulation;
  def.threads = 1;
  MuscleSystem system(def);
  const SceneHandles handles = addScene(system, *prepared_);
  btSphereShape shape(btScalar(scene_->tool.radius));
  btRigidBody body(btRigidBody::btRigidBodyConstructionInfo(0, nullptr, &shape));
  body.setCollisionFlags(body.getCollisionFlags() | btCollisionObject::CF_KINEMATIC_OBJECT);
  HapticTool tool(system, body, btScalar(scene_->tool.tickTime),
                  region(scene_->tool, scene_->tool.wholeEvery));
  btTransform pose = btTransform::getIdentity();
  // 50 ticks into the slide, then a local step of the region the tool's ticks gather.
  const int tick = int(scene_->tool.times[3] / scene_->tool.tickTime) + 50;
  for (int t = 1; t <= tick; ++t) {
    pose.setOrigin(scene_->tool.position(t));
    tool.tick(pose);
  }
  const btVector3 centre = pose.getOrigin();
  const btScalar radius = btScalar(scene_->tool.radius + scene_->tool.regionMargin);
  system.setLocalRegion(centre, radius);
  const std::span<const btVector3> now = system.positions(handles.muscles[0]);
  const std::vector<btVector3> before(now.begin(), now.end());
  system.stepLocal(btScalar(scene_->tool.tickTime));
  EXPECT_FALSE(system.lastStep().failed);
  EXPECT_GT(system.contactWrench(body, pose).force.z(), 0);
  const std::span<const btVector3> after = system.positions(handles.muscles[0]);
  size_t moved = 0, outside = 0;
  for (size_t i = 0; i < before.size(); ++i) {
    const bool same = std::memcmp(&before[i], &after[i], sizeof(btVector3)) == 0;
    moved += same ? 0 : 1;
    if (before[i].distance(centre) <= radius) continue;
    ++outside;
    EXPECT_TRUE(same) << "particle " << i << " outside the region moved";
  }
  EXPECT_GT(moved, 10u);
  EXPECT_GT(outside, before.size() / 2);  // most of the muscle is outside it
}

TEST_F(ProbeScene, OneAndTwoThreadsGiveTheSameForcesBitForBit) {
  const ToolRunResult& one = run(1);
  const ToolRunResult& two = run(2);
  EXPECT_EQ(one.threads, 1);
  EXPECT_EQ(two.threads, 2);
  ASSERT_EQ(one.ticks.size(), two.ticks.size());
  for (size_t t = 0; t < one.ticks.size(); ++t)
    ASSERT_EQ(std::memcmp(&one.ticks[t].force, &two.ticks[t].force, sizeof(btVector3)), 0)
        << "tick " << t + 1;
}

/// Runs `scene`'s ticks up to the hold on two threads, whole every `wholeEvery`-th, then ten
/// more with the allocation counter armed (whole and local ticks) and a local step of a region
/// gathered again; expects them in contact and without allocation.
void expectTicksAllocateNothing(const LoadedScene& scene, const PreparedScene& prepared,
                                int wholeEvery) {
  MuscleSystemDef def = scene.simulation;
  def.threads = 2;
  MuscleSystem system(def);
  addScene(system, prepared);
  btSphereShape shape(btScalar(scene.tool.radius));
  btRigidBody body(btRigidBody::btRigidBodyConstructionInfo(0, nullptr, &shape));
  body.setCollisionFlags(body.getCollisionFlags() | btCollisionObject::CF_KINEMATIC_OBJECT);
  HapticTool tool(system, body, btScalar(scene.tool.tickTime), region(scene.tool, wholeEvery));
  btTransform pose = btTransform::getIdentity();
  const int hold = int(scene.tool.times[3] / scene.tool.tickTime);
  for (int tick = 1; tick <= hold; ++tick) {
    pose.setOrigin(scene.tool.position(tick));
    tool.tick(pose);
  }
  btAlignedAllocSetCustom(testing::countingAlloc, std::free);
  testing::allocationCount = 0;
  testing::countingArmed = true;
  ContactWrench wrench;
  for (int tick = hold + 1; tick <= hold + 10; ++tick) {
    pose.setOrigin(scene.tool.position(tick));
    wrench = tool.tick(pose);
  }
  system.setLocalRegion(pose.getOrigin() + btVector3(0, btScalar(0.01), 0), btScalar(0.02));
  system.stepLocal(btScalar(scene.tool.tickTime));
  testing::countingArmed = false;
  btAlignedAllocSetCustom(nullptr, nullptr);
  EXPECT_GT(wrench.force.z(), 0) << "no contact ran";
  EXPECT_EQ(testing::allocationCount.load(), 0);
  EXPECT_EQ(tool.ticks(), hold + 10);
  EXPECT_GT(tool.wholeTicks(), 0);
  EXPECT_LT(tool.wholeTicks(), tool.ticks());
}

TEST_F(ProbeScene, ATickInContactAllocatesNothing) {
  {
    SCOPED_TRACE("the probe's ticks: a quasi-static far field, local Verlet ticks");
    expectTicksAllocateNothing(*scene_, *prepared_, scene_->tool.wholeEvery);
  }
  SCOPED_TRACE("Verlet's whole and local ticks");
  expectTicksAllocateNothing(*verlet_, *preparedVerlet_, kLocalEvery);
}

TEST(HapticTool, RejectsABodyThatIsNotKinematicAndAPoseWithNaN) {
  MuscleSystem system;
  btSphereShape shape(btScalar(0.005));
  btRigidBody dynamic(btRigidBody::btRigidBodyConstructionInfo(1, nullptr, &shape));
  EXPECT_THROW(HapticTool(system, dynamic), InputError);
  btRigidBody body(btRigidBody::btRigidBodyConstructionInfo(0, nullptr, &shape));
  body.setCollisionFlags(body.getCollisionFlags() | btCollisionObject::CF_KINEMATIC_OBJECT);
  EXPECT_THROW(HapticTool(system, body, 0), InputError);
  EXPECT_THROW(HapticTool(system, body, btScalar(1e-3), {0, btScalar(0.01), btScalar(0.002)}),
               InputError);
  EXPECT_THROW(HapticTool(system, body, btScalar(1e-3), {2, btScalar(0.01), btScalar(0.01)}),
               InputError);
  EXPECT_THROW(system.setLocalRegion(btVector3(0, 0, 0), -1), InputError);
  EXPECT_THROW(system.stepLocal(0), InputError);
  HapticTool tool(system, body);
  btTransform pose = btTransform::getIdentity();
  pose.setOrigin(btVector3(std::nanf(""), 0, 0));
  EXPECT_THROW(tool.tick(pose), InputError);
}

}  // namespace
}  // namespace fibremss
