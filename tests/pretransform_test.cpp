// The blended pre-transform (method.md §4): the dual-quaternion blend is rigid for every weight,
// so it keeps what a rotation keeps where the linear blend pulls points towards the axis.
#include "fibremss/Pretransform.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

namespace fibremss {
namespace {

/// Settings whose particles blend bone 0 (weight 1 − w) and bone 1 (w), one per weight.
MuscleSettings blendedBetweenTwoBones(const std::vector<btScalar>& weights) {
  MuscleSettings settings;
  settings.blendWeight = weights;
  settings.blendBoneA.assign(weights.size(), 0);
  settings.blendBoneB.assign(weights.size(), 1);
  settings.nearestBone.assign(weights.size(), 0);
  return settings;
}

TEST(DualQuaternionPretransform, IdentityMotionsLeaveEveryPointBitForBit) {
  std::mt19937 random(5);
  std::uniform_real_distribution<double> uniform(-0.2, 0.2);
  std::vector<btScalar> weights;
  for (int i = 0; i < 100; ++i) weights.push_back(btScalar((i + 0.5) / 100));
  const MuscleSettings settings = blendedBetweenTwoBones(weights);
  const btTransform both[2] = {btTransform::getIdentity(), btTransform::getIdentity()};
  const btTransform one[1] = {btTransform::getIdentity()};  // bone 1 beyond: the identity
  for (uint32_t i = 0; i < weights.size(); ++i) {
    const btVector3 p(btScalar(uniform(random)), btScalar(uniform(random)),
                      btScalar(uniform(random)));
    for (std::span<const btTransform> transforms :
         {std::span<const btTransform>(both), std::span<const btTransform>(one)}) {
      const btVector3 moved =
          pretransformPoint(settings, transforms, i, p, true, PretransformBlend::DualQuaternion);
      const btVector3 turned = pretransformDirection(settings, transforms, i, p, true,
                                                     PretransformBlend::DualQuaternion);
      EXPECT_EQ(std::memcmp(moved.m_floats, p.m_floats, 3 * sizeof(btScalar)), 0) << i;
      EXPECT_EQ(std::memcmp(turned.m_floats, p.m_floats, 3 * sizeof(btScalar)), 0) << i;
    }
  }
}

TEST(DualQuaternionPretransform, KeepsTheDistanceToACommonAxisWhereTheLinearBlendLosesIt) {
  // Bone 0 stays, bone 1 turns 170° about an axis through c; points between the bones with
  // weights spread over (0, 1). The dual-quaternion blend turns each point about that axis (its
  // distance to it and its place along it kept); the linear blend takes the chord, at w = ½
  // to cos 85° = 0.09 of the distance. Directions turn as differences of moved points.
  const btVector3 axis = btVector3(1, 2, -1).normalized(), c(0.02f, -0.01f, 0.03f);
  const btQuaternion turn(axis, btScalar(170 * M_PI / 180));
  const btTransform transforms[2] = {btTransform::getIdentity(),
                                     btTransform(turn, c - quatRotate(turn, c))};
  std::mt19937 random(11);
  std::uniform_real_distribution<double> uniform(-0.1, 0.1);
  std::vector<btScalar> weights;
  for (int i = 0; i < 200; ++i) weights.push_back(btScalar((i + 0.5) / 200));
  const MuscleSettings settings = blendedBetweenTwoBones(weights);
  const auto radial = [&](const btVector3& p) { return (p - c) - axis * axis.dot(p - c); };
  double worstDual = 0, leastLinear = 1;
  for (uint32_t i = 0; i < weights.size(); ++i) {
    const btVector3 p(btScalar(uniform(random)), btScalar(uniform(random)),
                      btScalar(uniform(random)));
    const btVector3 dual =
        pretransformPoint(settings, transforms, i, p, true, PretransformBlend::DualQuaternion);
    const btVector3 linear =
        pretransformPoint(settings, transforms, i, p, true, PretransformBlend::Linear);
    const double r = radial(p).length();
    worstDual = std::max(worstDual, std::abs(radial(dual).length() - r) / r);
    EXPECT_NEAR(axis.dot(dual - c), axis.dot(p - c), 1e-6) << i;
    leastLinear = std::min(leastLinear, double(radial(linear).length()) / r);
    const btVector3 d(0.01f, -0.02f, 0.005f);
    const btVector3 turned =
        pretransformDirection(settings, transforms, i, d, true, PretransformBlend::DualQuaternion);
    const btVector3 difference =
        pretransformPoint(settings, transforms, i, p + d, true, PretransformBlend::DualQuaternion) -
        dual;
    EXPECT_LT((turned - difference).length(), 1e-6) << i;
  }
  EXPECT_LT(worstDual, 1e-4);
  EXPECT_LT(leastLinear, 0.2);
}

/// The volume of the bar [0, length] × [−half, half]² (a grid of n × m × m cubes, six
/// tetrahedra each) with each grid point p moved by move(p, p.x / length).
template <typename Move>
double barVolume(double length, double half, int n, int m, const Move& move) {
  const auto point = [&](int i, int j, int k) {
    const btVector3 p(btScalar(length * i / n), btScalar(-half + 2 * half * j / m),
                      btScalar(-half + 2 * half * k / m));
    return move(p, btScalar(double(i) / n));
  };
  // The six tetrahedra of a cube along its main diagonal (corner 0 to corner 7).
  constexpr int kPaths[6][2] = {{1, 3}, {1, 5}, {2, 3}, {2, 6}, {4, 5}, {4, 6}};
  double volume = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < m; ++j)
      for (int k = 0; k < m; ++k) {
        btVector3 corner[8];
        for (int v = 0; v < 8; ++v) corner[v] = point(i + (v & 1), j + (v >> 1 & 1), k + (v >> 2));
        for (const auto& path : kPaths) {
          const btVector3 a = corner[path[0]] - corner[0], b = corner[path[1]] - corner[0],
                          d = corner[7] - corner[0];
          volume += std::abs(a.dot(b.cross(d))) / 6;
        }
      }
  return volume;
}

TEST(DualQuaternionPretransform, ATwistedBarKeepsItsVolume) {
  // A bar from a fixed bone (w = 0) to one twisted 150° about the bar's axis (w = 1), the weight
  // rising along it, moved by the pre-transform alone in one step. Dual quaternions turn each
  // cross-section rigidly (an exact twist keeps volume); the linear blend shrinks a section at
  // weight w to 1 − 2w(1 − w)(1 − cos 150°) of its area: −62 % over the bar.
  const btTransform transforms[2] = {
      btTransform::getIdentity(),
      btTransform(btQuaternion(btVector3(1, 0, 0), btScalar(150 * M_PI / 180)))};
  const MuscleSettings settings = blendedBetweenTwoBones({0});
  const auto moved = [&](PretransformBlend blend) {
    return [&, blend](const btVector3& p, btScalar w) {
      MuscleSettings one = settings;
      one.blendWeight[0] = w;
      return pretransformPoint(one, transforms, 0, p, true, blend);
    };
  };
  constexpr double kLength = 0.2, kHalf = 0.01;
  constexpr int kCells = 60, kSide = 4;
  const double rest =
      barVolume(kLength, kHalf, kCells, kSide, [](const btVector3& p, btScalar) { return p; });
  EXPECT_NEAR(rest, kLength * 4 * kHalf * kHalf, 1e-3 * rest);
  const double dual =
      barVolume(kLength, kHalf, kCells, kSide, moved(PretransformBlend::DualQuaternion));
  const double linear = barVolume(kLength, kHalf, kCells, kSide, moved(PretransformBlend::Linear));
  EXPECT_NEAR(dual / rest, 1, 0.01);
  EXPECT_LT(linear / rest, 0.5);
}

}  // namespace
}  // namespace fibremss
