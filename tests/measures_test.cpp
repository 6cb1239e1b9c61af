// The accuracy measures on constructed cases whose answers are known by construction.
#include "fibremss/Measures.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "fibremss/Error.h"

namespace fibremss {
namespace {

/// Axis-aligned cube of half side `half` centred at the origin, outward-facing triangles.
TriangleMesh cube(btScalar half) {
  TriangleMesh mesh;
  for (int i = 0; i < 8; ++i) {
    mesh.vertices.emplace_back(i & 1 ? half : -half, i & 2 ? half : -half, i & 4 ? half : -half);
  }
  mesh.triangles = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                    {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return mesh;
}

TEST(RmsDistance, SurfaceShiftedByOneMillimetreHasRmsOneMillimetre) {
  const TriangleMesh surface = cube(0.01f);
  const btVector3 shift = btVector3(0.6f, 0.8f, 0.0f) * 0.001f;  // |shift| = 1 mm
  std::vector<btVector3> shifted;
  for (const btVector3& v : surface.vertices) shifted.push_back(v + shift);
  EXPECT_NEAR(rmsDistanceMm(surface.vertices, shifted), 1.0, 1e-4);
  EXPECT_NEAR(rmsDistanceMm(surface.vertices, surface.vertices), 0.0, 1e-9);
}

TEST(RmsDistance, MixedDisplacementsGiveTheRootMeanSquare) {
  // Half the points moved 1 mm, half 3 mm: sqrt((1 + 9) / 2) = sqrt(5) mm.
  std::vector<btVector3> a(10, btVector3(0, 0, 0));
  std::vector<btVector3> b;
  for (size_t i = 0; i < a.size(); ++i) b.emplace_back(0, 0, i % 2 ? 0.001f : -0.003f);
  EXPECT_NEAR(rmsDistanceMm(a, b), std::sqrt(5.0), 1e-4);
}

TEST(RmsDistance, RejectsDifferentCountsAndMarksEmptyAsNotMeasured) {
  std::vector<btVector3> two(2), three(3);
  EXPECT_THROW(rmsDistanceMm(two, three), InputError);
  EXPECT_TRUE(std::isnan(rmsDistanceMm({}, {})));
}

class PenetrationTest : public ::testing::Test {
 protected:
  TriangleMesh boneMesh = cube(0.01f);  // 20 mm cube
  MeshDistance bone{boneMesh};
};

TEST_F(PenetrationTest, VertexTwoMillimetresInsideGivesTwoMillimetres) {
  const MeshDistance* bones[] = {&bone};
  const btTransform identity = btTransform::getIdentity();
  const btVector3 points[] = {btVector3(0.008f, 0, 0),  // 2 mm inside the +x face
                              btVector3(0.02f, 0, 0)};  // outside
  const Penetration p = measurePenetration(points, bones, {&identity, 1});
  EXPECT_NEAR(p.maxMm, 2.0, 1e-3);
  EXPECT_NEAR(p.meanMm, 2.0, 1e-3);
  EXPECT_EQ(p.penetrating, 1u);
  EXPECT_EQ(p.points, 2u);
}

TEST_F(PenetrationTest, PointsAreMeasuredInTheMovedBone) {
  // The bone is rotated and translated; a point at the transformed rest position 2 mm inside
  // stays 2 mm inside, and the rest-pose position of that point is now outside.
  const btTransform moved(btQuaternion(btVector3(1, 1, 0).normalized(), 0.7f),
                          btVector3(0.1f, -0.05f, 0.2f));
  const MeshDistance* bones[] = {&bone};
  const btVector3 restPoint(0, 0.008f, 0);
  const btVector3 points[] = {moved * restPoint, restPoint};
  const Penetration p = measurePenetration(points, bones, {&moved, 1});
  EXPECT_NEAR(p.maxMm, 2.0, 1e-3);
  EXPECT_EQ(p.penetrating, 1u);
}

TEST_F(PenetrationTest, DeepestBoneCountsAndMeanIsOverPenetratingPoints) {
  // Two overlapping cubes: the second shifted by 5 mm along x. The point x = 8 mm is 2 mm
  // inside the first and 7 mm inside the second: 7 mm counts.
  const btTransform transforms[] = {
      btTransform::getIdentity(),
      btTransform(btQuaternion::getIdentity(), btVector3(0.005f, 0, 0))};
  const MeshDistance* bones[] = {&bone, &bone};
  const btVector3 points[] = {btVector3(0.008f, 0, 0), btVector3(-0.009f, 0, 0),
                              btVector3(0.05f, 0, 0)};
  const Penetration p = measurePenetration(points, bones, transforms);
  EXPECT_NEAR(p.maxMm, 7.0, 1e-3);
  EXPECT_NEAR(p.meanMm, (7.0 + 1.0) / 2.0, 1e-3);
  EXPECT_EQ(p.penetrating, 2u);
  EXPECT_EQ(p.points, 3u);
}

TEST(PenetrationCombine, TakesMaxAndWeightsMeansByPenetratingCounts) {
  Penetration a{.maxMm = 4, .meanMm = 2, .penetrating = 3, .points = 10};
  Penetration b{.maxMm = 1, .meanMm = 1, .penetrating = 1, .points = 5};
  const Penetration c = combine(a, b);
  EXPECT_DOUBLE_EQ(c.maxMm, 4);
  EXPECT_DOUBLE_EQ(c.meanMm, (2 * 3 + 1 * 1) / 4.0);
  EXPECT_EQ(c.penetrating, 4u);
  EXPECT_EQ(c.points, 15u);
  const Penetration none = combine(Penetration{}, Penetration{.points = 2});
  EXPECT_EQ(none.meanMm, 0);
  EXPECT_EQ(none.points, 2u);
}

TEST(VolumeChange, SurfaceScaledBySChangesVolumeBySCubedMinusOne) {
  const TriangleMesh rest = cube(0.02f);
  for (const double s : {0.9, 1.0, 1.1, 1.5}) {
    std::vector<btVector3> scaled;
    for (const btVector3& v : rest.vertices) scaled.push_back(v * static_cast<btScalar>(s));
    EXPECT_NEAR(volumeChangePercent(rest, scaled), (s * s * s - 1) * 100, 1e-3) << "s = " << s;
  }
}

TEST(VolumeChange, RigidMotionKeepsTheVolume) {
  const TriangleMesh rest = cube(0.02f);
  const btTransform motion(btQuaternion(btVector3(0, 0, 1), 1.0f), btVector3(1, 2, 3));
  std::vector<btVector3> moved;
  for (const btVector3& v : rest.vertices) moved.push_back(motion * v);
  EXPECT_NEAR(volumeChangePercent(rest, moved), 0.0, 1e-2);
}

TEST(SpringDeviation, UniformStretchGivesTheStretch) {
  // A chain of 5 particles 10 mm apart, stretched by 10 %: every spring deviates by 10 %.
  std::vector<btVector3> rest, stretched;
  std::vector<Spring> springs;
  for (uint32_t i = 0; i < 5; ++i) {
    rest.emplace_back(0.01f * static_cast<btScalar>(i), 0, 0);
    stretched.push_back(rest.back() * 1.1f);
    if (i > 0) springs.push_back({i - 1, i, 0.01f, 100});
  }
  EXPECT_NEAR(springDeviationRatio(springs, rest), 0.0, 1e-6);
  EXPECT_NEAR(springDeviationRatio(springs, stretched), 0.1, 1e-5);
}

TEST(SpringDeviation, WeightsBySumOfRestLengths) {
  // Springs of rest 1 and 3 (same particles' positions give lengths 2 and 3):
  // (|2−1| + |3−3|) / (1 + 3) = 0.25; compression counts like stretch.
  const std::vector<btVector3> positions = {{0, 0, 0}, {2, 0, 0}, {0, 3, 0}};
  const std::vector<Spring> springs = {{0, 1, 1, 1}, {0, 2, 3, 1}};
  EXPECT_NEAR(springDeviationRatio(springs, positions), 0.25, 1e-6);
  const std::vector<Spring> compressed = {{0, 1, 4, 1}};
  EXPECT_NEAR(springDeviationRatio(compressed, positions), 0.5, 1e-6);
  const std::vector<Spring> outside = {{0, 7, 1, 1}};
  EXPECT_THROW(springDeviationRatio(outside, positions), InputError);
}

TEST(SpringExploded, PastThreeTimesAndPastTheMeanRestLength) {
  const double meanRest = 2e-3;
  EXPECT_TRUE(springExploded(3.1 * 1e-3, 1e-3, meanRest));   // 2.1 mm longer than at rest
  EXPECT_FALSE(springExploded(2.9 * 3e-3, 3e-3, meanRest));  // stretched, but below 3x
  // A 0.08 mm spring at 4x is 0.24 mm long: harmless next to a 2 mm mean rest length.
  EXPECT_FALSE(springExploded(4 * 0.08e-3, 0.08e-3, meanRest));
  EXPECT_TRUE(springExploded(std::nan(""), 1e-3, meanRest));
  EXPECT_FALSE(springExploded(0, 1e-3, meanRest));  // compressed to nothing is not an explosion
}

}  // namespace
}  // namespace fibremss
