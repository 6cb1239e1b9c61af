// The Bullet world component: MuscleWorld and MuscleAction step FibreMSS muscles next to
// kinematic bones and btSoftBody; fixed particles follow their bones; handles guard removal.
#include <BulletCollision/BroadphaseCollision/btDbvtBroadphase.h>
#include <BulletDynamics/ConstraintSolver/btSequentialImpulseConstraintSolver.h>
#include <BulletDynamics/Dynamics/btDiscreteDynamicsWorld.h>
#include <BulletSoftBody/btSoftBodyHelpers.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <vector>

#include "fibremss/BoneBody.h"
#include "fibremss/Error.h"
#include "fibremss/MuscleAction.h"
#include "fibremss/MuscleWorld.h"
#include "support/GridMuscle.h"

namespace fibremss {
namespace {

using testing::cubeBone;
using testing::gridMuscle;

MuscleSystemDef fewIterations() {
  MuscleSystemDef parameters;
  parameters.stepSettings.iterations = 10;
  return parameters;
}

/// The transform of the moving bone at step s: slides along x and turns about z.
btTransform movedBone(int s) {
  btTransform t;
  t.setIdentity();
  t.setOrigin(btVector3(btScalar(0.001) * s, btScalar(0.0005) * s, 0));
  t.setRotation(btQuaternion(btVector3(0, 0, 1), btScalar(0.02) * s));
  return t;
}

void expectFixedParticlesOnBones(const MuscleSystem& system, MuscleHandle muscle,
                                 const std::vector<btTransform>& boneTransforms) {
  const MuscleSettings& settings = system.settings(muscle);
  std::span<const btVector3> positions = system.positions(muscle);
  ASSERT_EQ(positions.size(), settings.particleCount());
  for (uint32_t p : settings.fixedParticles) {
    const btVector3 expected = boneTransforms[settings.fixedBone[p]] * settings.restPositions[p];
    EXPECT_NEAR(positions[p].distance(expected), 0, 1e-6) << "fixed particle " << p;
  }
}

/// A Bullet soft-rigid MuscleWorld with its infrastructure.
struct WorldFixture {
  btSoftBodyRigidBodyCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher{&configuration};
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  MuscleWorld world{&dispatcher, &broadphase, &solver, &configuration, fewIterations()};
  BoneBody fixedBone{cubeBone("left", btVector3(-0.02f, 0, 0))};
  BoneBody movingBone{cubeBone("right", btVector3(0.02f, 0, 0))};
  std::vector<BoneHandle> bones;

  WorldFixture() {
    world.setGravity(btVector3(0, btScalar(-9.81), 0));
    world.getWorldInfo().m_gravity = world.getGravity();
    world.getWorldInfo().m_sparsesdf.Initialize();
    bones.push_back(world.addBone(fixedBone.settings(), fixedBone.body()));
    bones.push_back(world.addBone(movingBone.settings(), movingBone.body()));
  }
  ~WorldFixture() {
    for (MuscleHandle m : world.muscleSystem().muscles()) world.removeMuscle(m);
    for (BoneHandle b : bones) world.removeBone(b);
  }
  std::vector<btTransform> step(int s) {
    movingBone.setTransform(movedBone(s));
    world.stepSimulation(btScalar(1.0 / 60), 0);
    return {btTransform::getIdentity(), movedBone(s)};
  }
};

btScalar softCentreY(const btSoftBody& body) {
  btScalar sum = 0;
  for (int i = 0; i < body.m_nodes.size(); ++i) sum += body.m_nodes[i].m_x.y();
  return sum / btScalar(body.m_nodes.size());
}

TEST(BoneBody, IsKinematicWithTheBoneMeshAtItsTransform) {
  BoneBody bone(cubeBone("cube", btVector3(0, 0, 0)));
  EXPECT_TRUE(bone.body()->isKinematicObject());
  EXPECT_EQ(bone.body()->getInvMass(), 0);
  btTransform moved = btTransform::getIdentity();
  moved.setOrigin(btVector3(0.5f, 0.25f, 0));
  bone.setTransform(moved);

  // A ray along x hits the cube's face at x = 0.5 − 0.01: the shape reads the vertex array in
  // btScalar's precision and sits where the transform puts it.
  btDefaultCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher(&configuration);
  btDbvtBroadphase broadphase;
  btCollisionWorld world(&dispatcher, &broadphase, &configuration);
  world.addCollisionObject(bone.body());
  const btVector3 from(-1, 0.25f, 0.001f), to(1, 0.25f, 0.001f);
  btCollisionWorld::ClosestRayResultCallback hit(from, to);
  world.rayTest(from, to, hit);
  ASSERT_TRUE(hit.hasHit());
  EXPECT_EQ(hit.m_collisionObject, bone.body());
  EXPECT_NEAR(hit.m_hitPointWorld.x(), 0.49, 1e-5);
  EXPECT_NEAR(hit.m_hitNormalWorld.x(), -1, 1e-5);
  world.removeCollisionObject(bone.body());
}

TEST(BoneBody, RejectsABoneWithoutTriangles) {
  auto empty = std::make_shared<BoneSettings>();
  empty->name = "empty";
  EXPECT_THROW(BoneBody bone(empty), InputError);
}

TEST(MuscleWorld, FixedParticlesFollowTheKinematicBoneAndTheSoftBodyFalls) {
  WorldFixture f;
  const MuscleHandle muscle = f.world.addMuscle(gridMuscle(), f.bones);
  btSoftBody* ball = btSoftBodyHelpers::CreateEllipsoid(
      f.world.getWorldInfo(), btVector3(0, 0.5f, 0), btVector3(0.02f, 0.02f, 0.02f), 32);
  ball->setTotalMass(0.05f);
  f.world.addSoftBody(ball);
  const btScalar ballStart = softCentreY(*ball);

  for (int s = 1; s <= 5; ++s) {
    const std::vector<btTransform> transforms = f.step(s);
    EXPECT_EQ(f.world.muscleSteps(), s);
    EXPECT_EQ(f.world.muscleSystem().lastStep().iterations, 10);
    EXPECT_FALSE(f.world.muscleSystem().lastStep().nan);
    expectFixedParticlesOnBones(f.world.muscleSystem(), muscle, transforms);
    const btTransform read = f.world.muscleSystem().boneTransform(f.bones[1]);
    EXPECT_NEAR(read.getOrigin().distance(transforms[1].getOrigin()), 0, 1e-6);
  }
  // Free particles moved with the bone too (the middle of the muscle shifts towards +x).
  const std::span<const btVector3> positions = f.world.muscleSystem().positions(muscle);
  const MuscleSettings& settings = f.world.muscleSystem().settings(muscle);
  btScalar shift = 0;
  for (uint32_t p = 0; p < settings.particleCount(); ++p)
    if (!settings.isFixed(p)) shift += positions[p].x() - settings.restPositions[p].x();
  EXPECT_GT(shift, 0);
  EXPECT_LT(softCentreY(*ball), ballStart - 0.01f);  // 5 steps of 1/60 s under gravity

  f.world.removeSoftBody(ball);
  delete ball;
}

TEST(MuscleWorld, OneMuscleStepPerInternalBulletStep) {
  WorldFixture f;
  f.world.addMuscle(gridMuscle(), f.bones);
  f.world.stepSimulation(btScalar(3.0 / 60), 10, btScalar(1.0 / 60));
  EXPECT_EQ(f.world.muscleSteps(), 3);
  f.world.stepSimulation(btScalar(0.5 / 60), 10, btScalar(1.0 / 60));  // not a whole step yet
  EXPECT_EQ(f.world.muscleSteps(), 3);
}

TEST(MuscleWorld, MusclesAreAddedAndRemovedBetweenStepsAndStaleHandlesRejected) {
  WorldFixture f;
  const auto settings = gridMuscle();
  const MuscleHandle first = f.world.addMuscle(settings, f.bones);
  f.step(1);
  const MuscleHandle second = f.world.addMuscle(settings, f.bones);
  EXPECT_TRUE(f.world.containsMuscle(first));
  EXPECT_TRUE(f.world.containsMuscle(second));
  std::vector<btTransform> transforms = f.step(2);
  expectFixedParticlesOnBones(f.world.muscleSystem(), first, transforms);
  expectFixedParticlesOnBones(f.world.muscleSystem(), second, transforms);

  EXPECT_TRUE(f.world.removeMuscle(first));
  EXPECT_FALSE(f.world.containsMuscle(first));
  EXPECT_FALSE(f.world.removeMuscle(first));  // stale: already removed
  EXPECT_ANY_THROW(f.world.muscleSystem().positions(first));
  transforms = f.step(3);
  expectFixedParticlesOnBones(f.world.muscleSystem(), second, transforms);

  const MuscleHandle third = f.world.addMuscle(settings, f.bones);
  EXPECT_FALSE(third.index == first.index && third.generation == first.generation);
  EXPECT_FALSE(f.world.containsMuscle(first));  // still stale if the slot was reused
  EXPECT_FALSE(f.world.removeMuscle(first));
  EXPECT_TRUE(f.world.containsMuscle(third));
  const std::vector<MuscleHandle> all = f.world.muscleSystem().muscles();
  ASSERT_EQ(all.size(), 2u);
  f.step(4);
  EXPECT_EQ(f.world.muscleSystem().positions(third).size(), settings->particleCount());
}

TEST(MuscleWorld, AddBonePutsItsBodyIntoTheWorldAndRemoveBoneTakesItOut) {
  WorldFixture f;
  const int objects = f.world.getNumCollisionObjects();
  BoneBody extra(cubeBone("extra", btVector3(0, 0.1f, 0)));
  const BoneHandle added = f.world.addBone(extra.settings(), extra.body());
  EXPECT_EQ(f.world.getNumCollisionObjects(), objects + 1);
  EXPECT_TRUE(f.world.removeBone(added));
  EXPECT_EQ(f.world.getNumCollisionObjects(), objects);
  EXPECT_FALSE(f.world.removeBone(added));

  // A body the application already put into the world stays there.
  f.world.addRigidBody(extra.body());
  const BoneHandle own = f.world.addBone(extra.settings(), extra.body());
  EXPECT_EQ(f.world.getNumCollisionObjects(), objects + 1);
  EXPECT_TRUE(f.world.removeBone(own));
  EXPECT_EQ(f.world.getNumCollisionObjects(), objects + 1);
  f.world.removeRigidBody(extra.body());
}

TEST(MuscleWorld, RemovingABonesBodyFromTheWorldRemovesTheBone) {
  WorldFixture f;
  const MuscleHandle muscle = f.world.addMuscle(gridMuscle(), f.bones);
  f.step(1);
  for (const bool rigid : {true, false}) {
    auto extra = std::make_unique<BoneBody>(cubeBone("extra", btVector3(0, 0.1f, 0)));
    const BoneHandle bone = f.world.addBone(extra->settings(), extra->body());
    EXPECT_NO_THROW(f.world.muscleSystem().boneTransform(bone));
    if (rigid)
      f.world.removeRigidBody(extra->body());
    else
      f.world.removeCollisionObject(extra->body());
    // The bone went with its body: deleting the body leaves the muscles nothing to read.
    EXPECT_THROW(f.world.muscleSystem().boneTransform(bone), InputError);
    EXPECT_FALSE(f.world.removeBone(bone));
    extra.reset();
    f.step(2);
    EXPECT_FALSE(f.world.muscleSystem().lastStep().nan);
  }
  EXPECT_TRUE(f.world.containsMuscle(muscle));
  // The fixture's own bones are still bones.
  for (BoneHandle bone : f.bones) EXPECT_NO_THROW(f.world.muscleSystem().boneTransform(bone));
}

TEST(MuscleWorld, RemovingTheBodyOfABoneAMuscleIsAttachedToReleasesTheBone) {
  WorldFixture f;
  const MuscleHandle muscle = f.world.addMuscle(gridMuscle(), f.bones);
  f.step(1);
  // Bullet's removal cannot fail: a throw from it would end a host in its destructor.
  EXPECT_NO_THROW(f.world.removeRigidBody(f.movingBone.body()));
  EXPECT_THROW(f.world.muscleSystem().boneTransform(f.bones[1]), InputError);
  EXPECT_FALSE(f.world.removeBone(f.bones[1]));
  EXPECT_TRUE(f.world.containsMuscle(muscle));
  f.world.stepSimulation(btScalar(1.0 / 60), 0);
  EXPECT_FALSE(f.world.muscleSystem().lastStep().nan);
  EXPECT_NO_THROW(f.world.muscleSystem().boneTransform(f.bones[0]));
}

/// Counts what a Bullet renderer would be asked to draw.
class CountingDrawer : public btIDebugDraw {
 public:
  int lines = 0;
  void drawLine(const btVector3&, const btVector3&, const btVector3&) override { ++lines; }
  void drawContactPoint(const btVector3&, const btVector3&, btScalar, int,
                        const btVector3&) override {}
  void reportErrorWarning(const char*) override {}
  void draw3dText(const btVector3&, const char*) override {}
  void setDebugMode(int mode) override { mode_ = mode; }
  int getDebugMode() const override { return mode_; }

 private:
  int mode_ = DBG_NoDebug;
};

TEST(MuscleWorld, DebugDrawGoesThroughTheWorldsDrawer) {
  WorldFixture f;
  f.world.addMuscle(gridMuscle(), f.bones);
  f.step(1);
  CountingDrawer drawer;
  f.world.setDebugDrawer(&drawer);
  f.world.setMuscleDebugFlags(kDrawParticles | kDrawSprings | kDrawBoneSpheres);
  // The drawer's mode says nothing is to be drawn: nothing is.
  f.world.debugDrawWorld();
  EXPECT_EQ(drawer.lines, 0);
  drawer.setDebugMode(btIDebugDraw::DBG_DrawWireframe);
  f.world.setMuscleDebugFlags(0);
  f.world.debugDrawWorld();
  const int withoutMuscles = drawer.lines;
  f.world.setMuscleDebugFlags(kDrawParticles | kDrawSprings | kDrawBoneSpheres);
  f.world.debugDrawWorld();
  EXPECT_GT(drawer.lines - 2 * withoutMuscles, 0);  // the muscles drew lines of their own
  f.world.setDebugDrawer(nullptr);
}

TEST(MuscleAction, StepsMusclesInsideAnApplicationsOwnWorld) {
  btDefaultCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher(&configuration);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btDiscreteDynamicsWorld world(&dispatcher, &broadphase, &solver, &configuration);
  BoneBody left(cubeBone("left", btVector3(-0.02f, 0, 0)));
  BoneBody right(cubeBone("right", btVector3(0.02f, 0, 0)));
  world.addRigidBody(left.body());
  world.addRigidBody(right.body());

  MuscleAction action(fewIterations());
  const std::vector<BoneHandle> bones = {
      action.muscleSystem().addBone(left.settings(), left.body()),
      action.muscleSystem().addBone(right.settings(), right.body())};
  const MuscleHandle muscle = action.muscleSystem().addMuscle(gridMuscle(), bones);
  world.addAction(&action);
  for (int s = 1; s <= 3; ++s) {
    right.setTransform(movedBone(s));
    world.stepSimulation(btScalar(1.0 / 60), 0);
    EXPECT_EQ(action.muscleSystem().lastStep().iterations, 10);
    expectFixedParticlesOnBones(action.muscleSystem(), muscle,
                                {btTransform::getIdentity(), movedBone(s)});
  }
  CountingDrawer drawer;
  drawer.setDebugMode(btIDebugDraw::DBG_DrawWireframe);
  world.setDebugDrawer(&drawer);
  world.debugDrawWorld();  // Bullet calls the action's debugDraw in wireframe mode
  EXPECT_GT(drawer.lines, 0);
  world.setDebugDrawer(nullptr);
  world.removeAction(&action);
  world.removeRigidBody(right.body());
  world.removeRigidBody(left.body());
}

}  // namespace
}  // namespace fibremss
