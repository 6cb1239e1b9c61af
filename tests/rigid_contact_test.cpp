// Two-way contact with rigid bodies (fibremss/RigidContact.h) in real Bullet
// worlds: a ball dropped on a muscle lying on a bone stops on it (never through), the muscle
// dents and recovers; momentum is conserved between a ball and a free muscle; a probe pressed
// deeper feels more force; the dynamic time mode advances exactly Bullet's dt; without contact
// bodies a step is bit-identical to the plain solver's; any thread count gives the same bits;
// the contact path allocates nothing; contact damping takes a landing ball's impact.
#include <BulletCollision/BroadphaseCollision/btDbvtBroadphase.h>
#include <BulletCollision/CollisionShapes/btBoxShape.h>
#include <BulletCollision/CollisionShapes/btSphereShape.h>
#include <BulletDynamics/ConstraintSolver/btSequentialImpulseConstraintSolver.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <limits>
#include <memory>
#include <vector>

#include "fibremss/BoneBody.h"
#include "fibremss/Error.h"
#include "fibremss/MuscleAction.h"
#include "fibremss/MuscleWorld.h"
#include "support/AllocationCounter.h"
#include "support/SlabMuscle.h"
#include "support/SolverFixtures.h"

namespace fibremss {
namespace {

using testing::slabBone;
using testing::slabMuscle;

constexpr btScalar kSpacing = btScalar(0.004);  // slab particle spacing [m]
constexpr int kSide = 9;                        // particles along x and z
constexpr int kLayers = 3;                      // particles along y
constexpr btScalar kWidth = (kSide - 1) * kSpacing;
constexpr btScalar kTop = (kLayers - 1) * kSpacing + kSpacing / 2;  // slab's upper surface [m]
constexpr btScalar kBulletStep = btScalar(1.0 / 480);               // fixed Bullet step [s]

MuscleSystemDef slabParameters(int threads = 1,
                               btScalar contactDamping = MuscleSystemDef{}.contactDamping) {
  MuscleSystemDef parameters = testing::verletDef();
  parameters.contactDamping = contactDamping;
  parameters.stepSettings.timeStep = btScalar(5e-5);  // below the slab's stable dt (about 1e-4 s)
  parameters.stepSettings.iterations = 20;
  parameters.threads = threads;
  return parameters;
}

/// A dynamic sphere body with its shape and motion state.
struct Ball {
  btSphereShape shape;
  btDefaultMotionState motion;
  btRigidBody body;
  Ball(btScalar radius, btScalar mass, const btVector3& centre)
      : shape(radius),
        motion(btTransform(btQuaternion::getIdentity(), centre)),
        body(mass, &motion, &shape, inertia(shape, mass)) {
    body.setActivationState(DISABLE_DEACTIVATION);
  }
  static btVector3 inertia(btSphereShape& shape, btScalar mass) {
    btVector3 i(0, 0, 0);
    shape.calculateLocalInertia(mass, i);
    return i;
  }
  btScalar bottom() const { return body.getWorldTransform().getOrigin().y() - shape.getRadius(); }
};

/// A MuscleWorld with slab muscles lying on one slab bone (x side by side), Dynamic time.
struct SlabWorld {
  btSoftBodyRigidBodyCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher{&configuration};
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  MuscleWorld world;
  std::unique_ptr<BoneBody> bone;
  BoneHandle boneHandle;
  std::vector<MuscleHandle> muscles;

  explicit SlabWorld(int slabs = 1, int threads = 1, btScalar kappa = 5,
                     btScalar contactDamping = MuscleSystemDef{}.contactDamping)
      : world(&dispatcher, &broadphase, &solver, &configuration,
              slabParameters(threads, contactDamping)) {
    world.setGravity(btVector3(0, btScalar(-9.81), 0));
    WorldCoupling coupling;
    coupling.time = MuscleTime::Dynamic;
    world.setCoupling(coupling);
    const btScalar pitch = kWidth + kSpacing + btScalar(0.0005);
    bone = std::make_unique<BoneBody>(slabBone(pitch * slabs, kWidth, kSpacing));
    boneHandle = world.addBone(bone->settings(), bone->body());
    for (int s = 0; s < slabs; ++s)
      muscles.push_back(world.addMuscle(slabMuscle(kSide, kLayers, kSide, kSpacing, kappa,
                                                   btScalar(0.3), true, btVector3(pitch * s, 0, 0)),
                                        std::span(&boneHandle, 1)));
  }
  ~SlabWorld() {
    for (MuscleHandle m : muscles) world.removeMuscle(m);
    world.removeBone(boneHandle);
  }
  void step(int count = 1) {
    for (int k = 0; k < count; ++k) world.stepSimulation(kBulletStep, 1, kBulletStep);
  }
  /// Mean y of the top layer's particles within `radius` of (x, z).
  btScalar topHeight(MuscleHandle muscle, btScalar x, btScalar z, btScalar radius) const {
    const std::span<const btVector3> p = world.muscleSystem().positions(muscle);
    const MuscleSettings& settings = world.muscleSystem().settings(muscle);
    btScalar sum = 0;
    int count = 0;
    for (size_t i = 0; i < p.size(); ++i) {
      const btVector3& rest = settings.restPositions[i];
      if (rest.y() < (kLayers - 1) * kSpacing - 1e-6f) continue;
      if (btVector3(rest.x() - x, 0, rest.z() - z).length() > radius) continue;
      sum += p[i].y();
      ++count;
    }
    return count ? sum / btScalar(count) : 0;
  }
};

// ---- The ball on the muscle ----------------------------------------------------------------

TEST(RigidContact, ABallDroppedOnAMuscleStopsOnItAndTheMuscleDentsAndRecovers) {
  SlabWorld f;
  const MuscleHandle slab = f.muscles.front();
  const btScalar centre = kWidth / 2;
  f.step(20);  // the muscle at rest on its bone
  const btScalar restTop = f.topHeight(slab, centre, centre, 1.5f * kSpacing);

  const btScalar radius = 0.008f, mass = 0.02f;
  Ball ball(radius, mass, btVector3(centre, kTop + radius + 0.01f, centre));
  const btScalar dropped = ball.bottom();
  f.world.addRigidBody(&ball.body);
  btScalar lowest = dropped, highestAfter = 0, deepestDent = 0;
  btVector3 reported(0, 0, 0);
  btVector3 measured(0, 0, 0);  // Δp of the ball that is not gravity's
  size_t touching = 0;
  bool bounced = false;
  for (int s = 0; s < 240; ++s) {  // half a second
    const btVector3 before = ball.body.getLinearVelocity();
    f.step();
    const btVector3 after = ball.body.getLinearVelocity();
    measured += (after - before - f.world.getGravity() * kBulletStep) * mass;
    const BodyContact contact = f.world.bodyContact(&ball.body);
    reported += contact.impulse;
    touching += contact.contacts > 0 ? 1 : 0;
    if (touching > 0) {
      highestAfter = std::max(highestAfter, ball.bottom());
      bounced = bounced || after.y() > 0.1f;
    }
    lowest = std::min(lowest, ball.bottom());
    deepestDent =
        std::max(deepestDent, restTop - f.topHeight(slab, centre, centre, 1.5f * kSpacing));
    ASSERT_FALSE(f.world.muscleSystem().lastStep().nan) << "step " << s;
  }
  ASSERT_GT(touching, 0u) << "the ball never touched the muscle";
  // Never through: the ball's lowest point stays well above the bottom layer (y = 0).
  EXPECT_GT(lowest, kTop - 3 * kSpacing / 2) << "lowest " << lowest;
  // It bounced off the muscle (or came to rest on it), and lower than it was dropped from: the
  // contact makes no energy.
  const bool resting =
      ball.body.getLinearVelocity().length() < 0.02f && std::abs(ball.bottom() - kTop) < kSpacing;
  EXPECT_TRUE(bounced || resting);
  EXPECT_LT(highestAfter, dropped - 1e-3f);
  EXPECT_GT(deepestDent, 2e-4f) << "the muscle did not dent";
  // The momentum the ball exchanged with the muscle is the impulse reported, within 1 %.
  ASSERT_GT(reported.length(), mass * 0.44f);  // at least the impact momentum
  EXPECT_LT((measured - reported).length(), 0.01f * reported.length())
      << "measured " << measured.y() << " reported " << reported.y();

  // Take the ball away: the muscle recovers its shape.
  f.world.removeRigidBody(&ball.body);
  f.step(240);
  EXPECT_NEAR(f.topHeight(slab, centre, centre, 1.5f * kSpacing), restTop, 5e-5f);
  EXPECT_EQ(f.world.bodyContact(&ball.body).contacts, 0u);
}

/// The fastest a 20 g ball dropped 10 mm on the slab moves up after it first touched it, over
/// half a second of Dynamic steps [m/s], with the contact damping `contactDamping`.
btScalar reboundSpeed(btScalar contactDamping) {
  SlabWorld f(1, 1, 5, contactDamping);
  f.step(20);  // the muscle at rest on its bone
  const btScalar radius = 0.008f, centre = kWidth / 2;
  Ball ball(radius, 0.02f, btVector3(centre, kTop + radius + 0.01f, centre));
  f.world.addRigidBody(&ball.body);
  bool touched = false;
  btScalar fastestUp = 0;
  for (int s = 0; s < 240; ++s) {
    f.step();
    touched = touched || f.world.bodyContact(&ball.body).contacts > 0;
    if (touched) fastestUp = std::max(fastestUp, ball.body.getLinearVelocity().y());
  }
  f.world.removeRigidBody(&ball.body);
  return fastestUp;
}

TEST(RigidContact, ContactDampingTakesALandingBallsImpact) {
  // Particles touching the ball are damped along the contact normal: the muscle returns less of
  // the impact, and the ball bounces back slower than from the muscle without contact damping.
  const btScalar undamped = reboundSpeed(0);
  ASSERT_GT(undamped, 0) << "the ball did not bounce without contact damping";
  EXPECT_LT(reboundSpeed(MuscleSystemDef{}.contactDamping), undamped);
}

/// What a ball dropped on a muscle in a default world did: speeds [m/s] and heights [m].
struct Landing {
  btScalar impact = 0;        ///< its speed in the step before it first touched the muscle
  btScalar fastestAfter = 0;  ///< its fastest speed from then on
  btScalar lowest = 1;        ///< the lowest its lowest point came from then on
  btScalar restSpeed = 0;     ///< the fastest it moved over the last half second (Δx per frame)
  btScalar bottom = 0;        ///< its lowest point at the end
};

/// Drops a 20 g ball 20 mm onto a slab muscle in a world of default parameters and coupling
/// (the projective solver, QuasiStaticPose) for two seconds of stepSimulation(1/60, substeps,
/// fixed).
Landing dropOnADefaultWorld(int substeps, btScalar fixed) {
  btSoftBodyRigidBodyCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher(&configuration);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  MuscleWorld world(&dispatcher, &broadphase, &solver, &configuration, MuscleSystemDef{});
  world.setGravity(btVector3(0, btScalar(-9.81), 0));
  BoneBody bone(slabBone(kWidth, kWidth, kSpacing));
  const BoneHandle boneHandle = world.addBone(bone.settings(), bone.body());
  const MuscleHandle slab =
      world.addMuscle(slabMuscle(kSide, kLayers, kSide, kSpacing, 5, btScalar(0.3), true),
                      std::span(&boneHandle, 1));
  const btScalar frame = btScalar(1.0 / 60), radius = 0.008f, centre = kWidth / 2;
  Ball ball(radius, 0.02f, btVector3(centre, kTop + radius + 0.02f, centre));
  world.addRigidBody(&ball.body);
  Landing landing;
  for (int s = 0; s < 120; ++s) {
    const btScalar before = ball.body.getLinearVelocity().length();
    const btVector3 from = ball.body.getWorldTransform().getOrigin();
    world.stepSimulation(frame, substeps, fixed);
    EXPECT_FALSE(world.muscleSystem().lastStep().nan) << "step " << s;
    if (world.bodyContact(&ball.body).contacts > 0 && landing.impact == 0) landing.impact = before;
    if (landing.impact == 0) continue;
    landing.fastestAfter = std::max(landing.fastestAfter, ball.body.getLinearVelocity().length());
    landing.lowest = std::min(landing.lowest, ball.bottom());
    if (s >= 90)
      landing.restSpeed = std::max(
          landing.restSpeed, (ball.body.getWorldTransform().getOrigin() - from).length() / frame);
  }
  landing.bottom = ball.bottom();
  world.removeRigidBody(&ball.body);
  world.removeMuscle(slab);
  world.removeBone(boneHandle);
  return landing;
}

TEST(RigidContact, InADefaultWorldABallDroppedOnAMuscleComesToRestOnIt) {
  // The muscles hold the ball's weight (their static reaction) and it cannot pass a particle
  // sphere in one step: it rests on the surface at 60 Hz (one Bullet step a frame, as
  // stepSimulation(1/60) steps) and at 240 Hz, never thrown.
  for (const int substeps : {1, 4}) {
    SCOPED_TRACE(::testing::Message() << substeps << " Bullet steps a frame");
    const Landing landing = dropOnADefaultWorld(substeps, btScalar(1.0 / 60) / substeps);
    ASSERT_GT(landing.impact, 0.3f) << "the ball never touched the muscle";
    EXPECT_LE(landing.fastestAfter, landing.impact) << "thrown faster than it landed";
    EXPECT_LT(landing.restSpeed, 2e-3f) << "not at rest";
    // On the surface (kTop), within a particle radius (kSpacing / 2) or two: not sunk in.
    EXPECT_NEAR(landing.bottom, kTop, kSpacing) << "not resting on the muscle";
    EXPECT_GT(landing.lowest, kTop - kSpacing) << "sank into the muscle";
  }
}

TEST(RigidContact, MomentumIsConservedBetweenABallAndAFreeMuscle) {
  btSoftBodyRigidBodyCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher(&configuration);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  MuscleWorld world(&dispatcher, &broadphase, &solver, &configuration, slabParameters());
  world.setGravity(btVector3(0, 0, 0));
  WorldCoupling coupling;
  coupling.time = MuscleTime::Dynamic;
  world.setCoupling(coupling);
  // A free slab without damping (internal forces only): its momentum is the centre's motion.
  const auto settings = slabMuscle(5, 3, 5, kSpacing, 5, 0, false);
  const MuscleHandle slab = world.addMuscle(settings, {});
  const btScalar muscleMass = settings->particleMass * btScalar(settings->particleCount());
  const auto centreOf = [&] {
    btVector3 sum(0, 0, 0);
    for (const btVector3& p : world.muscleSystem().positions(slab)) sum += p;
    return sum / btScalar(settings->particleCount());
  };
  const btScalar mass = 0.01f, speed = 0.3f;
  Ball ball(0.006f, mass, btVector3(-0.012f, kSpacing, 2 * kSpacing));
  ball.body.setLinearVelocity(btVector3(speed, 0, 0));
  world.addRigidBody(&ball.body);
  int apart = 0, steps = 0;
  bool touched = false;
  // Until the two have separated for 20 steps.
  for (; steps < 2000 && apart < 20; ++steps) {
    world.stepSimulation(kBulletStep, 1, kBulletStep);
    const bool touching = world.bodyContact(&ball.body).contacts > 0;
    touched = touched || touching;
    apart = touched && !touching ? apart + 1 : 0;
  }
  ASSERT_TRUE(touched);
  ASSERT_EQ(apart, 20) << "still in contact after " << steps << " steps";
  const btVector3 start = centreOf();
  world.stepSimulation(kBulletStep, 1, kBulletStep);
  const btVector3 muscleVelocity = (centreOf() - start) / kBulletStep;
  const btVector3 total = ball.body.getLinearVelocity() * mass + muscleVelocity * muscleMass;
  EXPECT_GT(muscleVelocity.x(), 0.1f * speed) << "the ball did not push the muscle";
  EXPECT_LT((total - btVector3(mass * speed, 0, 0)).length(), 0.01f * mass * speed)
      << "before " << mass * speed << " after " << total.x() << " " << total.y() << " "
      << total.z();
  world.removeRigidBody(&ball.body);
}

// ---- The probe -----------------------------------------------------------------------------

TEST(RigidContact, AProbePressedDeeperIntoAMuscleFeelsMoreForce) {
  SlabWorld f;
  const btScalar centre = kWidth / 2, radius = 0.005f;
  btSphereShape shape(radius);
  btRigidBody probe(0, nullptr, &shape);  // kinematic: the user moves it
  probe.setCollisionFlags(probe.getCollisionFlags() | btCollisionObject::CF_KINEMATIC_OBJECT);
  probe.setActivationState(DISABLE_DEACTIVATION);
  const auto place = [&](btScalar depth) {
    return btTransform(btQuaternion::getIdentity(),
                       btVector3(centre, kTop + radius - depth, centre + 0.0007f));
  };
  probe.setWorldTransform(place(-0.002f));
  f.world.addRigidBody(&probe);
  std::vector<btScalar> forces;
  for (btScalar depth : {0.0005f, 0.001f, 0.0015f, 0.002f, 0.0025f}) {
    probe.setWorldTransform(place(depth));
    f.step(120);  // a quarter second at this depth: settled
    const ContactWrench wrench = f.world.contactWrench(probe);
    EXPECT_GT(f.world.bodyContact(&probe).contacts, 0u) << depth;
    EXPECT_NEAR(wrench.force.y(), f.world.bodyContact(&probe).force.y(),
                0.05f * std::abs(wrench.force.y()))
        << "at the pose of the last step the Hooke term is small";
    // Between steps, the haptic query follows the tool at once: deeper is stronger.
    EXPECT_GT(f.world.contactWrench(probe, place(depth + 0.0003f)).force.y(), wrench.force.y());
    forces.push_back(wrench.force.y());
  }
  for (size_t k = 0; k < forces.size(); ++k) {
    EXPECT_GT(forces[k], 0) << "the muscle pushes the probe up";
    if (k > 0) {
      EXPECT_GT(forces[k], forces[k - 1]) << "depth " << k;
    }
  }
  f.world.removeRigidBody(&probe);
}

// ---- Time and identity ---------------------------------------------------------------------

TEST(RigidContact, DynamicTimeAdvancesExactlyBulletsStep) {
  SlabWorld f;
  f.step();
  const StepStats& stats = f.world.muscleSystem().lastStep();
  // k = max(20, ⌈(1/480) / 5e-5⌉) = 42 iterations of dt/k.
  EXPECT_EQ(stats.iterations, 42);
  EXPECT_NEAR(stats.simulatedTime, kBulletStep, 1e-9);
  EXPECT_FLOAT_EQ(stats.lastTimeStep, kBulletStep / 42);
  EXPECT_THROW(f.world.muscleSystem().step(btScalar(0)), InputError);
  WorldCoupling bad;
  bad.reach = -1;
  EXPECT_THROW(f.world.setCoupling(bad), InputError);
}

TEST(RigidContact, AHugeDynamicStepIsCutShortAndANanQueryPoseIsAnError) {
  SlabWorld f;
  f.world.stepSimulation(btScalar(1e30), 0);  // a variable step: one internal step of 1e30 s
  const StepStats& stats = f.world.muscleSystem().lastStep();
  EXPECT_TRUE(stats.shortened);
  EXPECT_EQ(stats.iterations, 16384);
  EXPECT_LT(stats.simulatedTime, 1.0);  // 16384 iterations of the stable dt (5e-5 s)
  EXPECT_FALSE(stats.nan);
  f.step();
  EXPECT_FALSE(f.world.muscleSystem().lastStep().shortened);
  btSphereShape shape(0.005f);
  btRigidBody probe(0, nullptr, &shape);
  const btScalar nan = std::numeric_limits<btScalar>::quiet_NaN();
  EXPECT_THROW(
      f.world.contactWrench(probe, btTransform(btQuaternion::getIdentity(), btVector3(nan, 0, 0))),
      InputError);
}

/// Positions after `steps` steps of a grid muscle between two moving bones: in a MuscleWorld
/// with `coupling` and, when `farBall`, a dynamic ball far out of reach; or (`plain`) in a bare
/// MuscleSystem without any world, the path before contact existed.
std::vector<btVector3> gridRun(bool plain, const WorldCoupling& coupling, bool farBall) {
  MuscleSystemDef parameters = slabParameters();
  parameters.stepSettings.iterations = 15;
  const auto settings = slabMuscle(5, 3, 4, kSpacing, 2, btScalar(0.2), true);
  const auto boneSettings = slabBone(4 * kSpacing, 3 * kSpacing, kSpacing);
  const auto moved = [](int s) {
    return btTransform(btQuaternion(btVector3(0, 0, 1), btScalar(0.01) * s),
                       btVector3(btScalar(0.0005) * s, 0, 0));
  };
  const int steps = 8;
  if (plain) {
    MuscleSystem system(parameters);
    const BoneHandle bone = system.addBone(boneSettings);
    const MuscleHandle muscle = system.addMuscle(settings, std::span(&bone, 1));
    for (int s = 1; s <= steps; ++s) {
      system.setBoneTransform(bone, moved(s));
      system.step();
    }
    const std::span<const btVector3> p = system.positions(muscle);
    return {p.begin(), p.end()};
  }
  btSoftBodyRigidBodyCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher(&configuration);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  MuscleWorld world(&dispatcher, &broadphase, &solver, &configuration, parameters);
  world.setCoupling(coupling);
  BoneBody bone(boneSettings);
  const BoneHandle handle = world.addBone(bone.settings(), bone.body());
  const MuscleHandle muscle = world.addMuscle(settings, std::span(&handle, 1));
  Ball ball(0.01f, 0.1f, btVector3(5, 5, 5));
  if (farBall) world.addRigidBody(&ball.body);
  for (int s = 1; s <= steps; ++s) {
    bone.setTransform(moved(s));
    world.stepSimulation(btScalar(1.0 / 60), 0);
  }
  const std::span<const btVector3> p = world.muscleSystem().positions(muscle);
  std::vector<btVector3> positions(p.begin(), p.end());
  if (farBall) world.removeRigidBody(&ball.body);
  world.removeMuscle(muscle);
  world.removeBone(handle);
  return positions;
}

bool sameBits(const std::vector<btVector3>& a, const std::vector<btVector3>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(btVector3)) == 0;
}

TEST(RigidContact, WithoutContactBodiesTheDefaultsAreBitIdenticalToThePlainSolver) {
  const std::vector<btVector3> plain = gridRun(true, {}, false);
  WorldCoupling off;
  off.rigidContact = false;
  EXPECT_TRUE(sameBits(gridRun(false, {}, false), plain)) << "defaults, no body";
  EXPECT_TRUE(sameBits(gridRun(false, {}, true), plain)) << "defaults, a ball out of reach";
  EXPECT_TRUE(sameBits(gridRun(false, off, true), plain)) << "contact off";
}

/// The ball and muscle positions of two slabs a ball lands on across both, with `threads`.
std::vector<btVector3> twoSlabDrop(int threads) {
  SlabWorld f(2, threads);
  const btScalar pitch = kWidth + kSpacing + btScalar(0.0005);
  Ball ball(0.008f, 0.02f, btVector3(pitch - kSpacing, kTop + 0.009f, kWidth / 2));
  f.world.addRigidBody(&ball.body);
  size_t touching = 0;
  for (int s = 0; s < 60; ++s) {
    f.step();
    touching += f.world.bodyContact(&ball.body).contacts;
  }
  EXPECT_GT(touching, 0u);
  std::vector<btVector3> result{ball.body.getWorldTransform().getOrigin(),
                                ball.body.getLinearVelocity(), ball.body.getAngularVelocity()};
  for (MuscleHandle m : f.muscles) {
    const std::span<const btVector3> p = f.world.muscleSystem().positions(m);
    result.insert(result.end(), p.begin(), p.end());
  }
  f.world.removeRigidBody(&ball.body);
  return result;
}

TEST(RigidContact, OneAndTwoThreadsGiveTheSameBits) {
  EXPECT_TRUE(sameBits(twoSlabDrop(1), twoSlabDrop(2)));
}

TEST(RigidContact, TheContactPathAllocatesNothing) {
  btAlignedAllocSetCustom(testing::countingAlloc, std::free);
  {
    SlabWorld f(2, 2);
    // A kinematic ball held 2 mm deep in the slab: contacts in every step.
    Ball ball(0.008f, 0, btVector3(kWidth / 2, kTop + 0.006f, kWidth / 2));
    ball.body.setCollisionFlags(ball.body.getCollisionFlags() |
                                btCollisionObject::CF_KINEMATIC_OBJECT);
    f.world.addRigidBody(&ball.body);
    // MuscleAction's path (gather through the broadphase, step, impulses) called directly:
    // Bullet's own step allocates contact manifolds of its own pairs.
    MuscleAction action(slabParameters(2));
    WorldCoupling coupling;
    coupling.time = MuscleTime::Dynamic;
    action.setCoupling(coupling);
    const BoneHandle bone = action.muscleSystem().addBone(f.bone->settings(), f.bone->body());
    action.muscleSystem().addMuscle(
        slabMuscle(kSide, kLayers, kSide, kSpacing, 5, btScalar(0.3), true), std::span(&bone, 1));
    action.updateAction(&f.world, kBulletStep);  // first step: the lists grow to the bodies
    f.step(2);
    testing::allocationCount = 0;
    testing::countingArmed = true;
    for (int s = 0; s < 10; ++s) {
      action.updateAction(&f.world, kBulletStep);
      (void)f.world.contactWrench(ball.body);
    }
    testing::countingArmed = false;
    EXPECT_GT(action.muscleSystem().bodyContact(&ball.body).contacts, 0u) << "no contact ran";
    EXPECT_EQ(testing::allocationCount.load(), 0);
    f.world.removeRigidBody(&ball.body);
  }
  btAlignedAllocSetCustom(nullptr, nullptr);
}

// ---- Gravity and external forces -----------------------------------------------------------

TEST(RigidContact, GravityAndExternalForcesMoveFreeParticles) {
  MuscleSystemDef parameters = slabParameters();
  parameters.gravity = btVector3(0, -9.81f, 0);
  MuscleSystem system(parameters);
  const BoneHandle bone = system.addBone(slabBone(kWidth, kWidth, kSpacing));
  const auto settings = slabMuscle(kSide, kLayers, kSide, kSpacing, 5, btScalar(0.3), true);
  const MuscleHandle muscle = system.addMuscle(settings, std::span(&bone, 1));
  const size_t top = settings->particleCount() - 1;
  for (int s = 0; s < 20; ++s) system.step(kBulletStep);
  EXPECT_LT(system.positions(muscle)[top].y(), settings->restPositions[top].y()) << "sags";
  const btScalar sagged = system.positions(muscle)[top].y();
  system.setExternalForce(muscle, static_cast<uint32_t>(top), btVector3(0, 0.5f, 0));
  for (int s = 0; s < 20; ++s) system.step(kBulletStep);
  EXPECT_GT(system.positions(muscle)[top].y(), sagged + 1e-4f) << "pulled up";
  EXPECT_THROW(system.setExternalForce(muscle, 100000, btVector3(0, 1, 0)), InputError);
  EXPECT_THROW(system.setExternalForce(muscle, 0, btVector3(NAN, 0, 0)), InputError);
  system.clearExternalForces(muscle);
}

}  // namespace
}  // namespace fibremss
