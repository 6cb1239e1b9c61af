// Spring-force kernels (plugin/src/MuscleSystemForces.cpp): every kernel this build and CPU can
// run gives the forces, the deviation and the overstretched count of a plain double-precision
// computation, spring by spring, on prepared thigh muscles and on a hand-made grid, including
// coincident particles (zero force), overstretched springs and a non-finite position.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include "../plugin/src/SpringForces.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "support/GridMuscle.h"
#include "support/ThighSteps.h"

namespace fibremss {
namespace {

/// Every kernel, for the loops over them.
constexpr SpringKernel kKernels[] = {SpringKernel::scalar, SpringKernel::sse2, SpringKernel::avx2};

/// The spring forces in double, one spring at a time, with the scale of the rounding a float
/// kernel may carry per particle: l − L0 in float is off by a few ulps of l, so Σ k·(l + L0)
/// over the particle's springs (which also bounds Σ |f|).
struct Reference {
  std::vector<double> force;      ///< 3 per particle
  std::vector<double> magnitude;  ///< Σ k·(l + L0) per particle
  double deviation = 0;           ///< Σ |l − L0|
  size_t overstretched = 0;       ///< springs with not (l − L0 ≤ 2·L0)
  double restLengthSum = 0;       ///< Σ L0, the scale of the deviation's rounding
};

Reference reference(const MuscleSettings& settings, const std::vector<btVector3>& x) {
  Reference r;
  r.force.assign(3 * x.size(), 0);
  r.magnitude.assign(x.size(), 0);
  for (const Spring& spring : settings.springs) {
    double d[3], length2 = 0;
    for (int c = 0; c < 3; ++c) {
      d[c] = double(x[spring.b][c]) - double(x[spring.a][c]);
      length2 += d[c] * d[c];
    }
    const double length = std::sqrt(length2), stretch = length - spring.restLength;
    r.deviation += std::fabs(stretch);
    r.restLengthSum += spring.restLength;
    if (!(stretch <= 2.0 * spring.restLength)) ++r.overstretched;
    const double factor = length > 0 ? spring.stiffness * stretch / length : 0;
    for (int c = 0; c < 3; ++c) {
      r.force[3 * spring.a + c] += factor * d[c];
      r.force[3 * spring.b + c] -= factor * d[c];
    }
    r.magnitude[spring.a] += spring.stiffness * (length + spring.restLength);
    r.magnitude[spring.b] += spring.stiffness * (length + spring.restLength);
  }
  return r;
}

/// Rest positions moved by up to ±`jitter` of the muscle's mean rest length per axis.
std::vector<btVector3> jittered(const MuscleSettings& settings, double jitter, uint32_t seed) {
  double mean = 0;
  for (const Spring& spring : settings.springs) mean += spring.restLength;
  mean /= double(settings.springs.size());
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> offset(-jitter * mean, jitter * mean);
  std::vector<btVector3> x = settings.restPositions;
  for (btVector3& p : x)
    p += btVector3(btScalar(offset(random)), btScalar(offset(random)), btScalar(offset(random)));
  return x;
}

/// Moves every spring neighbour b of the particle `a` onto it: a run of zero-length springs.
void collapseNeighbours(const MuscleSettings& settings, std::vector<btVector3>& x, uint32_t a) {
  for (const Spring& spring : settings.springs)
    if (spring.a == a) x[spring.b] = x[a];
}

/// Every available kernel matches the reference within float rounding of the force sums.
void expectKernelsMatch(const MuscleSettings& settings, const std::vector<btVector3>& x,
                        const std::string& what) {
  const Reference r = reference(settings, x);
  ASSERT_GT(settings.springs.size(), 0u) << what;
  for (SpringKernel kernel : kKernels) {
    if (!springKernelAvailable(kernel)) continue;
    SCOPED_TRACE(what + " on the " + springKernelName(kernel) + " kernel");
    std::vector<btVector3> forces(x.size(), btVector3(1, 2, 3));  // overwritten
    const SpringForceResult result = springForces(settings, x, forces, kernel);
    EXPECT_EQ(result.overstretched, r.overstretched);
    EXPECT_EQ(result.exploded, r.overstretched > 0);
    EXPECT_NEAR(result.deviation, r.deviation, 1e-5 * r.deviation + 1e-6 * r.restLengthSum);
    size_t wrong = 0;
    for (size_t i = 0; i < x.size(); ++i)
      for (int c = 0; c < 3; ++c)
        if (!(std::fabs(forces[i][c] - r.force[3 * i + c]) <= 1e-5 * r.magnitude[i] + 1e-30))
          ++wrong;
    EXPECT_EQ(wrong, 0u) << "force components off the reference";
  }
}

}  // namespace

TEST(SpringKernels, TheFastestIsAvailableAndTheScalarAlwaysIs) {
  EXPECT_TRUE(springKernelAvailable(SpringKernel::scalar));
  EXPECT_TRUE(springKernelAvailable(fastestSpringKernel()));
  for (SpringKernel kernel : kKernels)
    if (springKernelAvailable(kernel))
      std::printf("kernel available: %s\n", springKernelName(kernel));
}

TEST(SpringKernels, PreparedMusclesMatchTheReference) {
  LoadedScene scene;
  const PreparedScene& prepared = testing::preparedThigh(scene);
  ASSERT_FALSE(prepared.muscles.empty());
  for (const auto& muscle : prepared.muscles) {
    const MuscleSettings& settings = *muscle;
    std::vector<btVector3> x = jittered(settings, 0.2, 11);
    expectKernelsMatch(settings, x, muscle->name + " jittered");
    // A run of coincident particles in the middle of the spring list, and one particle pulled
    // far away: its springs are beyond 3× their rest length.
    const Spring& middle = settings.springs[settings.springs.size() / 2];
    collapseNeighbours(settings, x, middle.a);
    const uint32_t far = settings.springs[settings.springs.size() / 3].b;
    x[far] += btVector3(1, 0, 0);
    const Reference r = reference(settings, x);
    ASSERT_GT(r.overstretched, 0u);
    expectKernelsMatch(settings, x, muscle->name + " collapsed and overstretched");
  }
}

TEST(SpringKernels, CoincidentEndsGiveZeroForce) {
  const auto grid = testing::gridMuscle();
  std::vector<btVector3> x = grid->restPositions;
  // The first spring's a is the lowest particle index: it is no spring's b, so the force on it
  // comes from its own springs only, all of zero length.
  const uint32_t a = grid->springs.front().a;
  collapseNeighbours(*grid, x, a);
  for (SpringKernel kernel : kKernels) {
    if (!springKernelAvailable(kernel)) continue;
    SCOPED_TRACE(springKernelName(kernel));
    std::vector<btVector3> forces(x.size(), btVector3(1, 2, 3));
    springForces(*grid, x, forces, kernel);
    for (int c = 0; c < 3; ++c) EXPECT_EQ(forces[a][c], 0);
  }
  expectKernelsMatch(*grid, x, "grid with a collapsed run");
}

TEST(SpringKernels, SpringListsOfEveryLengthMatch) {
  // Prefixes of the grid's springs: every remainder modulo the vector widths, and runs cut
  // anywhere.
  const auto grid = testing::gridMuscle();
  const std::vector<btVector3> x = jittered(*grid, 0.3, 5);
  for (size_t count : {1u, 3u, 4u, 7u, 8u, 9u, 15u, 17u, 31u, 100u}) {
    MuscleSettings cut = *grid;
    ASSERT_LE(count, cut.springs.size());
    cut.springs.resize(count);
    expectKernelsMatch(cut, x, "first " + std::to_string(count) + " springs");
  }
}

TEST(SpringKernels, NonFinitePositionCountsAsOverstretched) {
  const auto grid = testing::gridMuscle();
  std::vector<btVector3> x = grid->restPositions;
  const uint32_t broken = 31;
  x[broken] = btVector3(std::nanf(""), 0, 0);
  size_t touching = 0;
  for (const Spring& spring : grid->springs) touching += spring.a == broken || spring.b == broken;
  ASSERT_GT(touching, 0u);
  for (SpringKernel kernel : kKernels) {
    if (!springKernelAvailable(kernel)) continue;
    SCOPED_TRACE(springKernelName(kernel));
    std::vector<btVector3> forces(x.size());
    const SpringForceResult result = springForces(*grid, x, forces, kernel);
    EXPECT_EQ(result.overstretched, touching);
    EXPECT_TRUE(result.exploded);
  }
}

}  // namespace fibremss
