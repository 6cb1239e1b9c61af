// Sphere collision (method.md §6): the btDbvt broad phase against brute force, the response (half /
// whole overlap, accumulated from the starting positions, order-independent), the collision
// switches, and no tunnelling with the adaptive time step; the bone distance field against exact
// distances; exact sphere–shape contacts (spheres, boxes, capsules, convex hulls).
#include <BulletCollision/CollisionShapes/btBoxShape.h>
#include <BulletCollision/CollisionShapes/btCapsuleShape.h>
#include <BulletCollision/CollisionShapes/btConvexHullShape.h>
#include <BulletCollision/CollisionShapes/btSphereShape.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "contact/ShapeContact.h"
#include "fibremss/Error.h"
#include "fibremss/Geometry.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Procedural.h"
#include "geometry/BoneDistanceField.h"
#include "geometry/CollisionTrees.h"
#include "geometry/SurfaceContact.h"
#include "support/GridMuscle.h"
#include "support/SolverFixtures.h"

namespace fibremss {
namespace {

using testing::fix;
using testing::makeBone;
using testing::makeSpheres;

/// One iteration per step: every test below looks at a single response.
MuscleSystemDef oneIteration() {
  MuscleSystemDef parameters = testing::verletDef();
  parameters.stepSettings.iterations = 1;
  return parameters;
}

TEST(Response, TwoOverlappingSpheresMoveHalfTheOverlapEach) {
  const btVector3 a(0.01, 0.02, -0.01), b(0.013, 0.021, -0.0095);
  const btScalar ra = 0.003, rb = 0.002;
  MuscleSystem system(oneIteration());
  const MuscleHandle ha = system.addMuscle(makeSpheres({a}, {ra}), {});
  const MuscleHandle hb = system.addMuscle(makeSpheres({b}, {rb}), {});
  const btScalar overlap = ra + rb - (a - b).length();
  ASSERT_GT(overlap, 0);
  system.step();
  EXPECT_EQ(system.lastStep().contacts, 1u);
  const btVector3 pa = system.positions(ha)[0], pb = system.positions(hb)[0];
  EXPECT_NEAR((pa - pb).length(), ra + rb, 1e-7);
  EXPECT_NEAR((pa - a).length(), overlap / 2, 1e-7);
  EXPECT_NEAR((pb - b).length(), overlap / 2, 1e-7);
  EXPECT_LT(((pa + pb) / 2 - (a + b) / 2).length(), 1e-7);  // the midpoint stays
  // Along the line of centres.
  EXPECT_NEAR((pa - a).normalized().dot((a - b).normalized()), 1, 1e-5);
  // Velocity zeroed: nothing moves afterwards.
  system.step();
  EXPECT_LT((system.positions(ha)[0] - pa).length(), 1e-9);
  EXPECT_LT((system.positions(hb)[0] - pb).length(), 1e-9);
}

TEST(Response, AFixedParticleLeavesTheWholeOverlapToTheFreeOne) {
  const btVector3 a(0, 0, 0), b(0.004, 0, 0);
  MuscleSystem system(oneIteration());
  const BoneHandle bone = system.addBone(makeBone());
  auto fixed = makeSpheres({b}, {0.002});
  fix(*fixed, 0, 0);
  const MuscleHandle ha = system.addMuscle(makeSpheres({a}, {0.003}), {});
  const MuscleHandle hb = system.addMuscle(fixed, std::span(&bone, 1));
  system.step();
  EXPECT_NEAR(system.positions(ha)[0].x(), -0.001, 1e-8);
  EXPECT_EQ(system.positions(hb)[0], b);
}

TEST(Response, ASphereAgainstABoneSphereMovesTheWholeOverlap) {
  // The bone is rotated and moved: the query runs in the bone's frame.
  const btTransform boneToWorld(btQuaternion(btVector3(1, 1, 0).normalized(), 0.8),
                                btVector3(0.1, -0.05, 0.2));
  const btVector3 centreLocal(0.01, 0.0, 0.02);
  const btScalar boneRadius = 0.01, radius = 0.002;
  const btVector3 centre = boneToWorld * centreLocal;
  const btVector3 direction = btVector3(0.3, -0.5, 0.8).normalized();
  const btVector3 start = centre + direction * 0.011;  // overlap 1 mm
  MuscleSystemDef parameters = oneIteration();
  parameters.muscleMuscle = false;
  MuscleSystem system(parameters);
  const BoneHandle bone = system.addBone(makeBone({centreLocal}, {boneRadius}));
  system.setBoneTransform(bone, boneToWorld);
  system.step();  // the bone moves to its pose (no muscle yet)
  const MuscleHandle muscle = system.addMuscle(makeSpheres({start}, {radius}), {});
  system.step();
  const btVector3 end = system.positions(muscle)[0];
  EXPECT_NEAR((end - centre).length(), boneRadius + radius, 1e-7);
  EXPECT_NEAR((end - start).length(), 0.001, 1e-7);
  EXPECT_NEAR((end - start).normalized().dot(direction), 1, 1e-5);
}

/// A particle overlapping three bone spheres and a sphere of another muscle, the bone's spheres
/// listed in the given order; returns the particle's position after one iteration.
btVector3 pushedBy(const std::vector<int>& order) {
  const std::vector<btVector3> centres{{0.01, 0, 0}, {0, 0.0105, 0}, {-0.002, -0.002, 0.011}};
  const std::vector<btScalar> radii{0.009, 0.0095, 0.01};
  std::vector<btVector3> orderedCentres;
  std::vector<btScalar> orderedRadii;
  for (int k : order) {
    orderedCentres.push_back(centres[k]);
    orderedRadii.push_back(radii[k]);
  }
  MuscleSystem system(oneIteration());
  system.addBone(makeBone(orderedCentres, orderedRadii));
  const MuscleHandle particle = system.addMuscle(makeSpheres({{0, 0, 0}}, {0.0015}), {});
  system.addMuscle(makeSpheres({{0, 0, -0.002}}, {0.001}), {});
  system.step();
  EXPECT_EQ(system.lastStep().contacts, 4u);
  return system.positions(particle)[0];
}

TEST(Response, AccumulatedPushesAreIndependentOfPairOrder) {
  // Expected: every push computed from the starting position, summed.
  const btVector3 start(0, 0, 0);
  btVector3 expected = start;
  const std::vector<btVector3> centres{{0.01, 0, 0}, {0, 0.0105, 0}, {-0.002, -0.002, 0.011}};
  const std::vector<btScalar> radii{0.009, 0.0095, 0.01};
  for (size_t k = 0; k < 3; ++k) {
    const btScalar overlap = radii[k] + 0.0015 - (start - centres[k]).length();
    ASSERT_GT(overlap, 0);
    expected += (start - centres[k]).normalized() * overlap;
  }
  expected += btVector3(0, 0, 1) * ((0.0015 + 0.001 - 0.002) / 2);
  std::vector<int> order{0, 1, 2};
  do {
    const btVector3 result = pushedBy(order);
    EXPECT_LT((result - expected).length(), 1e-8) << order[0] << order[1] << order[2];
  } while (std::next_permutation(order.begin(), order.end()));
}

TEST(Switches, NoSelfCollisionAndCollisionTogglesAreRespected) {
  const std::vector<btVector3> overlapping{{0, 0, 0}, {0.002, 0, 0}};
  {
    MuscleSystem system(oneIteration());
    const MuscleHandle h = system.addMuscle(makeSpheres(overlapping, {0.002, 0.002}), {});
    system.step();
    EXPECT_EQ(system.lastStep().contacts, 0u);  // one muscle: no self-collision
    EXPECT_EQ(system.positions(h)[0], overlapping[0]);
  }
  for (bool muscleMuscle : {false, true})
    for (bool muscleBone : {false, true}) {
      MuscleSystemDef parameters = oneIteration();
      parameters.muscleMuscle = muscleMuscle;
      parameters.muscleBone = muscleBone;
      MuscleSystem system(parameters);
      system.addBone(makeBone({{0, -0.0035, 0}}, {0.002}));
      const MuscleHandle a = system.addMuscle(makeSpheres({overlapping[0]}, {0.002}), {});
      system.addMuscle(makeSpheres({overlapping[1]}, {0.002}), {});
      system.step();
      EXPECT_EQ(system.lastStep().contacts, size_t(muscleMuscle) + size_t(muscleBone));
      const btVector3 moved = system.positions(a)[0] - overlapping[0];
      EXPECT_EQ(moved.x() != 0, muscleMuscle);
      EXPECT_EQ(moved.y() != 0, muscleBone);
    }
}

// ---- Broad phase against brute force -------------------------------------------------------

using PairSet = std::set<std::pair<int, int>>;

struct RandomSpheres {
  std::vector<btVector3> centres, velocities;
  std::vector<btScalar> radii;
  std::vector<uint32_t> indices;
};

/// Collects the leaf pairs whose spheres overlap exactly; counts the candidates.
struct PairRecorder {
  PairRecorder(const RandomSpheres& first, const RandomSpheres& second) : a(first), b(second) {}
  void operator()(int32_t i, int32_t j) {
    ++candidates;
    const btScalar reach = a.radii[i] + b.radii[j];
    if ((a.centres[i] - b.centres[j]).length2() < reach * reach) pairs.insert({i, j});
  }
  const RandomSpheres& a;
  const RandomSpheres& b;
  PairSet pairs;
  size_t candidates = 0;
};

PairSet bruteForce(const std::vector<btVector3>& a, const std::vector<btScalar>& ra,
                   const std::vector<btVector3>& b, const std::vector<btScalar>& rb,
                   const btTransform& bToWorld = btTransform::getIdentity()) {
  PairSet pairs;
  for (size_t i = 0; i < a.size(); ++i)
    for (size_t j = 0; j < b.size(); ++j) {
      const btScalar reach = ra[i] + rb[j];
      if ((a[i] - bToWorld * b[j]).length2() < reach * reach)
        pairs.insert({static_cast<int>(i), static_cast<int>(j)});
    }
  return pairs;
}

RandomSpheres randomSpheres(std::mt19937& random, size_t n, btScalar box) {
  std::uniform_real_distribution<btScalar> position(-box, box), radius(0.001, 0.004),
      speed(-0.002, 0.002);
  RandomSpheres spheres;
  for (uint32_t i = 0; i < n; ++i) {
    spheres.centres.emplace_back(position(random), position(random), position(random));
    spheres.velocities.emplace_back(speed(random), speed(random), speed(random));
    spheres.radii.push_back(radius(random));
    spheres.indices.push_back(i);
  }
  // A few fast ones, which leave their fattened bounds every iteration.
  for (size_t i = 0; i < n; i += 17) spheres.velocities[i] *= 8;
  return spheres;
}

/// Moves the spheres (bouncing in the box, random jitter) and refits their tree, or rebuilds it
/// every tenth iteration (the thesis mode).
void moveAndRefit(RandomSpheres& spheres, SphereTree& tree, std::mt19937& random, btScalar box,
                  int iteration) {
  std::uniform_real_distribution<btScalar> jitter(-0.0005, 0.0005);
  for (size_t i = 0; i < spheres.centres.size(); ++i) {
    btVector3& c = spheres.centres[i];
    c += spheres.velocities[i] + btVector3(jitter(random), jitter(random), jitter(random));
    for (int axis = 0; axis < 3; ++axis)
      if (std::abs(c[axis]) > box) spheres.velocities[i][axis] *= -1;
  }
  if (iteration % 10 == 0)
    tree.rebuild(spheres.centres, spheres.radii);
  else
    tree.refit(spheres.centres, spheres.radii);
}

TEST(BroadPhase, MuscleTreesFindExactlyTheBruteForcePairsWhileMoving) {
  std::mt19937 random(12345);
  const btScalar box = 0.03;
  RandomSpheres a = randomSpheres(random, 300, box), b = randomSpheres(random, 250, box);
  SphereTree treeA, treeB;
  treeA.build(a.indices, a.centres, a.radii);
  treeB.build(b.indices, b.centres, b.radii, 0, false);  // its rebuilds start a new btDbvt
  TreeTraversalStack stack;
  size_t totalPairs = 0, totalCandidates = 0;
  for (int iteration = 0; iteration < 80; ++iteration) {
    if (iteration > 0) {
      moveAndRefit(a, treeA, random, box, iteration);
      moveAndRefit(b, treeB, random, box, iteration);
    }
    PairRecorder recorder(a, b);
    collideTrees(stack, treeA, treeB, recorder);
    ASSERT_EQ(recorder.pairs, bruteForce(a.centres, a.radii, b.centres, b.radii))
        << "iteration " << iteration;
    totalPairs += recorder.pairs.size();
    totalCandidates += recorder.candidates;
  }
  EXPECT_GT(totalPairs, 100u);  // the sets really overlap
  // The broad phase prunes: far fewer candidates than all 300 × 250 pairs per iteration.
  EXPECT_LT(totalCandidates, 80u * 300 * 250 / 10);
}

TEST(BroadPhase, BoneTreeFindsExactlyTheBruteForcePairsWhileBothMove) {
  std::mt19937 random(777);
  const btScalar box = 0.03;
  RandomSpheres muscle = randomSpheres(random, 300, box);
  const RandomSpheres bone = randomSpheres(random, 400, box);  // static, bone frame
  SphereTree muscleTree;
  BoneSphereTree boneTree;
  muscleTree.build(muscle.indices, muscle.centres, muscle.radii);
  boneTree.build(bone.centres, bone.radii);
  TreeTraversalStack stack;
  std::uniform_real_distribution<btScalar> unit(-1, 1);
  size_t totalPairs = 0, totalCandidates = 0;
  for (int iteration = 0; iteration < 80; ++iteration) {
    if (iteration > 0) moveAndRefit(muscle, muscleTree, random, box, iteration);
    const btTransform boneToWorld(
        btQuaternion(btVector3(unit(random), unit(random), unit(random) + 2).normalized(),
                     btScalar(0.03) * iteration),
        btVector3(unit(random), unit(random), unit(random)) * 0.005);
    boneTree.place(boneToWorld, bone.centres, bone.radii);
    PairSet pairs;
    collideTrees(stack, muscleTree, boneTree, [&](int32_t i, int32_t s) {
      ++totalCandidates;
      EXPECT_LT((boneTree.centre(s) - boneToWorld * bone.centres[s]).length(), 1e-6);
      const btScalar reach = muscle.radii[i] + bone.radii[s];
      if ((muscle.centres[i] - boneTree.centre(s)).length2() < reach * reach) pairs.insert({i, s});
    });
    ASSERT_EQ(pairs,
              bruteForce(muscle.centres, muscle.radii, bone.centres, bone.radii, boneToWorld))
        << "iteration " << iteration;
    totalPairs += pairs.size();
  }
  EXPECT_GT(totalPairs, 100u);
  EXPECT_LT(totalCandidates, 80u * 300 * 400 / 10);
}

// ---- Tunnelling ----------------------------------------------------------------------------

/// A particle pulled by a stiff spring from +30 mm towards an anchor at −30 mm, through a bone
/// sphere of radius 10 mm at the origin; returns the particle's x after every iteration.
std::vector<double> pulledThroughBone(MuscleSystemDef parameters, int iterations) {
  // The spring starts 600× its rest length on purpose: the guard reports it, never freezes it.
  parameters.onFailure = FailurePolicy::Report;
  auto muscle = std::make_shared<MuscleSettings>();
  muscle->name = "pulled";
  muscle->restPositions = {{-0.03, 0, 0}, {0.03, 0, 0}};
  muscle->radii = {0, 0.002};
  muscle->flags = {kFixed, kBoundary};
  muscle->fixedBone = {0, -1};
  muscle->nearestBone = {-1, -1};
  muscle->boundaryParticles = {1};
  muscle->fixedParticles = {0};
  muscle->particleMass = 1e-4;
  muscle->springs = {{0, 1, 0.0001, 1000}};
  MuscleSystem system(parameters);
  const BoneHandle bone = system.addBone(makeBone({{0, 0, 0}}, {0.01}));
  const MuscleHandle h = system.addMuscle(muscle, std::span(&bone, 1));
  std::vector<double> x;
  for (int i = 0; i < iterations; ++i) {
    system.step();
    x.push_back(system.positions(h)[1].x());
  }
  return x;
}

TEST(Tunnelling, AFastParticleNeverEndsInsideTheBoneWithTheAdaptiveStep) {
  MuscleSystemDef parameters = oneIteration();
  parameters.stepSettings.minTimeStep = 1e-9;
  const std::vector<double> x = pulledThroughBone(parameters, 3000);
  for (size_t i = 0; i < x.size(); ++i) ASSERT_GE(x[i], 0.012 - 1e-6) << "iteration " << i;
  EXPECT_NEAR(x.back(), 0.012, 1e-6);  // it arrived and rests on the bone
}

TEST(Tunnelling, TheSameParticleTunnelsWithAFixedLargeStep) {
  // The check above can fail: with a fixed dt the particle jumps through the bone.
  MuscleSystemDef parameters = oneIteration();
  parameters.stepSettings.adaptiveTimeStep = false;
  parameters.stepSettings.timeStep = 3e-4;
  const std::vector<double> x = pulledThroughBone(parameters, 200);
  EXPECT_LT(*std::min_element(x.begin(), x.end()), -0.012);
}

TEST(SurfaceContact, VerticesInsideABoneMoveOntoItsSurfaceWithinReach) {
  // A cube bone of side 2 cm at the origin, turned 30° about z and moved; vertices given in the
  // bone frame and placed with it.
  const TriangleMesh cube =
      testing::boxMesh(btVector3(-0.01f, -0.01f, -0.01f), btVector3(0.01f, 0.01f, 0.01f));
  const ContactMesh bone(cube);
  const btTransform placed(btQuaternion(btVector3(0, 0, 1), btScalar(SIMD_PI / 6)),
                           btVector3(0.1f, -0.05f, 0.02f));
  const btVector3 local[] = {
      {0.009f, 0.002f, 0.001f},  // 1 mm inside the +x face: onto it
      {0.002f, -0.0085f, 0},     // 1.5 mm inside the −y face: onto it
      {0.012f, 0, 0},            // outside: stays
      {0, 0, 0},                 // 10 mm deep, beyond the reach: stays
  };
  std::vector<btVector3> surface;
  for (const btVector3& p : local) surface.push_back(placed * p);
  const std::vector<btVector3> before = surface;
  const std::vector<btScalar> reach(surface.size(), btScalar(0.003));
  const btVector3 far(1, 1, 1), near = placed.getOrigin();
  EXPECT_EQ(liftOutOfBone(bone, placed, reach, far, far * 2, surface), 0u);  // bounds miss
  EXPECT_EQ(surface, before);
  EXPECT_EQ(liftOutOfBone(bone, placed, reach, near - far, near + far, surface), 2u);
  const btTransform toBone = placed.inverse();
  EXPECT_NEAR((toBone * surface[0]).x(), 0.01, 1e-6);
  EXPECT_NEAR((toBone * surface[0]).y(), 0.002, 1e-6);
  EXPECT_NEAR((toBone * surface[1]).y(), -0.01, 1e-6);
  EXPECT_NEAR((toBone * surface[1]).x(), 0.002, 1e-6);
  for (int v : {0, 1}) EXPECT_GT(bone.distance.signedDistance(toBone * surface[v]), -1e-6) << v;
  EXPECT_EQ(surface[2], before[2]);
  EXPECT_EQ(surface[3], before[3]);
}

TEST(SurfaceContact, TheSystemsSurfaceStaysOutOfTheBoneOnlyWhenSwitchedOn) {
  // The grid muscle (surface y up to 5 mm, its particles up to 4 mm) with a slab bone above it
  // from y = 4.5 mm: with muscle–bone collision off, nothing keeps the surface's +y corners out
  // of it (0.5 mm deep); surface contact lifts them onto the bone.
  auto bone = std::make_shared<BoneSettings>();
  bone->name = "above";
  bone->mesh = testing::boxMesh({-0.03f, 0.0045f, -0.03f}, {0.03f, 0.03f, 0.03f});
  bone->sphereCentres = {btVector3(0, 0.017f, 0)};
  bone->sphereRadii = {btScalar(0.012)};
  for (const bool on : {false, true}) {
    MuscleSystemDef parameters = testing::verletDef();
    parameters.surfaceContact = on;
    parameters.muscleBone = false;
    MuscleSystem system(parameters);
    const BoneHandle ends[] = {system.addBone(testing::cubeBone("left", {-0.02f, 0, 0})),
                               system.addBone(testing::cubeBone("right", {0.02f, 0, 0}))};
    system.addBone(bone);
    const MuscleHandle muscle = system.addMuscle(testing::gridMuscle(), ends);
    system.step();
    const MeshDistance mesh(bone->mesh);
    btScalar deepest = 0;
    for (const btVector3& v : system.surface(muscle))
      deepest = std::min(deepest, mesh.signedDistance(v));
    if (on)
      EXPECT_GT(deepest, -1e-6);
    else
      EXPECT_LT(deepest, btScalar(-0.0004));
  }
}

// ---- Distance field ------------------------------------------------------------------------

TEST(DistanceField, MatchesTheMeshDistanceOfASphere) {
  const btScalar radius = 0.02, cell = 0.002;
  const MeshDistance mesh(makeEllipsoid({0, 0, 0}, {radius, radius, radius}, 3));
  const btScalar margin = 20 * cell;
  const BoneDistanceField field(mesh, cell, margin);
  EXPECT_LT(field.exactNodes(), field.nodeCount());  // far blocks were interpolated
  std::mt19937 random(7);
  std::uniform_real_distribution<btScalar> unit(-1, 1);
  int nearSurface = 0;
  for (int k = 0; k < 4000; ++k) {
    // Every other point near the surface, the rest anywhere in the grid and a little beyond.
    const btVector3 cube(unit(random), unit(random), unit(random));
    const btVector3 p =
        k % 2 ? cube * (radius + margin) : cube.normalized() * (radius + unit(random) * 2 * cell);
    const MeshDistance::Closest exact = mesh.closest(p);
    const btScalar expected = exact.inside ? -exact.distance : exact.distance;
    const BoneDistanceField::Sample s = field.sample(p);
    // Trilinear over exact nodes: close to the surface the distance is nearly linear per cell.
    if (std::abs(expected) < 2 * cell) {
      ++nearSurface;
      ASSERT_NEAR(s.distance, expected, 0.1 * cell)
          << "at " << p.x() << " " << p.y() << " " << p.z();
      ASSERT_GT(s.gradient.dot((p - exact.point).normalized() * (exact.inside ? -1 : 1)), 0.95);
    } else {
      ASSERT_NEAR(s.distance, expected, cell);
    }
  }
  EXPECT_GE(nearSurface, 2000);
}

TEST(DistanceField, GivesTheKnownDistancesNextToTheFacesOfABox) {
  // A box 40 × 20 × 30 mm: over the middle of a face the distance is the height above it.
  const btVector3 half(0.02, 0.01, 0.015);
  const btScalar cell = 0.0015;
  const MeshDistance mesh(makeBox({0, 0, 0}, half * 2, {8, 4, 6}));
  const BoneDistanceField field(mesh, cell, 6 * cell);
  for (btScalar h = -0.004f; h <= 0.008f; h += 0.0007f) {
    EXPECT_NEAR(field.sample({0.001f, half.y() + h, -0.002f}).distance, h, 1e-5) << h;
    EXPECT_NEAR(field.sample({half.x() + h, 0.002f, 0.001f}).distance, h, 1e-5) << h;
    EXPECT_NEAR(field.sample({-0.003f, 0.001f, -half.z() - h}).distance, h, 1e-5) << h;
    EXPECT_GT(field.sample({0.001f, half.y() + h, -0.002f}).gradient.y(), 0.99) << h;
  }
  // Beyond the grid the value grows with the distance to it.
  const btScalar far = half.y() + 6 * cell + 0.05f;
  EXPECT_NEAR(field.sample({0, far, 0}).distance, far - half.y(), 2e-4);
  EXPECT_THROW(BoneDistanceField(mesh, 0, 0), InputError);
}

// ---- Exact contacts with shapes ------------------------------------------------------------

TEST(ShapeContact, SpheresBoxesCapsulesAndConvexHullsGiveTheirSignedDistances) {
  const btTransform pose(btQuaternion(btVector3(1, 2, 3).normalized(), 0.7f),
                         btVector3(0.1f, -0.2f, 0.05f));
  btBoxShape box(btVector3(0.02f, 0.01f, 0.015f));
  btConvexHullShape hull;
  for (int corner = 0; corner < 8; ++corner)
    hull.addPoint(btVector3(corner & 1 ? 0.02f : -0.02f, corner & 2 ? 0.01f : -0.01f,
                            corner & 4 ? 0.015f : -0.015f));
  hull.setMargin(0);
  btSphereShape sphere(0.01f);
  btCapsuleShape capsule(0.005f, 0.02f);  // radius, height of the cylinder part (y)
  std::mt19937 random(3);
  std::uniform_real_distribution<btScalar> unit(-0.03f, 0.03f);
  const btScalar r = 0.004f;
  int boxHits = 0;
  for (int k = 0; k < 2000; ++k) {
    const btVector3 local(unit(random), unit(random), unit(random));
    const btVector3 p = pose * local;
    ShapeContact a, b;
    const bool hitBox = sphereShapeContact(box, pose, p, r, a);
    // Outside the box: the distance to the clamped point.
    btVector3 clamped = local;
    clamped.setMax(-box.getHalfExtentsWithMargin());
    clamped.setMin(box.getHalfExtentsWithMargin());
    const btScalar outside = (local - clamped).length();
    if (outside > 1e-4f) {
      ASSERT_EQ(hitBox, outside < r) << k;
      if (hitBox) {
        ++boxHits;
        EXPECT_NEAR(a.depth, r - outside, 1e-5f);
        EXPECT_NEAR(a.point.distance(pose * clamped), 0, 1e-5f);
      }
    }
    // The hull of the same box agrees (GJK/EPA), inside too.
    ASSERT_EQ(sphereShapeContact(hull, pose, p, r, b), hitBox) << k;
    if (hitBox) {
      EXPECT_NEAR(b.depth, a.depth, 2e-4f) << k;
      EXPECT_GT(b.normal.dot(a.normal), 0.98f)
          << k << " outside " << outside << " depth " << a.depth << " " << b.depth;
    }
    // The sphere and the capsule: distance to a centre point and to the axis segment.
    const btScalar toCentre = local.length() - 0.01f;
    ASSERT_EQ(sphereShapeContact(sphere, pose, p, r, a), toCentre < r);
    if (toCentre < r) {
      EXPECT_NEAR(a.depth, r - toCentre, 1e-5f);
    }
    const btVector3 axis(0, std::clamp(local.y(), btScalar(-0.01), btScalar(0.01)), 0);
    const btScalar toAxis = (local - axis).length() - 0.005f;
    ASSERT_EQ(sphereShapeContact(capsule, pose, p, r, a), toAxis < r);
    if (toAxis < r) {
      EXPECT_NEAR(a.depth, r - toAxis, 1e-5f);
      EXPECT_NEAR(a.normal.dot(pose.getBasis() * (local - axis).normalized()), 1, 1e-4f);
    }
  }
  EXPECT_GT(boxHits, 50);
}

}  // namespace
}  // namespace fibremss
