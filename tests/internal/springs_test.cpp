// Spring-force kernels (plugin/core/src/kernels/SpringForces.cpp): every kernel this build and
// CPU can run gives the forces, the deviation and the overstretched count of a plain
// double-precision computation, spring by spring, on prepared thigh muscles and on a hand-made
// grid, with and without the AVX2 kernel's spring blocks (layoutSprings), including coincident
// particles (zero force), overstretched springs, a non-finite position and runs of every length;
// every kernel counts the springs near the strain limit.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "kernels/SpringForces.h"
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

/// `kernel` matches the reference within float rounding of the force sums.
void expectKernelMatches(const MuscleSettings& settings, const std::vector<btVector3>& x,
                         SpringKernel kernel) {
  const Reference r = reference(settings, x);
  std::vector<btVector3> forces(x.size(), btVector3(1, 2, 3));  // overwritten
  const SpringForceResult result = springForces(settings, x, forces, kernel);
  EXPECT_EQ(result.overstretched, r.overstretched);
  EXPECT_EQ(result.exploded, r.overstretched > 0);
  EXPECT_NEAR(result.deviation, r.deviation, 1e-5 * r.deviation + 1e-6 * r.restLengthSum);
  size_t wrong = 0;
  for (size_t i = 0; i < x.size(); ++i)
    for (int c = 0; c < 3; ++c)
      if (!(std::fabs(forces[i][c] - r.force[3 * i + c]) <= 1e-5 * r.magnitude[i] + 1e-30)) ++wrong;
  EXPECT_EQ(wrong, 0u) << "force components off the reference";
}

/// Copies of the settings without spring blocks (AVX2 runs as SSE2) and laid out for AVX2.
std::vector<MuscleSettings> bothLayouts(const MuscleSettings& settings) {
  std::vector<MuscleSettings> both(2, settings);
  both[0].springBlocks = SpringBlocks{};
  layoutSprings(both[1]);
  return both;
}

/// A muscle of `count` particles at random places in a 1 cm cube whose particle a has a % 21
/// springs (runs of 0 to 20) to the next particles.
MuscleSettings runsOfEveryLength(uint32_t count) {
  MuscleSettings settings;
  std::mt19937 random(7);
  std::uniform_real_distribution<btScalar> place(0, btScalar(0.01));
  for (uint32_t i = 0; i < count; ++i)
    settings.restPositions.emplace_back(place(random), place(random), place(random));
  for (uint32_t a = 0; a < count; ++a)
    for (uint32_t b = a + 1; b <= a + a % 21 && b < count; ++b) {
      const btScalar length = settings.restPositions[a].distance(settings.restPositions[b]);
      settings.springs.push_back({a, b, length, 1 / length});
    }
  return settings;
}

/// Every available kernel matches the reference within float rounding of the force sums.
void expectKernelsMatch(const MuscleSettings& given, const std::vector<btVector3>& x,
                        const std::string& what) {
  ASSERT_GT(given.springs.size(), 0u) << what;
  for (const MuscleSettings& settings : bothLayouts(given))
    for (SpringKernel kernel : kKernels) {
      if (!springKernelAvailable(kernel)) continue;
      SCOPED_TRACE(what + " on the " + springKernelName(kernel) + " kernel, " +
                   (settings.springBlocks.springCount > 0 ? "laid out" : "not laid out"));
      expectKernelMatches(settings, x, kernel);
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
    EXPECT_EQ(settings.springBlocks.springCount, settings.springs.size()) << "not laid out";
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
  for (const MuscleSettings& settings : bothLayouts(*grid))
    for (SpringKernel kernel : kKernels) {
      if (!springKernelAvailable(kernel)) continue;
      SCOPED_TRACE(springKernelName(kernel));
      std::vector<btVector3> forces(x.size(), btVector3(1, 2, 3));
      springForces(settings, x, forces, kernel);
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
  size_t touching = 0, runs = 0;
  for (const Spring& spring : grid->springs) {
    touching += spring.a == broken || spring.b == broken;
    runs += spring.a == broken;
  }
  ASSERT_GT(touching, 0u);
  // The broken particle's own run ends in padding lanes (b = a), which are no springs.
  ASSERT_NE(runs % SpringBlocks::kLanes, 0u);
  for (const MuscleSettings& settings : bothLayouts(*grid))
    for (SpringKernel kernel : kKernels) {
      if (!springKernelAvailable(kernel)) continue;
      SCOPED_TRACE(springKernelName(kernel));
      std::vector<btVector3> forces(x.size());
      const SpringForceResult result = springForces(settings, x, forces, kernel);
      EXPECT_EQ(result.overstretched, touching);
      EXPECT_TRUE(result.exploded);
    }
}

TEST(SpringBlocks, EachRunFillsWholeBlocksOfOneParticle) {
  MuscleSettings settings = runsOfEveryLength(200);
  layoutSprings(settings);
  const SpringBlocks& blocks = settings.springBlocks;
  constexpr size_t lanes = SpringBlocks::kLanes;
  constexpr uint32_t bytes = sizeof(btVector3);
  ASSERT_EQ(blocks.springCount, settings.springs.size());
  ASSERT_EQ(blocks.a.size() % 2, 0u);
  ASSERT_EQ(blocks.b.size(), blocks.a.size() * lanes);
  ASSERT_EQ(blocks.restLength.size(), blocks.b.size());
  ASSERT_EQ(blocks.stiffness.size(), blocks.b.size());
  // Runs alternate between even and odd blocks: each of the two lists of blocks holds every
  // other run in order, its springs and then padding to the end of its last block; empty blocks
  // (padding only) even out the lists.
  size_t s = 0, runs = 0, spare[2] = {0, 0};
  size_t next[2] = {0, 1};  // the next block of each list
  for (uint32_t a = 0; a < settings.particleCount(); ++a) {
    size_t run = 0;
    while (s + run < settings.springs.size() && settings.springs[s + run].a == a) ++run;
    if (run == 0) continue;  // a particle without springs has no block
    size_t& block = next[runs++ % 2];
    for (size_t k = 0; k < (run + lanes - 1) / lanes; ++k, block += 2) {
      ASSERT_LT(block, blocks.a.size());
      EXPECT_EQ(blocks.a[block], a * bytes);
      for (size_t lane = block * lanes; lane < (block + 1) * lanes; ++lane) {
        const bool spring = lane - block * lanes + k * lanes < run;
        EXPECT_EQ(blocks.b[lane], spring ? settings.springs[s].b * bytes : a * bytes);
        EXPECT_EQ(blocks.restLength[lane], spring ? settings.springs[s].restLength : 0);
        EXPECT_EQ(blocks.stiffness[lane], spring ? settings.springs[s].stiffness : 0);
        s += spring;
      }
    }
  }
  EXPECT_EQ(s, settings.springs.size()) << "springs left out of the blocks";
  for (size_t half = 0; half < 2; ++half)
    for (size_t block = next[half]; block < blocks.a.size(); block += 2, ++spare[half])
      for (size_t lane = block * lanes; lane < (block + 1) * lanes; ++lane) {
        EXPECT_EQ(blocks.b[lane], blocks.a[block]) << "empty block " << block;
        EXPECT_EQ(blocks.stiffness[lane], 0);
      }
  EXPECT_EQ(std::min(spare[0], spare[1]), 0u) << "a group of empty blocks";
}

TEST(SpringBlocks, RunsOfEveryLengthMatchTheReference) {
  // Runs of 0 to 20 springs (none, padded, whole blocks, several blocks), an odd block count.
  for (uint32_t count : {200u, 203u}) {
    const MuscleSettings settings = runsOfEveryLength(count);
    std::vector<btVector3> x = jittered(settings, 0.3, count);
    expectKernelsMatch(settings, x, std::to_string(count) + " particles");
    collapseNeighbours(settings, x, 41);  // a run of 20 (41 % 21), coincident
    x[150] += btVector3(1, 0, 0);         // far: its springs are overstretched
    expectKernelsMatch(settings, x, std::to_string(count) + " particles, collapsed and far");
  }
}

TEST(SpringBlocks, ChangedSpringsAreNotReadFromStaleBlocks) {
  // Blocks laid out for other springs are not read: AVX2 runs on the springs as they are.
  const auto grid = testing::gridMuscle();
  MuscleSettings settings = *grid;
  layoutSprings(settings);
  settings.springs.resize(settings.springs.size() / 2);
  const std::vector<btVector3> x = jittered(settings, 0.3, 9);
  for (SpringKernel kernel : kKernels)
    if (springKernelAvailable(kernel)) {
      SCOPED_TRACE(springKernelName(kernel));
      expectKernelMatches(settings, x, kernel);
    }
}

TEST(SpringBlocks, AddMuscleLaysOutSpringsChangedByHand) {
  // Same count, new stiffness: a kernel that checked only the count would read the old blocks.
  auto changed = std::make_shared<MuscleSettings>(*testing::gridMuscle());
  layoutSprings(*changed);
  for (Spring& spring : changed->springs) spring.stiffness *= 3;
  MuscleSystem system;
  const BoneHandle bones[] = {system.addBone(testing::cubeBone("left", btVector3(-0.02f, 0, 0))),
                              system.addBone(testing::cubeBone("right", btVector3(0.02f, 0, 0)))};
  const MuscleSettings& used = system.settings(system.addMuscle(changed, bones));
  EXPECT_EQ(used.springs.size(), changed->springs.size());
  if (fastestSpringKernel() != SpringKernel::avx2) GTEST_SKIP() << "no AVX2: blocks unused";
  EXPECT_TRUE(used.springBlocks == springBlocksFor(*changed)) << "stale blocks kept";
  EXPECT_FALSE(changed->springBlocks == springBlocksFor(*changed));  // the test's premise
}

// The iteration's projection runs only for a muscle whose forces found a spring beyond
// kStrainWatch of the limit: every kernel counts them as a count over the springs does.
TEST(StrainLimit, EveryKernelCountsTheSpringsNearIt) {
  auto muscle = std::make_shared<MuscleSettings>(*testing::gridMuscle("near"));
  muscle->strainLimit = btScalar(1.5);
  layoutSprings(*muscle);  // AVX2 reads the blocks
  // The layers from x = 4 mm on moved 2 mm along x: the 4 mm springs across reach 1.5×, the
  // diagonal ones 1.27×, below the watch (1.35×).
  std::vector<btVector3> x = muscle->restPositions;
  for (btVector3& p : x)
    if (p.x() > btScalar(0.001)) p.setX(p.x() + btScalar(0.002));
  size_t near = 0;
  for (const Spring& spring : muscle->springs)
    near +=
        x[spring.a].distance(x[spring.b]) > kStrainWatch * muscle->strainLimit * spring.restLength;
  ASSERT_EQ(near, 9u);  // the 3 × 3 fibres' springs across
  std::vector<btVector3> forces(x.size());
  for (SpringKernel kernel : {SpringKernel::scalar, SpringKernel::sse2, SpringKernel::avx2}) {
    if (!springKernelAvailable(kernel)) continue;
    muscle->strainLimit = btScalar(1.5);
    EXPECT_EQ(springForces(*muscle, x, forces, kernel).nearLimit, near) << springKernelName(kernel);
    muscle->strainLimit = 0;
    EXPECT_EQ(springForces(*muscle, x, forces, kernel).nearLimit, 0u) << springKernelName(kernel);
  }
}

}  // namespace fibremss
