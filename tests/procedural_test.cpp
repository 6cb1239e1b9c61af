// Procedural geometry and the built-in scenes: closed outward meshes, fibres inside their
// muscles, muscle ends on bones, the thesis' particle counts for thigh13, sweep pose counts.
#include "fibremss/Procedural.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>

#include "fibremss/Geometry.h"
#include "fibremss/Scene.h"

using fibremss::LoadedScene;
using fibremss::loadScene;
using fibremss::TriangleMesh;

namespace {

/// Every directed edge appears once and its reverse once: closed, consistently oriented.
::testing::AssertionResult closedAndConsistent(const TriangleMesh& mesh) {
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (const auto& t : mesh.triangles) {
    for (int e = 0; e < 3; ++e) {
      const uint32_t a = t[e], b = t[(e + 1) % 3];
      if (a == b) return ::testing::AssertionFailure() << "degenerate triangle";
      if (a >= mesh.vertices.size() || b >= mesh.vertices.size())
        return ::testing::AssertionFailure() << "index out of range";
      ++directed[{a, b}];
    }
  }
  for (const auto& [edge, count] : directed) {
    if (count != 1)
      return ::testing::AssertionFailure() << "edge " << edge.first << "-" << edge.second
                                           << " used " << count << " times one way";
    if (!directed.count({edge.second, edge.first}))
      return ::testing::AssertionFailure() << "open edge " << edge.first << "-" << edge.second;
  }
  return ::testing::AssertionSuccess();
}

double totalParticles(const LoadedScene& scene) {
  double total = 0;
  for (const auto& muscle : scene.muscles)
    total += double(muscle.fibres.fibreCount()) * muscle.parameters.resolution;
  return total;
}

}  // namespace

TEST(Procedural, TubeIsClosedOutwardAndHasTheCylinderVolume) {
  fibremss::TubeDefinition definition;
  definition.points = {{0, 0, 0}, {0, 0, 50}, {0, 0, 100}};
  definition.radii = {{10, 10}, {10, 10}, {10, 10}};
  definition.slices = 128;
  definition.sections = 10;
  const fibremss::Tube tube(definition);
  EXPECT_NEAR(tube.length(), 100, 1e-3);
  const TriangleMesh mesh = tube.mesh();
  EXPECT_TRUE(closedAndConsistent(mesh));
  // A 128-gon prism: area (n/2) r² sin(2π/n) × length.
  const double expected = 64 * 100 * std::sin(2 * M_PI / 128) * 100;
  EXPECT_NEAR(fibremss::meshVolume(mesh), expected, 1e-3 * expected);

  // Round caps add two half-ellipsoid domes (polygonal, so a little less than 4/3 π r³).
  definition.roundCaps = true;
  const TriangleMesh capped = fibremss::Tube(definition).mesh();
  EXPECT_TRUE(closedAndConsistent(capped));
  const double dome = 4.0 / 3 * M_PI * 1000;
  EXPECT_GT(fibremss::meshVolume(capped), expected + 0.9 * dome);
  EXPECT_LT(fibremss::meshVolume(capped), expected + dome);

  // Elliptic sections: volume π a b L.
  definition.roundCaps = false;
  definition.radii = {{10, 5}, {10, 5}, {10, 5}};
  const TriangleMesh elliptic = fibremss::Tube(definition).mesh();
  EXPECT_NEAR(fibremss::meshVolume(elliptic), M_PI * 10 * 5 * 100, 0.01 * M_PI * 10 * 5 * 100);
}

TEST(Procedural, ShapesAreClosedWithKnownVolumes) {
  const TriangleMesh box = fibremss::makeBox({1, 2, 3}, {2, 4, 6}, {3, 2, 5});
  EXPECT_TRUE(closedAndConsistent(box));
  EXPECT_NEAR(fibremss::meshVolume(box), 48, 1e-4);
  EXPECT_EQ(box.triangles.size(), size_t(2 * 2 * (3 * 2 + 2 * 5 + 3 * 5)));
  const TriangleMesh ellipsoid = fibremss::makeEllipsoid({0, 0, 0}, {3, 2, 1}, 4);
  EXPECT_TRUE(closedAndConsistent(ellipsoid));
  const double expected = 4.0 / 3 * M_PI * 6;
  EXPECT_NEAR(fibremss::meshVolume(ellipsoid), expected, 0.01 * expected);
}

TEST(Procedural, DiskPatternsStayInsideTheDisk) {
  for (int count : {1, 7, 64, 100}) {
    for (auto pattern : {fibremss::DiskPattern::Sunflower, fibremss::DiskPattern::Grid}) {
      int columns = -1;
      const auto points = fibremss::diskPoints(count, pattern, &columns);
      ASSERT_EQ(points.size(), size_t(count));
      for (const auto& [u, v] : points) EXPECT_LE(u * u + v * v, 1 + 1e-12);
      if (pattern == fibremss::DiskPattern::Grid) {
        EXPECT_EQ(count % columns, 0);
        EXPECT_GE(columns * columns, count);
      } else {
        EXPECT_EQ(columns, 0);
      }
    }
  }
  int columns = 0;
  fibremss::diskPoints(64, fibremss::DiskPattern::Grid, &columns);
  EXPECT_EQ(columns, 8);
}

TEST(Procedural, EveryBuiltInSceneLoadsWithClosedMeshesAndFibresInside) {
  const auto builtIns = fibremss::builtInScenes();
  ASSERT_GE(builtIns.size(), 9u);
  for (const auto& builtIn : builtIns) {
    SCOPED_TRACE(builtIn.name);
    const LoadedScene scene = loadScene(builtIn.name);
    EXPECT_EQ(scene.name, builtIn.name);
    EXPECT_FALSE(scene.muscles.empty());
    for (const auto& bone : scene.bones) {
      EXPECT_TRUE(closedAndConsistent(bone.mesh)) << bone.name;
      EXPECT_GT(fibremss::meshVolume(bone.mesh), 0) << bone.name;
    }
    for (const auto& muscle : scene.muscles) {
      EXPECT_TRUE(closedAndConsistent(muscle.surface)) << muscle.name;
      const double volume = fibremss::meshVolume(muscle.surface);
      EXPECT_GT(volume, 0) << muscle.name;
      EXPECT_EQ(muscle.fibres.fibreCount(), 64u) << muscle.name;
      // Fibres inside the surface (ends may touch the caps).
      const fibremss::MeshDistance surface(muscle.surface);
      size_t outside = 0;
      for (const btVector3& p : muscle.fibres.points)
        if (surface.signedDistance(p) > 1e-5) ++outside;
      EXPECT_EQ(outside, 0u) << muscle.name;
    }
    // Deterministic: a second load gives the same geometry.
    const LoadedScene again = loadScene(builtIn.name);
    for (size_t m = 0; m < scene.muscles.size(); ++m)
      EXPECT_EQ(again.muscles[m].fibres.points, scene.muscles[m].fibres.points);
  }
}

TEST(Procedural, MuscleEndsTouchBones) {
  // Both ends of (nearly) every fibre lie within the attachment distance of some bone, so the
  // end particles become fixed; the rest of the muscle body stays clear of the bones.
  for (const auto& builtIn : fibremss::builtInScenes()) {
    const LoadedScene scene = loadScene(builtIn.name);
    if (scene.bones.empty() || builtIn.name == "sphere-planes") continue;  // free spheres
    SCOPED_TRACE(builtIn.name);
    std::vector<fibremss::MeshDistance> bones;
    for (const auto& bone : scene.bones) bones.emplace_back(bone.mesh);
    auto nearBone = [&](const btVector3& p, double limit) {
      for (const auto& bone : bones)
        if (std::abs(bone.signedDistance(p)) <= limit) return true;
      return false;
    };
    for (const auto& muscle : scene.muscles) {
      const double limit = muscle.parameters.attachmentDistance;
      size_t starts = 0, ends = 0, middles = 0, middleNear = 0;
      for (size_t f = 0; f < muscle.fibres.fibreCount(); ++f) {
        const auto fibre = muscle.fibres.fibre(f);
        starts += nearBone(fibre.front(), limit);
        ends += nearBone(fibre.back(), limit);
        for (size_t k = fibre.size() / 5; k < fibre.size() * 4 / 5; ++k, ++middles)
          middleNear += nearBone(fibre[k], limit);
      }
      const size_t fibres = muscle.fibres.fibreCount();
      EXPECT_GE(starts, fibres * 9 / 10) << muscle.name;
      EXPECT_GE(ends, fibres * 9 / 10) << muscle.name;
      EXPECT_LE(middleNear, middles / 20) << muscle.name;
    }
  }
}

TEST(Procedural, Thigh13MatchesTheThesisParticleCounts) {
  // 000 Table 5.2: 13 muscles × 64 fibres at resolution 20/40/60/80.
  const std::map<int, double> thesis = {{20, 16120}, {40, 32760}, {60, 49423}, {80, 66063}};
  for (const auto& [resolution, particles] : thesis) {
    const LoadedScene scene = loadScene("thigh13", {"resolution=" + std::to_string(resolution)});
    ASSERT_EQ(scene.muscles.size(), 13u);
    ASSERT_EQ(scene.bones.size(), 5u);
    const double total = totalParticles(scene);
    EXPECT_NEAR(total, particles, 0.05 * particles) << "resolution " << resolution;
  }
  // A walking-like motion: several poses, the pelvis still, the femur and shank moving.
  const LoadedScene scene = loadScene("thigh13");
  EXPECT_GE(scene.poseCount, 8);
  const btVector3 knee(0.025f, -0.45f, 0.02f);
  double largest = 0;
  for (int p = 0; p < scene.poseCount; ++p) {
    EXPECT_LT((scene.bonePose(0, p) * knee - knee).length(), 1e-6);  // pelvis
    largest = std::max(largest, double((scene.bonePose(3, p) * knee - knee).length()));
  }
  EXPECT_GT(largest, 0.05);
}

TEST(Procedural, HipSweepsHaveThePosesOfTheStressTests) {
  for (const auto& [step, poses] : std::map<int, int>{{2, 41}, {4, 21}, {5, 17}, {10, 9}}) {
    const LoadedScene scene = loadScene("hip-extension", {"step_deg=" + std::to_string(step)});
    EXPECT_EQ(scene.poseCount, poses) << step;
    EXPECT_DOUBLE_EQ(scene.poseLabels.back(), 80.0);
  }
  EXPECT_EQ(loadScene("hip-extension").poseCount, 9);  // default step 10°
  const LoadedScene adduction = loadScene("hip-adduction");
  EXPECT_EQ(adduction.poseCount, 31);
  EXPECT_DOUBLE_EQ(adduction.poseLabels[1], 2.0);
  for (const char* name : {"hip-flexion", "hip-extension", "hip-adduction", "hip-rotation"}) {
    const LoadedScene scene = loadScene(name);
    SCOPED_TRACE(name);
    ASSERT_EQ(scene.bones.size(), 2u);
    EXPECT_GE(scene.muscles.size(), 3u);
    EXPECT_LE(scene.muscles.size(), 4u);
    // A ball joint: the femoral head centre (the origin) stays put in every pose.
    for (int p = 0; p < scene.poseCount; ++p)
      EXPECT_LT((scene.bonePose(1, p) * btVector3(0, 0, 0)).length(), 1e-6);
    EXPECT_GT(std::abs(scene.poseLabels.back() - scene.poseLabels.front()), 30);
  }
}

TEST(Procedural, SphereScenesHave3840Particles) {
  for (const char* name : {"sphere-denoise", "sphere-planes"}) {
    const LoadedScene scene = loadScene(name);
    EXPECT_EQ(totalParticles(scene), 3840) << name;
  }
  EXPECT_GT(loadScene("sphere-denoise").simulation.initialNoise, 0);
  EXPECT_TRUE(loadScene("sphere-denoise").bones.empty());
  EXPECT_EQ(loadScene("sphere-planes").bones.size(), 2u);
}
