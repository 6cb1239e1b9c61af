// A tool at haptic rate (HapticTool, the probe scene's tool run): the force on the tool tick by
// tick — zero before contact, non-zero in contact, continuous while it slides — the same bits for
// any thread count, and no allocation in a tick.
#include <BulletCollision/CollisionShapes/btSphereShape.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

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
  HapticTool tool(system, body, btScalar(scene_->tool.tickTime));
  btTransform pose = btTransform::getIdentity();
  // The script's ticks up to the hold, then ten more with the counter armed.
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
  testing::countingArmed = false;
  btAlignedAllocSetCustom(nullptr, nullptr);
  EXPECT_GT(wrench.force.z(), 0) << "no contact ran";
  EXPECT_EQ(testing::allocationCount.load(), 0);
  EXPECT_EQ(tool.ticks(), hold + 10);
}

TEST(HapticTool, RejectsABodyThatIsNotKinematicAndAPoseWithNaN) {
  MuscleSystem system;
  btSphereShape shape(btScalar(0.005));
  btRigidBody dynamic(btRigidBody::btRigidBodyConstructionInfo(1, nullptr, &shape));
  EXPECT_THROW(HapticTool(system, dynamic), InputError);
  btRigidBody body(btRigidBody::btRigidBodyConstructionInfo(0, nullptr, &shape));
  body.setCollisionFlags(body.getCollisionFlags() | btCollisionObject::CF_KINEMATIC_OBJECT);
  EXPECT_THROW(HapticTool(system, body, 0), InputError);
  HapticTool tool(system, body);
  btTransform pose = btTransform::getIdentity();
  pose.setOrigin(btVector3(std::nanf(""), 0, 0));
  EXPECT_THROW(tool.tick(pose), InputError);
}

}  // namespace
}  // namespace fibremss
