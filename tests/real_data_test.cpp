// Real anatomy from ../shared/data/muscle-deformation-pbd (skipped when absent): fibres from a
// real muscle surface, the real-hip and real-block scenes prepare and run.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <nlohmann/json.hpp>

#include "fibremss/FibreGeneration.h"
#include "fibremss/MeshIO.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "support/PrepFixtures.h"
#include "support/Process.h"

namespace fibremss {
namespace {

namespace fs = std::filesystem;
const std::string kData = std::string(FIBREMSS_SHARED_DATA_DIR) + "/muscle-deformation-pbd";
const std::string kSource = FIBREMSS_SOURCE_DIR;

#define REQUIRE_SHARED_DATA()                                                                     \
  if (!fs::exists(kData + "/muscle0_s1.vtk") || !fs::exists(kData + "/bone1_s1.vtk"))             \
  GTEST_SKIP() << "real meshes not found in " << kData                                            \
               << " (FIBREMSS_SHARED_DATA_DIR/muscle-deformation-pbd); the real-data tests need " \
                  "../shared/data next to the repository"

TEST(RealData, FibresOfARealMuscleMeetTheQualityBounds) {
  REQUIRE_SHARED_DATA();
  const TriangleMesh muscle = loadSurface(kData + "/muscle0_s1.vtk", 0.001);
  const TriangleMesh femur = loadSurface(kData + "/bone1_s1.vtk", 0.001);
  const btScalar areaDistance = 0.003;
  FibreGenerationOptions options;  // 64 fibres, 48 voxels along the longest side
  const FibreGenerationResult result = generateFibres(
      muscle, AttachmentArea{}, AttachmentArea::fromBone(femur, areaDistance), options);
  const FibreQuality& q = result.quality;
  ASSERT_EQ(result.fibres.fibreCount(), 64u);
  // All inside: every point within a quarter voxel of the surface's inside, checked here.
  const MeshDistance surface(muscle), bone(femur);
  size_t outside = 0;
  for (const auto& p : result.fibres.points) outside += surface.signedDistance(p) > q.voxelSize / 4;
  EXPECT_EQ(outside, 0u);
  // >= 90 % end at the femur (within the area distance plus a voxel) and start at the far end
  // (farther from the femur than that).
  int right = 0;
  for (size_t f = 0; f < result.fibres.fibreCount(); ++f) {
    const auto fibre = result.fibres.fibre(f);
    right += bone.closest(fibre.back()).distance < areaDistance + q.voxelSize &&
             bone.closest(fibre.front()).distance > areaDistance + q.voxelSize;
  }
  EXPECT_GE(right, int(0.9 * 64));
  EXPECT_GE(q.rightEnds, 0.9);
  // Coverage bound: 64 fibres in this ~160 mm long muscle leave it at least 40 % within 5 mm
  // (measured 50 %: it is wide and flat, 64 fibres 5 mm thick cannot fill it).
  EXPECT_GE(q.coverage, 0.4);
  EXPECT_EQ(q.pointsOutside, 0);
  // Length spread: no fibre is shorter than the straight line between the two areas (less a
  // voxel at each end for where a streamline starts and stops).
  btScalar gap = std::numeric_limits<btScalar>::infinity();
  for (uint32_t o : result.originArea)
    for (uint32_t i : result.insertionArea)
      gap = std::min(gap, muscle.vertices[o].distance(muscle.vertices[i]));
  EXPECT_GT(q.minLength, gap - 2 * q.voxelSize);
  EXPECT_LE(q.minLength, q.medianLength);
  EXPECT_LE(q.medianLength, q.maxLength);
  // Crossings: streamlines of a gradient field do not cross; pairs closer than the tolerance
  // are fibres converging into the tendon. Bound: at most 5 % of the 2016 pairs.
  EXPECT_LE(q.crossingPairs, 64 * 63 / 2 / 20);
}

LoadedScene loadRealScene(const std::string& name) {
  return loadScene(kSource + "/scenes/json/" + name + ".json", {"data_dir=" + kData});
}

TEST(RealData, HipScenePreparesWithAnchorsAndAFittedPivot) {
  REQUIRE_SHARED_DATA();
  const LoadedScene scene = loadRealScene("real-hip");
  ASSERT_EQ(scene.muscles.size(), 4u);
  // The femur plus one static anchor plate per muscle origin.
  ASSERT_EQ(scene.bones.size(), 5u);
  EXPECT_EQ(scene.bones[0].name, "femur");
  ASSERT_EQ(scene.poseCount, 19);  // 0 -> 90 deg in 5 deg steps
  for (const auto& muscle : scene.muscles) EXPECT_EQ(muscle.fibres.fibreCount(), 64u);
  // The sweep pivot is the femoral head's fitted centre: it stays put in every pose.
  btVector3 head;
  btScalar radius;
  ASSERT_TRUE(
      fitFemoralHead(scene.bones[0].mesh, btVector3(0, 0, 1), btScalar(0.03), head, radius));
  EXPECT_GT(radius, 0.015);  // a human femoral head: 20-28 mm
  EXPECT_LT(radius, 0.035);
  for (int pose = 0; pose < scene.poseCount; ++pose)
    EXPECT_LT((scene.bonePose(0, pose) * head).distance(head), 1e-5) << "pose " << pose;
  EXPECT_GT((scene.bonePose(0, 4) * btVector3(0.12f, 0.27f, -0.8f))
                .distance(btVector3(0.12f, 0.27f, -0.8f)),
            0.1);  // the knee end moves

  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, 1);
  ASSERT_EQ(prepared.muscles.size(), 4u);
  for (size_t m = 0; m < 4; ++m) {
    const MuscleSettings& muscle = *prepared.muscles[m];
    size_t onFemur = 0, onAnchor = 0;
    for (uint32_t i : muscle.fixedParticles) {
      onFemur += muscle.fixedBone[i] == 0;
      onAnchor += muscle.fixedBone[i] == int32_t(1 + m);
    }
    // Both ends attached: most fibres' first particles to the anchor, some to the femur.
    EXPECT_GE(onAnchor, muscle.fibreCount() / 2) << muscle.name;
    EXPECT_GT(onFemur, 0u) << muscle.name;
    for (const auto& p : muscle.restPositions) ASSERT_TRUE(std::isfinite(p.length2()));
  }
  // Converging fibres: particles of other fibres closer than a quarter spacing were merged, so
  // the shortest spring is no shorter than that unless it lies along one fibre.
  ASSERT_EQ(prepared.report.muscles.size(), 4u);
  for (size_t m = 0; m < 4; ++m) {
    const MusclePreparationReport& report = prepared.report.muscles[m];
    const MuscleSettings& muscle = *prepared.muscles[m];
    EXPECT_EQ(report.sampledParticles, 64u * 30u);
    EXPECT_EQ(muscle.particleCount(), report.sampledParticles - report.mergedParticles);
    EXPECT_GT(report.mergeDistance, 0);
    for (const Spring& spring : muscle.springs) {
      if (spring.restLength < report.mergeDistance) {
        EXPECT_TRUE(testing::shareAFibre(muscle, spring.a, spring.b)) << muscle.name;
      }
    }
  }
  // Every surface vertex starts outside the femur (those inside were moved out).
  const MeshDistance femur(scene.bones[0].mesh);
  for (const auto& muscle : prepared.muscles)
    for (const btVector3& v : muscle->restSurface.vertices) ASSERT_FALSE(femur.inside(v));
  for (const auto& warning : prepared.report.warnings)
    std::cout << "[prepared] " << warning << "\n";
  for (const auto& repair : prepared.report.repairs) std::cout << "[repaired] " << repair << "\n";
}

TEST(RealData, BlockScenePrepares) {
  REQUIRE_SHARED_DATA();
  const LoadedScene scene = loadRealScene("real-block");
  ASSERT_EQ(scene.bones.size(), 2u);
  ASSERT_EQ(scene.muscles.size(), 1u);
  EXPECT_EQ(scene.muscles[0].fibres.fibreCount(), 64u);
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, 1);
  const MuscleSettings& block = *prepared.muscles[0];
  size_t upper = 0, lower = 0;
  for (uint32_t i : block.fixedParticles) (block.fixedBone[i] == 0 ? upper : lower) += 1;
  EXPECT_GE(upper, block.fibreCount() / 2);
  EXPECT_GE(lower, block.fibreCount() / 2);
}

TEST(RealData, CompleteScenesLoadAgainToTheSameScene) {
  REQUIRE_SHARED_DATA();
  for (const std::string name : {"real-hip", "real-block"}) {
    SCOPED_TRACE(name);
    const LoadedScene scene = loadRealScene(name);  // data_dir absolute: the copy still finds it
    testing::TemporaryDirectory directory("fibremss_real_roundtrip");
    const std::string copy = (directory.path() / (name + ".json")).string();
    std::ofstream(copy) << scene.json;
    const LoadedScene again = loadScene(copy);
    EXPECT_EQ(nlohmann::json::parse(again.json), nlohmann::json::parse(scene.json));
    ASSERT_EQ(again.bones.size(), scene.bones.size());
    ASSERT_EQ(again.muscles.size(), scene.muscles.size());
    for (size_t m = 0; m < scene.muscles.size(); ++m)
      EXPECT_EQ(again.muscles[m].fibres.points.size(), scene.muscles[m].fibres.points.size());
    for (int p = 0; p < scene.poseCount; ++p)
      EXPECT_LT((again.bonePose(0, p).getOrigin() - scene.bonePose(0, p).getOrigin()).length(),
                1e-6);
  }
}

/// `fibremss run` for two poses with few iterations: exit 0, no NaN, penetration bounded.
void shortRun(const std::string& name, double penetrationBoundMm) {
  testing::TemporaryDirectory directory("fibremss_real_" + name);
  const std::string command = std::string(FIBREMSS_CLI) + " run " + kSource + "/scenes/json/" +
                              name + ".json --set data_dir=" + kData +
                              " --set iterations=20 --steps 2 --frame-every 0 --out " +
                              directory.path().string() + " 2>&1";
  const auto result = testing::runProcess(command);
  ASSERT_EQ(result.exitCode, 0) << result.output;
  std::ifstream in(directory.path() / "summary.json");
  ASSERT_TRUE(in) << result.output;
  const auto summary = nlohmann::json::parse(in);
  EXPECT_FALSE(summary.at("nan").get<bool>());
  EXPECT_FALSE(summary.at("exploded").get<bool>());
  EXPECT_EQ(summary.at("steps").get<int>(), 2);
  const double penetration = summary.at("max_penetration_mm").get<double>();
  EXPECT_TRUE(std::isfinite(penetration));
  EXPECT_LT(penetration, penetrationBoundMm);
}

// Bounds: the muscles' own collision radius scale (a few mm); measured 1.4 mm (hip, 5 poses,
// 70 iterations) and 3.5 mm (block, its boxes get one bone sphere each).
TEST(RealData, HipShortRunHasNoNaN) {
  REQUIRE_SHARED_DATA();
  shortRun("real-hip", 5.0);
}

TEST(RealData, BlockShortRunHasNoNaN) {
  REQUIRE_SHARED_DATA();
  shortRun("real-block", 10.0);
}

TEST(RealData, FibresCommandOnARealMuscle) {
  REQUIRE_SHARED_DATA();
  testing::TemporaryDirectory directory("fibremss_real_fibres");
  const std::string out = (directory.path() / "fibres.vtk").string();
  const auto result = testing::runProcess(std::string(FIBREMSS_CLI) + " fibres " + kData +
                                          "/muscle3_s1.vtk --insertion " + kData +
                                          "/bone1_s1.vtk --count 32 --out " + out);
  ASSERT_EQ(result.exitCode, 0) << result.output;
  const FibreSet fibres = loadFibres(out, 0.001);
  EXPECT_EQ(fibres.fibreCount(), 32u);
  const TriangleMesh muscle = loadSurface(kData + "/muscle3_s1.vtk", 0.001);
  EXPECT_TRUE(checkFibres(fibres, muscle, out, 0.002).empty());
}

}  // namespace
}  // namespace fibremss
