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

// The quality bounds on the four real muscles, with the real-hip scene's areas:
// insertion within 3 mm of the femur, origin the far end 3 mm deep.
// - inside: no point outside the surface (checked here, a quarter voxel's tolerance);
// - right ends: >= 90 % start at the origin and end at the femur (checked here, within the
//   generator's end tolerance of 2.5 voxels);
// - coverage: >= 60 % of the interior within 5 mm of a fibre. Seeds spread over the widest
//   cross-section (the default) give 75-99 % here; seeds on the origin area (the 3 mm tip)
//   bunch the fibres and gave 43 % for muscle 0, which this bound rejects;
// - crossings: streamlines of a gradient field do not cross; pairs closer than 0.5 mm are
//   fibres converging into a tendon: at most 6 % of the 2016 pairs (origin seeding: 215 and
//   107 pairs for muscles 2 and 3; a bone area keeps only its patch at the muscle's end, so all
//   of muscle 2's fibres run on into its insertion and converge there: 102 pairs, coverage
//   99 %, where an area that kept the whole bone stops them at a contact mid-muscle: 64, 83 %);
// - length spread: no fibre shorter than the straight line between the two areas.
TEST(RealData, FibresOfTheRealMusclesMeetTheQualityBounds) {
  REQUIRE_SHARED_DATA();
  const TriangleMesh femur = loadSurface(kData + "/bone1_s1.vtk", 0.001);
  const MeshDistance bone(femur);
  const btScalar areaDistance = 0.003;
  for (int m = 0; m < 4; ++m) {
    const std::string name = "muscle" + std::to_string(m) + "_s1.vtk";
    SCOPED_TRACE(name);
    const TriangleMesh muscle = loadSurface(kData + "/" + name, 0.001);
    AttachmentArea origin;  // the far end
    origin.endDepth = btScalar(0.003);
    FibreGenerationOptions options;  // 64 fibres, 48 voxels along the longest side
    const FibreGenerationResult result =
        generateFibres(muscle, origin, AttachmentArea::fromBone(femur, areaDistance), options);
    const FibreQuality& q = result.quality;
    ASSERT_EQ(result.fibres.fibreCount(), 64u);
    const MeshDistance surface(muscle);
    size_t outside = 0;
    for (const auto& p : result.fibres.points)
      outside += surface.signedDistance(p) > q.voxelSize / 4;
    EXPECT_EQ(outside, 0u);
    EXPECT_EQ(q.pointsOutside, 0);
    std::vector<char> inOrigin(muscle.vertices.size(), 0);
    for (uint32_t o : result.originArea) inOrigin[o] = 1;
    int right = 0;
    for (size_t f = 0; f < result.fibres.fibreCount(); ++f) {
      const auto fibre = result.fibres.fibre(f);
      btScalar toOrigin = std::numeric_limits<btScalar>::infinity();
      for (uint32_t o : result.originArea)
        toOrigin = std::min(toOrigin, muscle.vertices[o].distance(fibre.front()));
      // Within the generator's end tolerance (2.5 voxels) of each area.
      right += bone.closest(fibre.back()).distance < areaDistance + 2.5f * q.voxelSize &&
               toOrigin < 2.5f * q.voxelSize;
    }
    EXPECT_GE(right, int(0.9 * 64));
    EXPECT_GE(q.rightEnds, 0.9);
    EXPECT_GE(q.coverage, 0.6);
    EXPECT_LE(q.crossingPairs, 64 * 63 * 6 / 2 / 100);
    btScalar gap = std::numeric_limits<btScalar>::infinity();
    for (uint32_t o : result.originArea)
      for (uint32_t i : result.insertionArea)
        gap = std::min(gap, muscle.vertices[o].distance(muscle.vertices[i]));
    EXPECT_GT(q.minLength, gap - 2 * q.voxelSize);
    EXPECT_LE(q.minLength, q.medianLength);
    EXPECT_LE(q.medianLength, q.maxLength);
    std::cout << "[quality] " << name << ": coverage " << q.coverage * 100 << " %, crossings "
              << q.crossingPairs << ", right ends " << q.rightEnds * 100 << " % (" << right
              << " checked here)\n";
  }
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

// Bound: the contact target's 1 mm for the muscle surfaces' penetration into the true
// bone meshes. Measured over the whole runs with the scenes' 70 iterations: 0.072 mm (hip,
// 19 poses), 0.105 mm (block, 5 poses).
TEST(RealData, HipShortRunHasNoNaN) {
  REQUIRE_SHARED_DATA();
  shortRun("real-hip", 1.0);
}

TEST(RealData, BlockShortRunHasNoNaN) {
  REQUIRE_SHARED_DATA();
  shortRun("real-block", 1.0);
}

// `fibremss check` and `fibremss compare` on the block scene (run: BlockShortRunHasNoNaN).
TEST(RealData, BlockSceneChecksAndCompares) {
  REQUIRE_SHARED_DATA();
  const std::string scene = kSource + "/scenes/json/real-block.json --set data_dir=" + kData;
  const auto check = testing::runProcess(std::string(FIBREMSS_CLI) + " check " + scene + " 2>&1");
  ASSERT_EQ(check.exitCode, 0) << check.output;
  EXPECT_NE(check.output.find("1 muscles"), std::string::npos) << check.output;
  EXPECT_NE(check.output.find("preparation report"), std::string::npos) << check.output;
  testing::TemporaryDirectory directory("fibremss_real_compare");
  const auto compare =
      testing::runProcess(std::string(FIBREMSS_CLI) + " compare " + scene +
                          " --set iterations=20 --methods fibremss,btsoftbody --softbody-substeps "
                          "4 --no-fronts --no-reference --out " +
                          directory.path().string() + " 2>&1");
  ASSERT_EQ(compare.exitCode, 0) << compare.output;
  std::ifstream in(directory.path() / "summary.json");
  ASSERT_TRUE(in) << compare.output;
  const auto runs = nlohmann::json::parse(in).at("runs");
  ASSERT_EQ(runs.size(), 2u);
  for (const auto& run : runs) {
    SCOPED_TRACE(run.at("method").get<std::string>());
    // btSoftBody's links reach 2.5–3.8× on this motion whatever their solve order: it may stop
    // at the 3× criterion, but never with NaN.
    if (!run.at("exploded").get<bool>()) {
      EXPECT_EQ(run.at("steps").get<int>(), 5);
    }
    EXPECT_FALSE(run.at("nan").get<bool>());
  }
  EXPECT_FALSE(runs[0].at("exploded").get<bool>());  // FibreMSS
  EXPECT_TRUE(fs::exists(directory.path() / "report.md"));
}

// The hip with gait2392's pelvis (../shared/data/opensim-motions, metres) in a mm scene: the
// pelvis is read in metres, its cracks are welded and holes closed so that it loads without a
// warning, gait2392's hip centre lies on the fitted femoral head, and the adduction keyframes
// turn about that head. Loading only (the runs: scenes/json/REAL-ANATOMY.md).
TEST(RealData, HipWithThePelvisLoadsClosedAndTurnsAboutTheHead) {
  REQUIRE_SHARED_DATA();
  const std::string data = FIBREMSS_SHARED_DATA_DIR;
  if (!fs::exists(data + "/opensim-motions/pelvis.vtp"))
    GTEST_SKIP() << "no " << data << "/opensim-motions/pelvis.vtp";
  const LoadedScene scene =
      loadScene(kSource + "/scenes/json/real-hip-adduction.json", {"data_dir=" + data});
  for (const std::string& warning : scene.warnings)
    EXPECT_EQ(warning.find(".vtp"), std::string::npos) << warning;
  // femur, pelvis, sacrum, muscle 3's origin plate
  ASSERT_EQ(scene.bones.size(), 4u);
  ASSERT_EQ(scene.bones[1].name, "pelvis");
  EXPECT_TRUE(checkSurface(scene.bones[1].mesh, "pelvis").closed());
  EXPECT_TRUE(checkSurface(scene.bones[2].mesh, "sacrum").closed());
  EXPECT_GT(meshVolume(scene.bones[1].mesh), 1e-4);  // a hemipelvis of ~0.3 L, read in metres
  btVector3 head;
  btScalar radius;
  ASSERT_TRUE(
      fitFemoralHead(scene.bones[0].mesh, btVector3(0, 0, 1), btScalar(0.03), head, radius));
  // gait2392's hip centre (-0.0707, -0.0661, 0.0835) m in the pelvis frame: in the scene, the
  // pelvis' rest transform maps OpenSim X, Y, Z to -y, +z, -x with the centre on the head.
  const btVector3 translation(0.226894f, 0.172603f, -0.366297f);
  const btVector3 hip = translation + btVector3(-0.0835f, 0.0707f, -0.0661f);
  EXPECT_LT(hip.distance(head), 1e-4);
  ASSERT_EQ(scene.poseCount, 32);  // 16 keyframes of 10 deg, each split into two sub-poses
  for (int pose = 0; pose < scene.poseCount; ++pose)
    EXPECT_LT((scene.bonePose(0, pose) * head).distance(head), 1e-5) << "pose " << pose;
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
