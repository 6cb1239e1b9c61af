// Particle order (plugin/core/src/prepare/PreparationReorder.*): preparation leaves the particles
// along the Morton curve, and a muscle whose particles are renumbered is the same muscle: every
// index in it follows the permutation (the spring blocks are laid out again), and it steps to the
// same positions up to the permutation (to float rounding: the spring and push sums run in another
// order).
#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <random>
#include <tuple>
#include <vector>

#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "kernels/SpringForces.h"
#include "prepare/PreparationReorder.h"
#include "support/ThighSteps.h"

namespace fibremss {
namespace {

using testing::preparedThigh;

/// A random permutation of n particles (new k is old order[k]).
std::vector<uint32_t> randomOrder(size_t n, uint32_t seed) {
  std::vector<uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  std::shuffle(order.begin(), order.end(), std::mt19937(seed));
  return order;
}

/// rank[old] = new.
std::vector<uint32_t> ranks(const std::vector<uint32_t>& order) {
  std::vector<uint32_t> rank(order.size());
  for (size_t k = 0; k < order.size(); ++k) rank[order[k]] = static_cast<uint32_t>(k);
  return rank;
}

/// Largest |a − b| over the components of two point lists.
btScalar maxDifference(std::span<const btVector3> a, std::span<const btVector3> b) {
  btScalar largest = 0;
  for (size_t i = 0; i < a.size(); ++i)
    for (int c = 0; c < 3; ++c) largest = std::max(largest, std::abs(a[i][c] - b[i][c]));
  return largest;
}

}  // namespace

TEST(Reorder, MortonOrderOfACubeIsTheZCurve) {
  // The corners of a cube, listed backwards: along the curve x varies first, then y, then z.
  std::vector<btVector3> corners;
  for (int code = 7; code >= 0; --code)
    corners.emplace_back(btScalar(code & 1), btScalar(code >> 1 & 1), btScalar(code >> 2 & 1));
  const std::vector<uint32_t> order = detail::mortonOrder(corners);
  const std::vector<uint32_t> expected = {7, 6, 5, 4, 3, 2, 1, 0};
  EXPECT_EQ(order, expected);
  // Coincident points keep their order.
  const std::vector<btVector3> same(3, btVector3(1, 2, 3));
  EXPECT_EQ(detail::mortonOrder(same), (std::vector<uint32_t>{0, 1, 2}));
}

TEST(Reorder, PreparedParticlesLieAlongTheMortonCurve) {
  LoadedScene scene;
  const PreparedScene& prepared = preparedThigh(scene);
  for (const auto& muscle : prepared.muscles) {
    const std::vector<uint32_t> order = detail::mortonOrder(muscle->restPositions);
    std::vector<uint32_t> identity(order.size());
    std::iota(identity.begin(), identity.end(), 0u);
    EXPECT_EQ(order, identity) << muscle->name;
  }
}

TEST(Reorder, EveryIndexFollowsThePermutation) {
  LoadedScene scene;
  const PreparedScene& prepared = preparedThigh(scene);
  for (const auto& original : prepared.muscles) {
    const MuscleSettings& old = *original;
    const std::vector<uint32_t> order = randomOrder(old.particleCount(), 7);
    const std::vector<uint32_t> rank = ranks(order);
    MuscleSettings muscle = old;
    detail::reorderParticles(muscle, order);
    SCOPED_TRACE(old.name);

    ASSERT_EQ(muscle.particleCount(), old.particleCount());
    for (size_t k = 0; k < order.size(); ++k) {
      const uint32_t i = order[k];
      ASSERT_EQ(muscle.restPositions[k], old.restPositions[i]);
      ASSERT_EQ(muscle.radii[k], old.radii[i]);
      ASSERT_EQ(muscle.flags[k], old.flags[i]);
      ASSERT_EQ(muscle.fixedBone[k], old.fixedBone[i]);
      ASSERT_EQ(muscle.nearestBone[k], old.nearestBone[i]);
      ASSERT_EQ(muscle.blendBoneA[k], old.blendBoneA[i]);
      ASSERT_EQ(muscle.blendBoneB[k], old.blendBoneB[i]);
      ASSERT_EQ(muscle.blendWeight[k], old.blendWeight[i]);
    }
    // The same springs between the renumbered ends, a < b, sorted by (a, b).
    using Key = std::tuple<uint32_t, uint32_t, btScalar, btScalar>;
    std::vector<Key> expected, actual;
    for (const Spring& s : old.springs)
      expected.emplace_back(std::min(rank[s.a], rank[s.b]), std::max(rank[s.a], rank[s.b]),
                            s.restLength, s.stiffness);
    std::sort(expected.begin(), expected.end());
    for (const Spring& s : muscle.springs) {
      EXPECT_LT(s.a, s.b);
      actual.emplace_back(s.a, s.b, s.restLength, s.stiffness);
    }
    EXPECT_TRUE(std::is_sorted(actual.begin(), actual.end()));
    EXPECT_EQ(actual, expected);
    // The AVX2 kernel's blocks follow the renumbered springs.
    MuscleSettings laidOut = muscle;
    layoutSprings(laidOut);
    EXPECT_EQ(muscle.springBlocks.springCount, muscle.springs.size());
    EXPECT_EQ(muscle.springBlocks.a, laidOut.springBlocks.a);
    EXPECT_EQ(muscle.springBlocks.b, laidOut.springBlocks.b);
    EXPECT_EQ(muscle.springBlocks.restLength, laidOut.springBlocks.restLength);
    EXPECT_EQ(muscle.springBlocks.stiffness, laidOut.springBlocks.stiffness);
    // Index lists: the renumbered particles, ascending where they were sorted.
    auto renumbered = [&rank](const std::vector<uint32_t>& indices, bool sorted) {
      std::vector<uint32_t> result;
      for (uint32_t i : indices) result.push_back(rank[i]);
      if (sorted) std::sort(result.begin(), result.end());
      return result;
    };
    EXPECT_EQ(muscle.boundaryParticles, renumbered(old.boundaryParticles, true));
    EXPECT_EQ(muscle.fixedParticles, renumbered(old.fixedParticles, true));
    EXPECT_EQ(muscle.fibreParticles, renumbered(old.fibreParticles, false));
    EXPECT_EQ(muscle.skinParticles, renumbered(old.skinParticles, false));
    EXPECT_EQ(muscle.tetParticles, renumbered(old.tetParticles, false));
    EXPECT_EQ(muscle.tetInverseVolume, old.tetInverseVolume);
    EXPECT_EQ(muscle.tetRestGradient, old.tetRestGradient);
    EXPECT_EQ(muscle.fanParticles, renumbered(old.fanParticles, false));
    EXPECT_EQ(muscle.fanOffsets, old.fanOffsets);
    EXPECT_EQ(muscle.fanInverseVolume, old.fanInverseVolume);
    EXPECT_EQ(muscle.fanRestGradient, old.fanRestGradient);
    // What is not per particle stays.
    EXPECT_EQ(muscle.fibreOffsets, old.fibreOffsets);
    EXPECT_EQ(muscle.skinWeights, old.skinWeights);
    EXPECT_EQ(muscle.skinNeighbours, old.skinNeighbours);
    EXPECT_EQ(muscle.particleMass, old.particleMass);
    EXPECT_EQ(muscle.damping, old.damping);
    EXPECT_EQ(muscle.restSurface.vertices, old.restSurface.vertices);
  }
}

TEST(Reorder, NotAPermutationIsRefused) {
  LoadedScene scene;
  MuscleSettings muscle = *preparedThigh(scene).muscles[0];
  std::vector<uint32_t> order(muscle.particleCount(), 0);
  EXPECT_THROW(detail::reorderParticles(muscle, order), std::invalid_argument);
  order.resize(1);
  EXPECT_THROW(detail::reorderParticles(muscle, order), std::invalid_argument);
}

TEST(Reorder, ARenumberedMuscleGivesTheSameForces) {
  LoadedScene scene;
  const MuscleSettings& old = *preparedThigh(scene).muscles[0];
  const std::vector<uint32_t> order = randomOrder(old.particleCount(), 11);
  MuscleSettings muscle = old;
  detail::reorderParticles(muscle, order);
  // Stretched: every particle moved by its own amount.
  std::vector<btVector3> x(old.particleCount()), y(old.particleCount());
  std::mt19937 random(3);
  std::uniform_real_distribution<btScalar> jitter(-0.001, 0.001);  // ±1 mm
  for (size_t i = 0; i < x.size(); ++i)
    x[i] = old.restPositions[i] + btVector3(jitter(random), jitter(random), jitter(random));
  for (size_t k = 0; k < y.size(); ++k) y[k] = x[order[k]];
  std::vector<btVector3> forces(x.size()), permutedForces(x.size());
  const SpringForceResult first = springForces(old, x, forces);
  const SpringForceResult second = springForces(muscle, y, permutedForces);
  btScalar largest = 0, difference = 0;
  for (size_t k = 0; k < y.size(); ++k) {
    largest = std::max(largest, forces[order[k]].length());
    difference = std::max(difference, (forces[order[k]] - permutedForces[k]).length());
  }
  ASSERT_GT(largest, 0);
  // Each force is a sum of the same terms in another order: float rounding only.
  EXPECT_LE(difference, 1e-5 * largest);
  EXPECT_NEAR(first.deviation, second.deviation, 1e-5 * first.deviation);
  EXPECT_EQ(first.overstretched, second.overstretched);
}

TEST(Reorder, RenumberedMusclesStepToTheSamePlaces) {
  LoadedScene scene;
  const PreparedScene& prepared = preparedThigh(scene);
  std::vector<std::shared_ptr<const MuscleSettings>> renumbered;
  std::vector<std::vector<uint32_t>> orders;
  for (size_t m = 0; m < prepared.muscles.size(); ++m) {
    orders.push_back(randomOrder(prepared.muscles[m]->particleCount(), static_cast<uint32_t>(m)));
    auto muscle = std::make_shared<MuscleSettings>(*prepared.muscles[m]);
    detail::reorderParticles(*muscle, orders.back());
    renumbered.push_back(muscle);
  }
  // Two steps through the first poses: the muscles touch each other and the bones.
  const testing::StepOutcome reference =
      testing::stepThroughPoses(scene, prepared, prepared.muscles, 1);
  const testing::StepOutcome outcome = testing::stepThroughPoses(scene, prepared, renumbered, 1);
  for (size_t m = 0; m < prepared.muscles.size(); ++m) {
    SCOPED_TRACE(prepared.muscles[m]->name);
    const std::vector<btVector3>& x = reference.positions[m];
    std::vector<btVector3> back(x.size());
    for (size_t k = 0; k < back.size(); ++k) back[orders[m][k]] = outcome.positions[m][k];
    btVector3 lower = x[0], upper = x[0];
    for (const btVector3& p : x) {
      lower.setMin(p);
      upper.setMax(p);
    }
    // Float rounding of sums in another order, grown over 40 iterations, and where it decides
    // whether an L-BFGS pair lies above the forces' rounding (its sums run in the new order too),
    // another history from there: measured ≤ 6.9e-6 m (2.8e-6 of the muscle's size, biceps
    // femoris short), far below a particle spacing (1/20 of the muscle here).
    const btScalar tolerance = btScalar(1e-4) * (upper - lower).length();
    EXPECT_LE(maxDifference(x, back), tolerance);
    EXPECT_LE(maxDifference(reference.surfaces[m], outcome.surfaces[m]), tolerance);
  }
}

}  // namespace fibremss
