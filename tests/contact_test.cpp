// Penetration-free contact (issue 5): the bone distance field against exact distances, penetration
// recovery (seed 001 eq 1) catching a particle a thin bone sweeps through, and the goal:
// hip extension in 10° steps with the default method keeps the muscle surfaces out of the bones.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include "../plugin/src/BoneDistanceField.h"
#include "fibremss/FibreRun.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Procedural.h"
#include "fibremss/Scene.h"
#include "support/SolverFixtures.h"

namespace fibremss {
namespace {

using testing::makeSpheres;

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
  EXPECT_THROW(BoneDistanceField(mesh, 0, 0), std::invalid_argument);
}

// ---- Penetration recovery ------------------------------------------------------------------

/// A 2 mm thin plate (normal y) that moves up 3.5 mm per step, in one iteration, towards a free
/// particle of radius 1 mm: after the first step the particle is 2 mm above the plate's top, near
/// but clear; the second step carries the plate past the particle's centre (0.5 mm beyond its
/// middle). Returns the particle's height above the plate's middle after every step.
std::vector<btScalar> plateSweep(bool recovery) {
  SimulationParameters parameters;
  parameters.iterations = 1;
  parameters.adaptiveTimeStep = false;
  parameters.boneCollision = BoneCollision::DistanceField;
  parameters.distanceFieldCell = 0.0005;
  parameters.penetrationRecovery = recovery;
  MuscleSystem system(parameters);
  auto plate = testing::makeBone();
  plate->mesh = makeBox({0, 0, 0}, {0.03, 0.002, 0.03}, {6, 1, 6});
  const BoneHandle bone = system.addBone(plate);
  const MuscleHandle particle =
      system.addMuscle(makeSpheres({{0.001, 0.0065, -0.002}}, {0.001}), {});
  std::vector<btScalar> heights;
  for (int step = 1; step <= 6; ++step) {
    const btScalar plateY = btScalar(0.0035 * step);
    system.setBoneTransform(bone, btTransform(btQuaternion::getIdentity(), {0, plateY, 0}));
    system.step();
    heights.push_back(system.positions(particle)[0].y() - plateY);
  }
  return heights;
}

TEST(Recovery, AParticleAThinBoneSweepsThroughIsPushedBackOutOnItsSide) {
  for (const btScalar height : plateSweep(true)) EXPECT_GE(height, 0.002f - 1e-5f);
}

TEST(Recovery, WithoutItTheFieldPushesTheParticleOutOnTheFarSide) {
  // The check above can fail: past the plate's middle the field's direction points down.
  const std::vector<btScalar> heights = plateSweep(false);
  EXPECT_LT(heights.back(), -0.002f + 1e-5f);
}

// ---- The goal --------------------------------------------------------------------------------

TEST(HipExtension, TenDegreeStepsKeepTheMuscleSurfacesWithinAMillimetreOfTheBones) {
  // The default method at a small resolution, the whole 0–80° sweep: the surfaces' deepest
  // vertex in the true bone meshes over all poses (the metric of `fibremss run`).
  const LoadedScene scene = loadScene("hip-extension", {"resolution=15", "step_deg=10"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  FibreRunOptions options;
  options.frameEvery = 0;
  options.keepPoseSurfaces = false;
  const RunMetrics metrics = runFibreMSS(scene, prepared, options);
  EXPECT_EQ(metrics.steps, scene.poseCount);
  EXPECT_FALSE(metrics.nan);
  EXPECT_FALSE(metrics.exploded);
  EXPECT_LE(metrics.maxPenetrationMm, 1.0);
}

TEST(Pinch, TheMuscleBetweenTwoClosingBonesStaysFiniteAndIsPressed) {
  // Two blades shear past each other through the muscle with a 2 mm gap: there is no room, the
  // muscle is squeezed (springs beyond 3× while it happens, reported as exploded). With the guard
  // set to report rather than freeze, collisions keep running and nothing becomes NaN. Open
  // (issue 5): boundary particles can still end up to a few mm inside a blade, depending on
  // round-off (measured 2.2 mm at pose 3 in a Release build, 0 with RelWithDebInfo).
  const LoadedScene scene = loadScene("pinch", {"resolution=10", "on_failure=report"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  MuscleSystem system(scene.simulation);
  std::vector<BoneHandle> bones;
  for (const auto& bone : prepared.bones) bones.push_back(system.addBone(bone));
  ASSERT_EQ(prepared.muscles.size(), 1u);
  const MuscleHandle muscle = system.addMuscle(prepared.muscles[0], bones);
  size_t contacts = 0;
  for (int pose = 0; pose < scene.poseCount; ++pose) {
    for (size_t b = 0; b < bones.size(); ++b)
      system.setBoneTransform(bones[b], scene.bonePose(b, pose));
    system.step();
    contacts += system.lastStep().contacts;
    ASSERT_FALSE(system.lastStep().nan) << "pose " << pose;
    for (const btVector3& x : system.positions(muscle))
      ASSERT_TRUE(std::isfinite(x.length2())) << "pose " << pose;
  }
  EXPECT_GT(contacts, 0u);  // the blades did press on the muscle
}

}  // namespace
}  // namespace fibremss
