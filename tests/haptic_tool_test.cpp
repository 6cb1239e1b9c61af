// A tool at haptic rate (HapticTool, the probe scene's tool run): the force on the tool tick by
// tick — zero before contact, non-zero in contact, continuous while it slides, close to the force
// of ticks that step the whole muscle — the same bits for any thread count, no allocation in a
// tick, and a local tick moves no particle outside the region around the tool.
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

/// The probe scene, loaded and prepared once for every test here.
class ProbeScene : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = new LoadedScene(loadScene("probe", {}));
    prepared_ = new PreparedScene(prepareScene(*scene_));
  }
  static void TearDownTestSuite() {
    delete prepared_;
    delete scene_;
  }
  /// The probe's run on `threads` threads, computed once per thread count.
  static const ToolRunResult& run(int threads) {
    static ToolRunResult runs[3];
    static bool done[3] = {false, false, false};
    if (!done[threads]) runs[threads] = runTool(*scene_, *prepared_, threads);
    done[threads] = true;
    return runs[threads];
  }
  /// The probe's run on `threads` threads with local ticks (the whole muscle every
  /// kLocalEvery-th tick) and the region `margin` beyond the sphere [m], once per thread count
  /// at the scene's margin, once on one thread at another.
  static const ToolRunResult& localRun(int threads, double margin = -1) {
    static ToolRunResult runs[3], other;
    static bool done[3] = {false, false, false};
    LoadedScene local = *scene_;
    local.tool.wholeEvery = kLocalEvery;
    if (margin >= 0) {
      local.tool.regionMargin = margin;
      return other = runTool(local, *prepared_, 1);
    }
    if (!done[threads]) runs[threads] = runTool(local, *prepared_, threads);
    done[threads] = true;
    return runs[threads];
  }
  /// Ticks per whole-muscle tick of the local runs.
  static constexpr int kLocalEvery = 16;
  /// The scene's region settings for a HapticTool with local ticks.
  static HapticRegion region() {
    const ToolScript& tool = scene_->tool;
    return {kLocalEvery, btScalar(tool.regionMargin), btScalar(tool.regionDrift)};
  }
  static LoadedScene* scene_;
  static PreparedScene* prepared_;
};
LoadedScene* ProbeScene::scene_ = nullptr;
PreparedScene* ProbeScene::prepared_ = nullptr;

TEST_F(ProbeScene, TheForceIsZeroBeforeContactAndPressesTheProbeBackInContact) {
  const ToolRunResult& result = run(1);
  ASSERT_EQ(result.ticks.size(), size_t(scene_->tool.ticks()));
  EXPECT_FALSE(result.failed);
  // The probe starts 10 mm above the belly: nothing touches it for the first ticks.
  ASSERT_GT(result.firstContact, 50);
  for (int t = 0; t + 1 < result.firstContact; ++t) {
    EXPECT_EQ(result.ticks[size_t(t)].force.length2(), 0) << "tick " << t + 1;
    EXPECT_EQ(result.ticks[size_t(t)].contacts, 0u) << "tick " << t + 1;
  }
  // Held 8 mm deep and sliding: the muscle pushes the probe back up (+z) every tick.
  for (size_t t = 0; t < result.ticks.size(); ++t) {
    const std::string& phase = scene_->tool.phase(int(t) + 1);
    if (phase != "hold" && phase != "slide") continue;
    EXPECT_GT(result.ticks[t].force.z(), 0) << "tick " << t + 1 << " (" << phase << ")";
  }
  EXPECT_GT(result.peakForce, 0);
}

TEST_F(ProbeScene, NoTickToTickJumpWhileSlidingExceedsATenthOfThePeakForce) {
  const ToolRunResult& result = run(1);
  ASSERT_GT(result.peakForce, 0);
  EXPECT_GT(result.slideJump, 0);  // it did slide, and the force changed
  EXPECT_LE(result.slideJump, 0.1 * result.peakForce);
}

TEST_F(ProbeScene, LocalTicksKeepTheForceContinuousAndTheSameForOneAndTwoThreads) {
  const ToolRunResult& one = localRun(1);
  const ToolRunResult& two = localRun(2);
  EXPECT_FALSE(one.failed);
  EXPECT_EQ(one.wholeTicks, (long(one.ticks.size()) + kLocalEvery - 1) / kLocalEvery);
  EXPECT_EQ(one.firstContact, run(1).firstContact);
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
  // whole muscle's ticks up to the rounding of the scalar kernels.
  const ToolRunResult& covering = localRun(1, 1.0);
  const ToolRunResult& whole = run(1);
  EXPECT_NEAR(covering.peakForce, whole.peakForce, 1e-3 * whole.peakForce);
  ASSERT_EQ(covering.ticks.size(), whole.ticks.size());
  double largest = 0;
  for (size_t t = 0; t < whole.ticks.size(); ++t)
    largest = std::max(largest, double(covering.ticks[t].force.distance(whole.ticks[t].force)));
  EXPECT_LE(largest, 1e-2 * whole.peakForce);
}

TEST_F(ProbeScene, ALocalStepMovesNoParticleOutsideTheRegionAroundTheTool) {
  MuscleSystemDef def = scene_->simulation;
  def.threads = 1;
  MuscleSystem system(def);
  const SceneHandles handles = addScene(system, *prepared_);
  btSphereShape shape(btScalar(scene_->tool.radius));
  btRigidBody body(btRigidBody::btRigidBodyConstructionInfo(0, nullptr, &shape));
  body.setCollisionFlags(body.getCollisionFlags() | btCollisionObject::CF_KINEMATIC_OBJECT);
  HapticTool tool(system, body, btScalar(scene_->tool.tickTime), region());
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

TEST_F(ProbeScene, ATickInContactAllocatesNothing) {
  MuscleSystemDef def = scene_->simulation;
  def.threads = 2;
  MuscleSystem system(def);
  addScene(system, *prepared_);
  btSphereShape shape(btScalar(scene_->tool.radius));
  btRigidBody body(btRigidBody::btRigidBodyConstructionInfo(0, nullptr, &shape));
  body.setCollisionFlags(body.getCollisionFlags() | btCollisionObject::CF_KINEMATIC_OBJECT);
  HapticTool tool(system, body, btScalar(scene_->tool.tickTime), region());
  btTransform pose = btTransform::getIdentity();
  // The script's ticks up to the hold, then ten more with the counter armed (whole and local
  // ticks), and a region gathered again.
  const int hold = int(scene_->tool.times[3] / scene_->tool.tickTime);
  for (int tick = 1; tick <= hold; ++tick) {
    pose.setOrigin(scene_->tool.position(tick));
    tool.tick(pose);
  }
  btAlignedAllocSetCustom(testing::countingAlloc, std::free);
  testing::allocationCount = 0;
  testing::countingArmed = true;
  ContactWrench wrench;
  for (int tick = hold + 1; tick <= hold + 10; ++tick) {
    pose.setOrigin(scene_->tool.position(tick));
    wrench = tool.tick(pose);
  }
  system.setLocalRegion(pose.getOrigin() + btVector3(0, btScalar(0.01), 0), btScalar(0.02));
  system.stepLocal(btScalar(scene_->tool.tickTime));
  testing::countingArmed = false;
  btAlignedAllocSetCustom(nullptr, nullptr);
  EXPECT_GT(wrench.force.z(), 0) << "no contact ran";
  EXPECT_EQ(testing::allocationCount.load(), 0);
  EXPECT_EQ(tool.ticks(), hold + 10);
  EXPECT_GT(tool.wholeTicks(), 0);
  EXPECT_LT(tool.wholeTicks(), tool.ticks());
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
