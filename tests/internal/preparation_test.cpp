// Preparation (method.md §2, §3, §6) on small fixtures whose answers are known: particle
// counts and positions, spring layouts, fixed and boundary particles, radii, bone spheres.
#include "fibremss/Preparation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <set>

#include "fibremss/Error.h"
#include "fibremss/Measures.h"
#include "prepare/PreparationInternal.h"
#include "support/PrepFixtures.h"

namespace fibremss {
namespace {

using testing::boxMesh;
using testing::bruteDistance;
using testing::sphereMesh;
using testing::tubeMesh;

/// A box muscle [x0, x1] × [y − w, y + w] × [−w, w] with straight fibres along x on a
/// rows × columns grid (row-major), inset from the surface.
MuscleInput gridMuscle(const std::string& name, btScalar x0, btScalar x1, btScalar y, btScalar w,
                       int rows, int columns, int resolution) {
  MuscleInput muscle;
  muscle.name = name;
  muscle.surface = boxMesh({x0, y - w, -w}, {x1, y + w, w});
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < columns; ++c) {
      const btScalar fy = y - w + (c + btScalar(0.5)) * 2 * w / columns;
      const btScalar fz = -w + (r + btScalar(0.5)) * 2 * w / rows;
      const std::vector<btVector3> line = {{x0, fy, fz}, {(x0 + x1) / 2, fy, fz}, {x1, fy, fz}};
      muscle.fibres.addFibre(line);
    }
  muscle.fibreGridColumns = columns;
  muscle.parameters.resolution = resolution;
  muscle.parameters.attachmentDistance = 0.004f;
  return muscle;
}

/// A tube muscle along x of radius `radius` with fibres on a square grid inside the circle.
MuscleInput tubeMuscle(const std::string& name, btScalar x0, btScalar x1, btScalar radius,
                       int resolution) {
  MuscleInput muscle;
  muscle.name = name;
  muscle.surface = tubeMesh(x0, x1, radius, 24, 12);
  const int grid = 6;
  // Small deterministic offsets break the grid's symmetry: no surface vertex is equally close
  // to two particles, so "the closest particle" has one answer.
  std::mt19937 random(42);
  std::uniform_real_distribution<btScalar> wobble(-0.05f * radius, 0.05f * radius);
  for (int r = 0; r < grid; ++r)
    for (int c = 0; c < grid; ++c) {
      const btScalar fy = radius * (-0.75f + 1.5f * c / (grid - 1)) + wobble(random);
      const btScalar fz = radius * (-0.75f + 1.5f * r / (grid - 1)) + wobble(random);
      if (fy * fy + fz * fz > 0.8f * radius * radius) continue;
      const std::vector<btVector3> line = {{x0, fy, fz}, {x1, fy, fz}};
      muscle.fibres.addFibre(line);
    }
  muscle.parameters.resolution = resolution;
  return muscle;
}

BoneInput boxBone(const std::string& name, const btVector3& lower, const btVector3& upper) {
  BoneInput bone;
  bone.name = name;
  bone.mesh = boxMesh(lower, upper);
  return bone;
}

BoneInput sphereBone(const std::string& name, const btVector3& centre, btScalar radius) {
  BoneInput bone;
  bone.name = name;
  bone.mesh = sphereMesh(centre, radius, 3);
  return bone;
}

/// Boxes at both ends of a gridMuscle from x = 0 to 0.1 m: "left" and "right".
std::vector<BoneInput> endBones() {
  return {boxBone("left", {-0.03f, -0.02f, -0.02f}, {0, 0.02f, 0.02f}),
          boxBone("right", {0.1f, -0.02f, -0.02f}, {0.13f, 0.02f, 0.02f})};
}

/// endBones() and `more`.
std::vector<BoneInput> endBonesAnd(std::vector<BoneInput> more) {
  std::vector<BoneInput> bones = endBones();
  bones.insert(bones.end(), more.begin(), more.end());
  return bones;
}

/// Sorted springs with their rest lengths; k = κ/L0 by length, and by volume k·L0 varies but the
/// network keeps κ/L0's Σ k·L0² = κ·Σ L0 (these muscles have no fixed springs to drop).
void expectWellFormedSprings(const MuscleSettings& muscle, const SpringParameters& parameters) {
  ASSERT_FALSE(muscle.springs.empty());
  const btScalar kappa = parameters.kappa;
  double network = 0, lengths = 0;
  for (size_t s = 0; s < muscle.springs.size(); ++s) {
    const Spring& spring = muscle.springs[s];
    ASSERT_LT(spring.a, spring.b);
    ASSERT_LT(spring.b, muscle.particleCount());
    if (s > 0) {
      const Spring& previous = muscle.springs[s - 1];
      ASSERT_TRUE(previous.a < spring.a || (previous.a == spring.a && previous.b < spring.b))
          << "springs not strictly sorted at " << s;
    }
    const btScalar distance =
        (muscle.restPositions[spring.a] - muscle.restPositions[spring.b]).length();
    EXPECT_NEAR(spring.restLength, distance, 1e-7);
    if (parameters.stiffness == SpringStiffness::Length) {
      EXPECT_NEAR(spring.stiffness * spring.restLength, kappa, kappa * 1e-5);
    }
    EXPECT_GT(spring.stiffness, 0);
    network += double(spring.stiffness) * spring.restLength * spring.restLength;
    lengths += spring.restLength;
  }
  EXPECT_NEAR(network, kappa * lengths, kappa * lengths * 1e-4);
}

PreparedScene prepareOne(const MuscleInput& muscle, std::vector<BoneInput> bones = {},
                         uint32_t seed = 1) {
  return prepareScene(bones, {muscle}, seed);
}

TEST(FibreSampling, EqualStepsAfterAJitteredSecondParticle) {
  const MuscleInput input = gridMuscle("m", 0, 0.1f, 0, 0.01f, 2, 3, 11);
  const PreparedScene scene = prepareOne(input);
  const MuscleSettings& muscle = *scene.muscles[0];
  ASSERT_EQ(muscle.particleCount(), 2u * 3u * 11u);
  ASSERT_EQ(muscle.fibreCount(), 6u);
  const btScalar step = 0.1f / 10;
  for (size_t f = 0; f < muscle.fibreCount(); ++f) {
    ASSERT_EQ(muscle.fibreOffsets[f + 1] - muscle.fibreOffsets[f], 11u);
    const auto fibre = input.fibres.fibre(f);
    auto particle = [&](int k) {
      return muscle.restPositions[muscle.fibreParticles[muscle.fibreOffsets[f] + k]];
    };
    EXPECT_LT((particle(0) - fibre.front()).length(), 1e-7);
    const btScalar jitter = (particle(1) - particle(0)).length();
    EXPECT_GT(jitter, 0);
    EXPECT_LT(jitter, step);
    for (int k = 2; k < 11; ++k) {
      EXPECT_NEAR((particle(k) - particle(k - 1)).length(), step, 1e-6);
      // On the straight fibre, in order and on the line.
      EXPECT_GT(particle(k).x(), particle(k - 1).x());
      EXPECT_NEAR(particle(k).y(), fibre.front().y(), 1e-7);
    }
    // The last particle lies ΔL − δ before the fibre end.
    EXPECT_NEAR(fibre.back().x() - particle(10).x(), step - jitter, 1e-6);
  }
}

TEST(FibreSampling, SameSeedSameResultOtherSeedOtherJitter) {
  const MuscleInput input = gridMuscle("m", 0, 0.1f, 0, 0.01f, 2, 2, 8);
  const PreparedScene a = prepareOne(input, {}, 5), b = prepareOne(input, {}, 5),
                      c = prepareOne(input, {}, 6);
  EXPECT_EQ(a.muscles[0]->restPositions, b.muscles[0]->restPositions);
  EXPECT_EQ(a.muscles[0]->radii, b.muscles[0]->radii);
  ASSERT_EQ(a.muscles[0]->springs.size(), b.muscles[0]->springs.size());
  for (size_t s = 0; s < a.muscles[0]->springs.size(); ++s) {
    EXPECT_EQ(a.muscles[0]->springs[s].a, b.muscles[0]->springs[s].a);
    EXPECT_EQ(a.muscles[0]->springs[s].b, b.muscles[0]->springs[s].b);
  }
  EXPECT_NE(a.muscles[0]->restPositions, c.muscles[0]->restPositions);
  // Fibres within one muscle get their own jitter.
  const auto& p = a.muscles[0]->restPositions;
  EXPECT_NE(p[1].x(), p[8 + 1].x());
}

TEST(FibreSampling, RejectsUnusableFibres) {
  MuscleInput input = gridMuscle("calf", 0, 0.1f, 0, 0.01f, 1, 2, 1);
  EXPECT_THROW(prepareOne(input), InputError);  // resolution 1
  input.parameters.resolution = 5;
  const std::vector<btVector3> point = {{0.05f, 0, 0}};
  input.fibres.addFibre(point);
  input.fibreGridColumns = 0;
  try {
    prepareOne(input);
    FAIL() << "expected InputError";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("calf"), std::string::npos) << error.what();
    EXPECT_NE(error.where().find("fibre 2"), std::string::npos) << error.what();
  }
}

TEST(Preparation, RejectsBrokenMeshesAndFibres) {
  MuscleInput input = gridMuscle("thigh", 0, 0.1f, 0, 0.01f, 1, 2, 5);
  input.surface.triangles.push_back({0, 1, 99});
  EXPECT_THROW(prepareOne(input), InputError);
  input = gridMuscle("thigh", 0, 0.1f, 0, 0.01f, 1, 2, 5);
  input.fibres.points[1].setX(std::numeric_limits<btScalar>::quiet_NaN());
  EXPECT_THROW(prepareOne(input), InputError);
  input = gridMuscle("thigh", 0, 0.1f, 0, 0.01f, 1, 2, 5);
  input.surface.triangles.clear();
  EXPECT_THROW(prepareOne(input), InputError);
  BoneInput bone = boxBone("femur", {-1, -1, -1}, {-0.5f, -0.5f, -0.5f});
  bone.mesh.vertices[3].setY(std::numeric_limits<btScalar>::infinity());
  try {
    prepareOne(gridMuscle("thigh", 0, 0.1f, 0, 0.01f, 1, 2, 5), {bone});
    FAIL() << "expected InputError";
  } catch (const InputError& error) {
    EXPECT_NE(error.source().find("femur"), std::string::npos) << error.what();
    EXPECT_NE(error.where().find("vertex 3"), std::string::npos) << error.what();
  }
}

TEST(Springs, LatticeCountsMatchTheGrid) {
  const int rows = 3, columns = 4, samples = 5;
  MuscleInput input = gridMuscle("m", 0, 0.1f, 0, 0.01f, rows, columns, samples);
  input.parameters.springs.layout = SpringLayout::Lattice6;
  const PreparedScene six = prepareOne(input);
  const size_t expected6 = size_t(rows - 1) * columns * samples +
                           size_t(rows) * (columns - 1) * samples +
                           size_t(rows) * columns * (samples - 1);
  EXPECT_EQ(six.muscles[0]->springs.size(), expected6);
  expectWellFormedSprings(*six.muscles[0], input.parameters.springs);

  input.parameters.springs.layout = SpringLayout::Lattice26;
  const PreparedScene all = prepareOne(input);
  // Ordered pairs within Chebyshev distance 1 per axis: 3n − 2; drop self pairs, halve.
  const size_t cells = size_t(rows) * columns * samples;
  const size_t expected26 =
      (size_t(3 * rows - 2) * (3 * columns - 2) * (3 * samples - 2) - cells) / 2;
  EXPECT_EQ(all.muscles[0]->springs.size(), expected26);
  expectWellFormedSprings(*all.muscles[0], input.parameters.springs);
  // Lattice6 neighbours are one step apart in exactly one grid direction (grid index: fibre ·
  // samples + place along it; preparation renumbers the particles).
  const MuscleSettings& lattice = *six.muscles[0];
  std::vector<uint32_t> grid(lattice.particleCount());
  for (uint32_t f = 0; f < lattice.fibreCount(); ++f)
    for (uint32_t k = lattice.fibreOffsets[f]; k < lattice.fibreOffsets[f + 1]; ++k)
      grid[lattice.fibreParticles[k]] = f * samples + (k - lattice.fibreOffsets[f]);
  for (const Spring& s : lattice.springs) {
    const uint32_t fa = grid[s.a] / samples, fb = grid[s.b] / samples, ka = grid[s.a] % samples,
                   kb = grid[s.b] % samples;
    const int dr = std::abs(int(fa / columns) - int(fb / columns));
    const int dc = std::abs(int(fa % columns) - int(fb % columns));
    const int dk = std::abs(int(ka) - int(kb));
    EXPECT_EQ(dr + dc + dk, 1);
  }
}

TEST(Springs, LatticeNeedsAGrid) {
  MuscleInput input = gridMuscle("m", 0, 0.1f, 0, 0.01f, 2, 3, 4);
  input.parameters.springs.layout = SpringLayout::Lattice26;
  input.fibreGridColumns = 0;
  EXPECT_THROW(prepareOne(input), InputError);
  input.fibreGridColumns = 4;  // 6 fibres do not fill rows of 4
  EXPECT_THROW(prepareOne(input), InputError);
}

TEST(Springs, NearestNeighboursOnALine) {
  const int n = 12;
  MuscleInput input = gridMuscle("line", 0, 0.1f, 0, 0.005f, 1, 1, n);
  input.parameters.springs.neighbours = 2;
  const PreparedScene two = prepareOne(input);
  // Spacing δ, ΔL, ΔL, ...: the chain, plus (0, 2) and (n−3, n−1) from the ends' 2 nearest.
  std::set<std::pair<uint32_t, uint32_t>> expected;
  for (uint32_t i = 0; i + 1 < n; ++i) expected.emplace(i, i + 1);
  expected.emplace(0, 2);
  expected.emplace(n - 3, n - 1);
  std::set<std::pair<uint32_t, uint32_t>> actual;
  for (const Spring& s : two.muscles[0]->springs) actual.emplace(s.a, s.b);
  EXPECT_EQ(actual, expected);
  expectWellFormedSprings(*two.muscles[0], input.parameters.springs);

  input.parameters.springs.neighbours = 1;
  const PreparedScene one = prepareOne(input);
  std::set<std::pair<uint32_t, uint32_t>> pairs;
  for (const Spring& s : one.muscles[0]->springs) {
    EXPECT_EQ(s.b, s.a + 1);  // a nearest neighbour on a line is an adjacent particle
    pairs.emplace(s.a, s.b);
  }
  EXPECT_TRUE(pairs.count({0, 1}));
  EXPECT_TRUE(pairs.count({n - 2, n - 1}));
  EXPECT_GE(pairs.size(), size_t(n) / 2);  // each spring serves at most two particles
}

TEST(Springs, NearestNeighboursNeedsFewerNeighboursThanParticles) {
  MuscleInput input = gridMuscle("small", 0, 0.1f, 0, 0.01f, 1, 2, 4);
  input.parameters.springs.neighbours = 8;  // 8 particles
  try {
    prepareOne(input);
    FAIL() << "expected InputError";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("small"), std::string::npos);
  }
  input.parameters.springs.neighbours = 7;
  const PreparedScene scene = prepareOne(input);
  EXPECT_EQ(scene.muscles[0]->springs.size(), 8u * 7u / 2u);  // every pair
}

TEST(Springs, NearestNeighbourUnionContainsEveryParticlesNearest) {
  const MuscleInput input = gridMuscle("m", 0, 0.1f, 0, 0.01f, 3, 3, 8);
  const PreparedScene scene = prepareOne(input);
  const MuscleSettings& muscle = *scene.muscles[0];
  expectWellFormedSprings(muscle, input.parameters.springs);
  std::set<std::pair<uint32_t, uint32_t>> pairs;
  for (const Spring& s : muscle.springs) pairs.emplace(s.a, s.b);
  std::vector<int> degree(muscle.particleCount(), 0);
  for (const Spring& s : muscle.springs) ++degree[s.a], ++degree[s.b];
  const int n = input.parameters.springs.neighbours;
  for (uint32_t i = 0; i < muscle.particleCount(); ++i) {
    EXPECT_GE(degree[i], n);  // its own N nearest at least
    // Brute force: the strictly nearest other particle is linked.
    btScalar best = 1e9f;
    uint32_t nearest = i;
    for (uint32_t j = 0; j < muscle.particleCount(); ++j)
      if (j != i && (muscle.restPositions[j] - muscle.restPositions[i]).length() < best) {
        best = (muscle.restPositions[j] - muscle.restPositions[i]).length();
        nearest = j;
      }
    EXPECT_TRUE(pairs.count({std::min(i, nearest), std::max(i, nearest)})) << i;
  }
}

TEST(Springs, DelaunayOfCubeCornersAndCentre) {
  // Tetrahedra: the centre with each of the 12 hull triangles. Edges: 8 to the centre, 12
  // cube edges and one diagonal per face.
  MuscleInput input;
  input.name = "cube";
  input.parameters.springs.layout = SpringLayout::Delaunay;
  std::vector<btVector3> points;
  for (int i = 0; i < 8; ++i)
    points.emplace_back(i & 1 ? 1.f : 0.f, i & 2 ? 1.f : 0.f, i & 4 ? 1.f : 0.f);
  points.emplace_back(0.5f, 0.5f, 0.5f);
  const detail::KdTree tree(points);
  const std::vector<Spring> springs = detail::buildSprings(input, points, tree);
  EXPECT_EQ(springs.size(), 8u + 12u + 6u);
  int toCentre = 0, cubeEdges = 0, faceDiagonals = 0;
  for (const Spring& s : springs) {
    EXPECT_LT(s.a, s.b);
    if (s.b == 8) {
      ++toCentre;
      continue;
    }
    const int differing = __builtin_popcount(s.a ^ s.b);
    cubeEdges += differing == 1;
    faceDiagonals += differing == 2;
    EXPECT_NE(differing, 3) << "a space diagonal crosses the centre's tetrahedra";
  }
  EXPECT_EQ(toCentre, 8);
  EXPECT_EQ(cubeEdges, 12);
  EXPECT_EQ(faceDiagonals, 6);
}

TEST(Springs, DelaunayContainsTheNearestNeighbourGraph) {
  MuscleInput input = gridMuscle("m", 0, 0.1f, 0, 0.01f, 3, 4, 9);
  input.parameters.springs.layout = SpringLayout::Delaunay;
  const PreparedScene scene = prepareOne(input);
  const MuscleSettings& muscle = *scene.muscles[0];
  expectWellFormedSprings(muscle, input.parameters.springs);
  std::set<std::pair<uint32_t, uint32_t>> pairs;
  for (const Spring& s : muscle.springs) pairs.emplace(s.a, s.b);
  for (uint32_t i = 0; i < muscle.particleCount(); ++i) {
    btScalar best = 1e9f, second = 1e9f;
    uint32_t nearest = i;
    for (uint32_t j = 0; j < muscle.particleCount(); ++j) {
      const btScalar d = (muscle.restPositions[j] - muscle.restPositions[i]).length();
      if (j == i) continue;
      if (d < best) {
        second = best;
        best = d;
        nearest = j;
      } else if (d < second) {
        second = d;
      }
    }
    if (second - best < 1e-6f) continue;  // a tie: either may be the Delaunay edge
    EXPECT_TRUE(pairs.count({std::min(i, nearest), std::max(i, nearest)})) << i;
  }
}

TEST(Springs, DelaunayRejectsCoplanarParticles) {
  MuscleInput input;
  input.name = "flat";
  input.parameters.springs.layout = SpringLayout::Delaunay;
  std::vector<btVector3> points;
  for (int i = 0; i < 9; ++i) points.emplace_back(i % 3, i / 3, 0);
  const detail::KdTree tree(points);
  EXPECT_THROW(detail::buildSprings(input, points, tree), InputError);
}

TEST(Springs, CoincidentParticlesAreAnError) {
  // Lattice layouts keep every sampled particle (their springs follow the grid's indices), so
  // a fibre repeated next to itself makes a zero-length spring.
  MuscleInput input = gridMuscle("twin", 0, 0.1f, 0, 0.01f, 1, 2, 6);
  FibreSet fibres;
  fibres.addFibre(input.fibres.fibre(0));
  fibres.addFibre(input.fibres.fibre(0));  // fibre 1 starts where fibre 0 starts
  fibres.addFibre(input.fibres.fibre(1));
  input.fibres = fibres;
  input.fibreGridColumns = 3;
  input.parameters.springs.layout = SpringLayout::Lattice6;
  try {
    prepareOne(input);
    FAIL() << "expected InputError";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("twin"), std::string::npos);
    EXPECT_NE(error.where().find("particles 0 and 6"), std::string::npos) << error.what();
  }
}

/// A muscle's particles and fibres given directly (no sampling).
MuscleSettings particlesOnFibres(const std::vector<std::vector<btVector3>>& fibres) {
  MuscleSettings muscle;
  for (const auto& fibre : fibres) {
    for (const btVector3& p : fibre) {
      muscle.fibreParticles.push_back(static_cast<uint32_t>(muscle.restPositions.size()));
      muscle.restPositions.push_back(p);
    }
    muscle.fibreOffsets.push_back(static_cast<uint32_t>(muscle.fibreParticles.size()));
  }
  return muscle;
}

TEST(MergeParticles, ParticlesOfOtherFibresCloserThanTheDistanceMerge) {
  MuscleSettings muscle = particlesOnFibres(
      {{{0, 0, 0}, {1, 0, 0}, {2, 0, 0}},             // A: kept
       {{0, 0.1f, 0}, {1, 1, 0}, {2, 0.05f, 0}},      // B: its ends merge into A's (0.1, 0.05)
       {{0, 0, 0.3f}, {1, 0, 1}, {2, 0, 1}},          // C: 0.3 from A's start, kept
       {{5, 0, 0}, {5.01f, 0, 0}, {6, 0, 0}},         // D: 0.01 apart on one fibre, kept
       {{9, 0, 0}},                                   // E: one particle
       {{9, 0.05f, 0}, {9, -0.05f, 0}, {9, 2, 0}}});  // F: both first particles merge into E's
  // Steps after the second particle: A 1, B 1.38, C 1, D 0.99, F 2.05 (E has none).
  EXPECT_NEAR(detail::medianSampleSpacing(muscle), 1.0, 1e-6);
  ASSERT_EQ(detail::mergeCloseParticles(muscle, 0.25f), 4u);
  ASSERT_EQ(muscle.particleCount(), 16u - 4u);
  const std::vector<uint32_t> offsets = {0, 3, 6, 9, 12, 13, 15};
  EXPECT_EQ(muscle.fibreOffsets, offsets);
  // Kept particles keep their order: A 0-2, B's middle 3, C 4-6, D 7-9, E 10, F's last 11.
  const std::vector<uint32_t> particles = {0, 1, 2, 0, 3, 2, 4, 5, 6, 7, 8, 9, 10, 10, 11};
  EXPECT_EQ(muscle.fibreParticles, particles);
  EXPECT_EQ(muscle.restPositions[3], btVector3(1, 1, 0));
  EXPECT_EQ(muscle.restPositions[10], btVector3(9, 0, 0));
  // Particles of different fibres are now at least the distance apart.
  for (size_t f = 0; f + 1 < muscle.fibreCount(); ++f)
    for (size_t g = f + 1; g < muscle.fibreCount(); ++g)
      for (uint32_t i = muscle.fibreOffsets[f]; i < muscle.fibreOffsets[f + 1]; ++i)
        for (uint32_t j = muscle.fibreOffsets[g]; j < muscle.fibreOffsets[g + 1]; ++j) {
          const uint32_t a = muscle.fibreParticles[i], b = muscle.fibreParticles[j];
          if (a != b) {
            EXPECT_GE(muscle.restPositions[a].distance(muscle.restPositions[b]), 0.25f);
          }
        }
  EXPECT_EQ(detail::mergeCloseParticles(muscle, 0.25f), 0u);  // nothing left to merge
}

TEST(MergeParticles, ConvergingFibresMergeAndNoSpringIsShorterThanTheDistance) {
  // 16 fibres from a 2 cm square converge to one point 10 cm away (a tendon).
  MuscleInput input;
  input.name = "fan";
  input.surface = boxMesh({-0.011f, -0.011f, -0.001f}, {0.011f, 0.011f, 0.101f});
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) {
      const std::vector<btVector3> line = {{-0.009f + 0.006f * c, -0.009f + 0.006f * r, 0},
                                           {0, 0, 0.1f}};
      input.fibres.addFibre(line);
    }
  input.parameters.resolution = 21;
  EXPECT_EQ(prepareOne(input).report.muscles[0].mergedParticles, 0u);  // only when asked
  input.mergeConverging = true;
  const PreparedScene scene = prepareOne(input);
  ASSERT_EQ(scene.report.muscles.size(), 1u);
  const MusclePreparationReport& report = scene.report.muscles[0];
  const MuscleSettings& muscle = *scene.muscles[0];
  EXPECT_EQ(report.sampledParticles, 16u * 21u);
  EXPECT_GT(report.mergedParticles, 0u);
  EXPECT_EQ(muscle.particleCount(), report.sampledParticles - report.mergedParticles);
  // The step is about 5 mm (10 cm / 20); a quarter of it is the merge distance.
  EXPECT_NEAR(report.mergeDistance, 0.25 * 0.1 / 20, 0.25 * 0.1 / 20 * 0.05);
  expectWellFormedSprings(muscle, input.parameters.springs);
  btScalar shortest = 1;
  for (const Spring& spring : muscle.springs) shortest = std::min(shortest, spring.restLength);
  EXPECT_EQ(report.shortestSpring, shortest);
  // Along one fibre the jittered second particle may be closer; across fibres nothing is.
  for (const Spring& spring : muscle.springs) {
    if (spring.restLength < report.mergeDistance) {
      EXPECT_TRUE(testing::shareAFibre(muscle, spring.a, spring.b))
          << spring.a << "-" << spring.b << " " << spring.restLength;
    }
  }
  bool reported = false;
  for (const auto& repair : scene.report.repairs)
    reported |= repair.find("fan") != std::string::npos &&
                repair.find(std::to_string(report.mergedParticles) + " of 336 particles merged") !=
                    std::string::npos;
  EXPECT_TRUE(reported);
}

TEST(PushOut, PointsDeeperThanTheMinimumLeaveAlongTheNormal) {
  const MeshDistance box(boxMesh({0, 0, 0}, {1, 1, 1}));
  std::vector<btVector3> points = {{0.5f, 0.5f, 0.9f},    // 0.1 below the top face: moves up
                                   {0.5f, 0.5f, 0.96f},   // 0.04 deep: shallower than 0.05
                                   {0.5f, 0.5f, 1.5f},    // outside
                                   {0.08f, 0.5f, 0.3f}};  // 0.08 from the face x = 0: moves
  const std::vector<btVector3> before = points;
  const detail::PushedOut moved = detail::pushOutOf(points, box, 0.05f, 0.01f);
  EXPECT_EQ(moved.count, 2u);
  EXPECT_NEAR(moved.deepest, 0.1f, 1e-5f);
  EXPECT_LT(points[0].distance(btVector3(0.5f, 0.5f, 1.01f)), 1e-5f);
  EXPECT_EQ(points[1], btVector3(0.5f, 0.5f, 0.96f));
  EXPECT_EQ(points[2], btVector3(0.5f, 0.5f, 1.5f));
  EXPECT_LT(points[3].distance(btVector3(-0.01f, 0.5f, 0.3f)), 1e-5f);
  // A shallow point may stay only when the caller lets it: here none may.
  points = before;
  const auto none = [](const btVector3&) { return false; };
  EXPECT_EQ(detail::pushOutOf(points, box, 0.05f, 0.01f, none).count, 3u);
  EXPECT_LT(points[1].distance(btVector3(0.5f, 0.5f, 1.01f)), 1e-5f);
}

TEST(Preparation, MassAndDamping) {
  MuscleInput input = gridMuscle("m", 0, 0.1f, 0, 0.01f, 2, 2, 10);
  input.parameters.springs.density = 1000;
  const PreparedScene scene = prepareOne(input);
  const MuscleSettings& muscle = *scene.muscles[0];
  const double volume = 0.1 * 0.02 * 0.02;
  EXPECT_NEAR(muscle.particleMass, 1000 * volume / 40, 1e-9);
  double meanK = 0;
  for (const Spring& s : muscle.springs) meanK += s.stiffness;
  meanK /= muscle.springs.size();
  // Zeleny's estimate times the damping scale (SpringParameters::dampingScale).
  EXPECT_NEAR(muscle.damping,
              input.parameters.springs.dampingScale * std::sqrt(8 * meanK * muscle.particleMass),
              1e-4 * muscle.damping);
  input.parameters.springs.damping = 0.25f;
  EXPECT_FLOAT_EQ(prepareOne(input).muscles[0]->damping, 0.25f);
}

TEST(Preparation, FixedParticlesAreThoseWithinTheAttachmentDistance) {
  // Fibres run from one bone to the other; a third bone sits beside the muscle.
  MuscleInput input = gridMuscle("m", 0, 0.1f, 0, 0.01f, 3, 3, 25);
  input.parameters.attachmentDistance = 0.006f;
  const std::vector<BoneInput> bones = endBonesAnd({sphereBone("side", {0.05f, 0.03f, 0}, 0.02f)});
  const PreparedScene scene = prepareScene(bones, {input}, 3);
  const MuscleSettings& muscle = *scene.muscles[0];
  size_t fixed = 0, checked = 0;
  std::vector<size_t> perBone(3, 0);
  for (uint32_t i = 0; i < muscle.particleCount(); ++i) {
    btScalar best = 1e9f;
    int nearest = -1;
    for (size_t b = 0; b < bones.size(); ++b) {
      const btScalar d = bruteDistance(bones[b].mesh, muscle.restPositions[i]);
      if (d < best) best = d, nearest = int(b);
    }
    if (std::abs(best - input.parameters.attachmentDistance) < 1e-6f) continue;  // a tie
    ++checked;
    EXPECT_EQ(muscle.nearestBone[i], nearest) << i;
    const bool shouldFix = best < input.parameters.attachmentDistance;
    EXPECT_EQ(muscle.isFixed(i), shouldFix) << i << " at " << best;
    EXPECT_EQ(muscle.fixedBone[i], shouldFix ? nearest : -1) << i;
    if (shouldFix) ++fixed, ++perBone[nearest];
  }
  EXPECT_GT(checked, muscle.particleCount() * 9 / 10);
  EXPECT_EQ(muscle.fixedParticles.size(), fixed);
  EXPECT_TRUE(std::is_sorted(muscle.fixedParticles.begin(), muscle.fixedParticles.end()));
  for (size_t f = 0; f < muscle.fibreCount(); ++f)  // every fibre starts on the left bone
    EXPECT_EQ(muscle.fixedBone[muscle.fibreParticles[muscle.fibreOffsets[f]]], 0);
  EXPECT_GE(perBone[0], 9u);
  EXPECT_GT(perBone[2], 0u);  // the side bone catches particles of the nearest column
}

/// The number that starts the warning containing `text` after "muscle 'name': " (0 if none).
size_t warnedCount(const PreparedScene& scene, const std::string& text) {
  for (const auto& warning : scene.report.warnings)
    if (warning.find(text) != std::string::npos)
      return std::stoul(warning.substr(warning.find("': ") + 3));
  return 0;
}

TEST(Preparation, ReportsFibreEndsLeftLoose) {
  // At resolution 5 the last particle lies ΔL − δ before the end, often beyond the
  // attachment distance of the end bone.
  const MuscleInput input = gridMuscle("m", 0, 0.1f, 0, 0.01f, 3, 3, 5);
  const std::vector<BoneInput> bones = endBones();
  size_t total = 0;
  for (uint32_t seed = 1; seed <= 4; ++seed) {
    const PreparedScene scene = prepareScene(bones, {input}, seed);
    const MuscleSettings& muscle = *scene.muscles[0];
    size_t loose = 0;
    for (size_t f = 0; f < muscle.fibreCount(); ++f)
      loose += !muscle.isFixed(muscle.fibreParticles[muscle.fibreOffsets[f + 1] - 1]);
    EXPECT_EQ(scene.report.muscles[0].looseFibreEnds, loose) << "seed " << seed;
    total += loose;
  }
  EXPECT_GT(total, 0u);  // (ΔL − δ) > 4 mm for 84 % of fibres: some are loose
}

TEST(Preparation, FreeParticlesInsideABoneArePushedOutAndFixed) {
  const MuscleInput input = gridMuscle("m", 0, 0.1f, 0, 0.01f, 3, 3, 20);
  const BoneInput bone = sphereBone("cyst", {0.05f, 0, 0}, 0.009f);
  const MeshDistance distance(bone.mesh);
  // Without the bone the particles are the sampled ones (straight fibres: nothing merges).
  const PreparedScene alone = prepareOne(input);
  ASSERT_EQ(alone.report.muscles[0].mergedParticles, 0u);
  size_t deep = 0;
  for (const btVector3& p : alone.muscles[0]->restPositions)
    deep += distance.signedDistance(p) < -input.parameters.attachmentDistance;
  ASSERT_GT(deep, 0u);

  const PreparedScene scene = prepareScene({bone}, {input}, 1);
  const MusclePreparationReport& report = scene.report.muscles[0];
  const btScalar margin = detail::medianSampleSpacing(*alone.muscles[0]) / 4;
  ASSERT_EQ(report.pushedOutOfBones.size(), 1u);
  EXPECT_EQ(report.pushedOutOfBones[0], deep);
  const MuscleSettings& muscle = *scene.muscles[0];
  size_t freeInside = 0, justOutside = 0;
  for (uint32_t i = 0; i < muscle.particleCount(); ++i) {
    const btScalar d = distance.signedDistance(muscle.restPositions[i]);
    freeInside += !muscle.isFixed(i) && d < 0;
    justOutside += d > 0 && d <= margin + 1e-6f && muscle.isFixed(i);
  }
  EXPECT_EQ(freeInside, 0u);
  EXPECT_GE(justOutside, deep);  // moved to a quarter spacing outside
  EXPECT_EQ(warnedCount(scene, "particles lie inside bone 'cyst'"), 0u);
  bool reported = false;
  for (const auto& repair : scene.report.repairs)
    reported |= repair.find(std::to_string(deep) + " free particles inside bone 'cyst'") !=
                std::string::npos;
  EXPECT_TRUE(reported);
}

TEST(Preparation, FreeParticlesInsideTheBoneOfADeclaredAreaButOutsideItArePushedOut) {
  // The cyst is the bone of the origin area, but the area lies at the muscle's other end, far
  // from it (the box's corners at x = 0; the cyst is nearer those at x = 0.1): particles inside
  // the cyst are not in the area, so nothing may keep them inside, however shallow.
  MuscleInput input = gridMuscle("m", 0, 0.1f, 0, 0.01f, 3, 3, 20);
  const BoneInput cyst = sphereBone("cyst", {0.075f, 0, 0}, 0.009f);
  DeclaredAttachment origin{"origin", {}, {0}};
  for (uint32_t v = 0; v < input.surface.vertices.size(); ++v)
    if (input.surface.vertices[v].x() < 0.001f) origin.surfaceVertices.push_back(v);
  ASSERT_FALSE(origin.surfaceVertices.empty());
  const MeshDistance distance(cyst.mesh);
  const PreparedScene alone = prepareOne(input);
  input.attachments = {origin};
  size_t inside = 0, shallow = 0;  // shallow: within the attachment distance of its surface
  for (const btVector3& p : alone.muscles[0]->restPositions) {
    const btScalar d = distance.signedDistance(p);
    inside += d < 0;
    shallow += d < 0 && d >= -input.parameters.attachmentDistance;
  }
  ASSERT_GT(shallow, 0u);
  ASSERT_GT(inside, shallow);

  const PreparedScene scene = prepareScene({cyst}, {input}, 1);
  const MuscleSettings& muscle = *scene.muscles[0];
  size_t freeInside = 0;
  for (uint32_t i = 0; i < muscle.particleCount(); ++i)
    freeInside += !muscle.isFixed(i) && distance.signedDistance(muscle.restPositions[i]) < 0;
  EXPECT_EQ(freeInside, 0u);
  EXPECT_EQ(scene.report.muscles[0].pushedOutOfBones[0], inside);
  EXPECT_GT(scene.report.muscles[0].pushedOutOfBonesDepth[0], 0.004f);  // deeper than fixing
  EXPECT_EQ(warnedCount(scene, "particles lie inside bone 'cyst'"), 0u);
}

/// Arc length of each particle of fibre f from its first particle [m].
std::vector<btScalar> arcAlong(const MuscleSettings& muscle, size_t f) {
  std::vector<btScalar> arc{0};
  for (uint32_t k = muscle.fibreOffsets[f] + 1; k < muscle.fibreOffsets[f + 1]; ++k)
    arc.push_back(arc.back() + muscle.restPositions[muscle.fibreParticles[k]].distance(
                                   muscle.restPositions[muscle.fibreParticles[k - 1]]));
  return arc;
}

TEST(Preparation, TendonsAreTheFreeParticlesWithinTheirFractionBeyondTheAttachments) {
  MuscleInput input = gridMuscle("m", 0, 0.1f, 0, 0.01f, 3, 3, 43);
  const PreparedScene plain = prepareScene(endBones(), {input}, 1);
  input.parameters.tendonFraction = 0.1f;
  input.parameters.tendonStiffness = 20;
  const PreparedScene scene = prepareScene(endBones(), {input}, 1);
  const MuscleSettings& muscle = *scene.muscles[0];
  size_t tendon = 0;
  for (size_t f = 0; f < muscle.fibreCount(); ++f) {
    const std::vector<btScalar> arc = arcAlong(muscle, f);
    // The fibre's attached runs at its two ends, then 10 % of its length beyond each.
    size_t first = 0, last = arc.size() - 1;
    const uint32_t* p = muscle.fibreParticles.data() + muscle.fibreOffsets[f];
    while (muscle.isFixed(p[first])) ++first;
    while (muscle.isFixed(p[last])) --last;
    ASSERT_GT(first, 0u);
    ASSERT_LT(last, arc.size() - 1);
    const btScalar length = 0.1f * arc.back();
    for (size_t k = first; k <= last; ++k) {
      const bool expected = arc[k] - arc[first - 1] <= length || arc[last + 1] - arc[k] <= length;
      EXPECT_EQ(muscle.isTendon(p[k]), expected) << "fibre " << f << " particle " << k;
      tendon += expected;
    }
  }
  EXPECT_EQ(scene.report.muscles[0].tendonParticles, tendon);
  EXPECT_GT(tendon, 0u);
  // Springs between tendon or fixed particles are 20 times as stiff; the others unchanged.
  ASSERT_EQ(muscle.springs.size(), plain.muscles[0]->springs.size());
  size_t stiffened = 0;
  for (size_t s = 0; s < muscle.springs.size(); ++s) {
    const Spring& spring = muscle.springs[s];
    const bool inTendon = (muscle.isTendon(spring.a) || muscle.isFixed(spring.a)) &&
                          (muscle.isTendon(spring.b) || muscle.isFixed(spring.b));
    EXPECT_NEAR(spring.stiffness, plain.muscles[0]->springs[s].stiffness * (inTendon ? 20 : 1),
                1e-4f * spring.stiffness);
    stiffened += inTendon;
  }
  EXPECT_EQ(scene.report.muscles[0].tendonSprings, stiffened);
}

TEST(Preparation, BoundaryParticlesAndRadiiFromSurfaceVertices) {
  const MuscleInput input = tubeMuscle("tube", 0, 0.12f, 0.02f, 12);
  const PreparedScene scene = prepareOne(input);
  const MuscleSettings& muscle = *scene.muscles[0];
  const auto& vertices = muscle.restSurface.vertices;
  // Brute force: every vertex chooses its closest particle.
  std::vector<double> sum(muscle.particleCount(), 0);
  std::vector<int> count(muscle.particleCount(), 0);
  for (const btVector3& v : vertices) {
    uint32_t best = 0;
    for (uint32_t i = 1; i < muscle.particleCount(); ++i)
      if ((muscle.restPositions[i] - v).length2() < (muscle.restPositions[best] - v).length2())
        best = i;
    sum[best] += (muscle.restPositions[best] - v).length();
    ++count[best];
  }
  std::vector<uint32_t> boundary;
  for (uint32_t i = 0; i < muscle.particleCount(); ++i) {
    EXPECT_EQ(muscle.isBoundary(i), count[i] > 0) << i;
    if (count[i] == 0) {
      EXPECT_EQ(muscle.radii[i], 0);
      continue;
    }
    boundary.push_back(i);
    EXPECT_NEAR(muscle.radii[i], sum[i] / count[i], 1e-6) << i;  // nothing to shrink against
  }
  EXPECT_EQ(muscle.boundaryParticles, boundary);
  // Each boundary particle covers at least its nearest vertex (the minimum distance is at most
  // the mean), so coverage >= boundary particles / vertices.
  ASSERT_EQ(scene.report.surfaceCoverage.size(), 1u);
  const double coverage = scene.report.surfaceCoverage[0];
  EXPECT_GE(coverage, double(boundary.size()) / vertices.size());
  EXPECT_LE(coverage, 1.0);
  // Brute force, with the sphere shrunk and grown a hair: vertices on a sphere are ties.
  auto coveredFraction = [&](btScalar scale) {
    size_t covered = 0;
    for (const btVector3& v : vertices)
      for (uint32_t i : boundary)
        if ((muscle.restPositions[i] - v).length() <= muscle.radii[i] * scale) {
          ++covered;
          break;
        }
    return double(covered) / vertices.size();
  };
  EXPECT_GE(coverage, coveredFraction(1 - 1e-4f));
  EXPECT_LE(coverage, coveredFraction(1 + 1e-4f));
}

TEST(Preparation, SkinningUsesTheClosestParticles) {
  MuscleInput input = tubeMuscle("tube", 0, 0.12f, 0.02f, 10);
  input.parameters.skinNeighbours = 4;
  const PreparedScene scene = prepareOne(input);
  const MuscleSettings& muscle = *scene.muscles[0];
  ASSERT_EQ(muscle.skinNeighbours, 4);
  const auto& vertices = muscle.restSurface.vertices;
  ASSERT_EQ(muscle.skinParticles.size(), vertices.size() * 4);
  ASSERT_EQ(muscle.skinWeights.size(), vertices.size() * 4);
  for (size_t v = 0; v < vertices.size(); ++v) {
    std::vector<btScalar> distances;
    for (const btVector3& p : muscle.restPositions) distances.push_back((p - vertices[v]).length());
    std::vector<btScalar> sorted = distances;
    std::sort(sorted.begin(), sorted.end());
    double weightSum = 0;
    for (int j = 0; j < 4; ++j) {
      const uint32_t particle = muscle.skinParticles[v * 4 + j];
      EXPECT_LE(distances[particle], sorted[3] + 1e-7f);
      EXPECT_GT(muscle.skinWeights[v * 4 + j], 0);
      weightSum += muscle.skinWeights[v * 4 + j];
      if (j > 0) {  // nearer particles weigh more
        EXPECT_LE(muscle.skinWeights[v * 4 + j], muscle.skinWeights[v * 4 + j - 1] + 1e-6f);
      }
    }
    EXPECT_NEAR(weightSum, 1.0, 1e-5);
  }
}

/// Every pair of spheres from different bodies is apart (fixed particles excepted against
/// their own bone).
void expectNoInterBodyOverlap(const PreparedScene& scene) {
  for (size_t m = 0; m < scene.muscles.size(); ++m) {
    const MuscleSettings& a = *scene.muscles[m];
    for (uint32_t i : a.boundaryParticles) {
      const btVector3& p = a.restPositions[i];
      for (size_t n = m + 1; n < scene.muscles.size(); ++n) {
        const MuscleSettings& b = *scene.muscles[n];
        for (uint32_t j : b.boundaryParticles)
          ASSERT_GE((p - b.restPositions[j]).length(), a.radii[i] + b.radii[j])
              << a.name << " " << i << " vs " << b.name << " " << j;
      }
      for (size_t bone = 0; bone < scene.bones.size(); ++bone) {
        if (a.fixedBone[i] == int32_t(bone)) continue;
        const BoneSettings& settings = *scene.bones[bone];
        for (size_t s = 0; s < settings.sphereCentres.size(); ++s)
          ASSERT_GE((p - settings.sphereCentres[s]).length(), a.radii[i] + settings.sphereRadii[s])
              << a.name << " " << i << " vs bone " << settings.name << " sphere " << s;
      }
    }
  }
}

TEST(Preparation, RestPoseHasNoOverlapBetweenBodies) {
  // Two tubes side by side closer than their spheres reach, a bone at one end of both and a
  // round bone pressed against them.
  std::vector<MuscleInput> muscles = {tubeMuscle("a", 0, 0.12f, 0.02f, 12),
                                      tubeMuscle("b", 0, 0.12f, 0.02f, 12)};
  for (auto& v : muscles[1].surface.vertices) v += btVector3(0, 0.041f, 0);
  for (auto& p : muscles[1].fibres.points) p += btVector3(0, 0.041f, 0);
  const std::vector<BoneInput> bones = {boxBone("end", {-0.03f, -0.03f, -0.03f}, {0, 0.07f, 0.03f}),
                                        sphereBone("knob", {0.06f, 0.02f, 0.035f}, 0.02f)};
  const PreparedScene scene = prepareScene(bones, muscles, 9);
  expectNoInterBodyOverlap(scene);
  size_t fixed = 0;
  for (const auto& muscle : scene.muscles) fixed += muscle->fixedParticles.size();
  EXPECT_GT(fixed, 0u);  // the exemption was exercised
  bool reported = false;
  for (const auto& repair : scene.report.repairs)
    reported |= repair.find("muscle spheres shrunk") != std::string::npos;
  EXPECT_TRUE(reported);
  for (double coverage : scene.report.surfaceCoverage) {
    EXPECT_GT(coverage, 0);
    EXPECT_LE(coverage, 1);
  }
}

/// Median over the fibres of (distance from the second to the last particle) / steps: the
/// regular sample spacing after the jittered second particle.
btScalar sampleSpacing(const MuscleSettings& muscle) {
  std::vector<btScalar> spacing;
  for (size_t f = 0; f < muscle.fibreCount(); ++f) {
    const uint32_t first = muscle.fibreOffsets[f], last = muscle.fibreOffsets[f + 1] - 1;
    spacing.push_back(muscle.restPositions[muscle.fibreParticles[last]].distance(
                          muscle.restPositions[muscle.fibreParticles[first + 1]]) /
                      btScalar(last - first - 1));
  }
  std::nth_element(spacing.begin(), spacing.begin() + spacing.size() / 2, spacing.end());
  return spacing[spacing.size() / 2];
}

TEST(Preparation, SpheresNearAnotherMuscleAreCappedAtTheSpacing) {
  // Two tubes (radius 20 mm, fibres within 15 mm of the axis, 3 mm sample spacing): boundary
  // spheres reach ~5 mm to the surface, more than the spacing. The same pair prepared 1 m
  // apart gives the radii before any shrinking (same particles: the jitter depends on the
  // seed and the muscle's index only).
  std::vector<MuscleInput> muscles = {tubeMuscle("a", 0, 0.12f, 0.02f, 41),
                                      tubeMuscle("b", 0, 0.12f, 0.02f, 41)};
  auto shiftSecond = [&](btScalar y) {
    std::vector<MuscleInput> shifted = muscles;
    for (auto& v : shifted[1].surface.vertices) v += btVector3(0, y, 0);
    for (auto& p : shifted[1].fibres.points) p += btVector3(0, y, 0);
    return shifted;
  };
  const PreparedScene apart = prepareScene({}, shiftSecond(1), 3);
  const PreparedScene close = prepareScene({}, shiftSecond(0.041f), 3);
  expectNoInterBodyOverlap(close);
  const MuscleSettings &a = *close.muscles[0], &b = *close.muscles[1];
  const MuscleSettings &a0 = *apart.muscles[0], &b0 = *apart.muscles[1];
  ASSERT_EQ(a.boundaryParticles, a0.boundaryParticles);
  // b's unshrunk radii, matched by position (its particles may be numbered differently 1 m away).
  std::vector<btScalar> bRadius(b.particleCount(), 0);
  for (uint32_t j : b.boundaryParticles) {
    const btVector3 there = b.restPositions[j] + btVector3(0, 1 - 0.041f, 0);
    uint32_t match = 0;
    for (uint32_t k = 1; k < b0.particleCount(); ++k)
      if (b0.restPositions[k].distance2(there) < b0.restPositions[match].distance2(there))
        match = k;
    ASSERT_LT(b0.restPositions[match].distance(there), 1e-5);
    bRadius[j] = b0.radii[match];
  }
  const btScalar spacing = sampleSpacing(a);
  ASSERT_GT(spacing, 0.0025f);
  ASSERT_LT(spacing, 0.0035f);
  size_t capped = 0, keptLarge = 0;
  for (uint32_t i : a.boundaryParticles) {
    // The smallest gap between i's sphere and one of b's, both at their unshrunk radii.
    btScalar gap = std::numeric_limits<btScalar>::infinity();
    for (uint32_t j : b.boundaryParticles)
      gap = std::min(gap,
                     a.restPositions[i].distance(b.restPositions[j]) - a0.radii[i] - b0.radii[j]);
    if (gap < spacing * 0.99f && a0.radii[i] > spacing) {
      EXPECT_LE(a.radii[i], spacing * 1.0001f) << i;
      ++capped;
    } else if (gap > spacing * 1.01f) {
      EXPECT_EQ(a.radii[i], a0.radii[i]) << i;  // away from b: untouched
      keptLarge += a.radii[i] > spacing;
    }
  }
  EXPECT_GT(capped, 0u);
  EXPECT_GT(keptLarge, 0u);
  bool reported = false;
  for (const auto& repair : close.report.repairs)
    reported |= repair.find("capped at the sample spacing") != std::string::npos &&
                repair.find(" 0 capped") == std::string::npos;
  EXPECT_TRUE(reported);
}

TEST(Preparation, OverlappingMusclesAreSeparatedAndSurfacesLeaveBones) {
  // Two 2 cm box muscles overlapping by 4 mm in y; a bone plate cutting 1 mm into the first.
  const MuscleInput first = gridMuscle("first", 0, 0.1f, 0, 0.01f, 3, 3, 20);
  const MuscleInput second = gridMuscle("second", 0, 0.1f, 0.016f, 0.01f, 3, 3, 20);
  const BoneInput plate = boxBone("plate", {-0.01f, -0.03f, -0.015f}, {0.11f, 0.03f, -0.009f});
  const PreparedScene scene = prepareScene({plate}, {first, second}, 1);
  const MeshDistance firstSurface(first.surface), plateDistance(plate.mesh);
  const MusclePreparationReport& report = scene.report.muscles[1];
  ASSERT_EQ(report.pushedOutOfMuscles.size(), 2u);
  EXPECT_GT(report.pushedOutOfMuscles[0], 0u);
  EXPECT_EQ(report.pushedOutOfMuscles[1], 0u);  // not out of itself
  EXPECT_TRUE(scene.report.muscles[0].pushedOutOfMuscles == std::vector<size_t>(2, 0));
  for (const btVector3& p : scene.muscles[1]->restPositions)
    EXPECT_GE(firstSurface.signedDistance(p), 0) << p.y();
  // The first muscle's surface vertices on its bottom face inside the plate move out of it.
  size_t insideBefore = 0;
  for (const btVector3& v : first.surface.vertices) insideBefore += plateDistance.inside(v);
  EXPECT_EQ(scene.report.muscles[0].surfaceVerticesPushedOut[0], insideBefore);
  for (const btVector3& v : scene.muscles[0]->restSurface.vertices)
    EXPECT_FALSE(plateDistance.inside(v));
  expectNoInterBodyOverlap(scene);
}

TEST(BoneSpheres, CentresLieInsideTheBone) {
  for (const BoneInput& bone : {sphereBone("ball", {0.1f, 0.2f, 0.3f}, 0.03f),
                                boxBone("block", {0, 0, 0}, {0.05f, 0.03f, 0.02f}),
                                // A thin plate: inward offsets by the longest edge cross it.
                                boxBone("plate", {0, 0, 0}, {0.1f, 0.1f, 0.002f})}) {
    const PreparedScene scene = prepareScene({bone}, {}, 1);
    const BoneSettings& settings = *scene.bones[0];
    ASSERT_FALSE(settings.sphereCentres.empty()) << bone.name;
    ASSERT_EQ(settings.sphereCentres.size(), settings.sphereRadii.size());
    const MeshDistance distance(bone.mesh);
    for (size_t s = 0; s < settings.sphereCentres.size(); ++s) {
      const btVector3& centre = settings.sphereCentres[s];
      EXPECT_LE(distance.signedDistance(centre), 1e-6f) << bone.name << " sphere " << s;
      EXPECT_GT(settings.sphereRadii[s], 0);
    }
    // Coarse boxes are thin: the centres pulled back are a repair, not a warning.
    bool pulledBack = false;
    for (const auto& repair : scene.report.repairs)
      pulledBack |= repair.find("pulled back") != std::string::npos;
    EXPECT_TRUE(pulledBack || bone.name == "ball") << bone.name;
    for (const auto& warning : scene.report.warnings)
      EXPECT_EQ(warning.find("pulled back"), std::string::npos) << warning;
  }
}

TEST(BoneSpheres, TwoRingRootsOnASphere) {
  const btScalar radius = 0.03f;
  const BoneInput bone = sphereBone("ball", {0, 0, 0}, radius);
  const PreparedScene scene = prepareScene({bone}, {}, 1);
  const BoneSettings& settings = *scene.bones[0];
  // On a regular mesh the longest edge through a root is about the mean edge: every sphere
  // sits Lmax inside and reaches Lmax·(√2 − 1) outside the surface.
  for (size_t s = 0; s < settings.sphereCentres.size(); ++s) {
    const btScalar depth = radius - settings.sphereCentres[s].length();
    const btScalar lmax = settings.sphereRadii[s] / std::sqrt(2.f);
    EXPECT_NEAR(depth, lmax, 0.02f * lmax);
  }
  // Two-rings are disjoint from other roots, so there are far fewer spheres than vertices
  // but at least vertices / (largest two-ring size).
  const size_t vertices = bone.mesh.vertices.size();
  EXPECT_LT(settings.sphereCentres.size(), vertices / 4);
  EXPECT_GE(settings.sphereCentres.size(), vertices / 19);
}

TEST(BoneSpheres, DegenerateTrianglesCannotMakeHugeSpheres) {
  BoneInput bone = sphereBone("ball", {0, 0, 0}, 0.03f);
  // A sliver: a far-away vertex joined to two neighbours by a zero-area triangle, and a long
  // thin triangle made of existing vertices.
  bone.mesh.vertices.push_back(bone.mesh.vertices[0] * 30.f);
  const uint32_t far = static_cast<uint32_t>(bone.mesh.vertices.size() - 1);
  bone.mesh.triangles.push_back({0, far, far});
  const PreparedScene scene = prepareScene({bone}, {}, 1);
  const BoneSettings& settings = *scene.bones[0];
  double edgeSum = 0;
  size_t edges = 0;
  for (const auto& t : bone.mesh.triangles)
    if (t[1] != t[2])
      for (int k = 0; k < 3; ++k)
        edgeSum += (bone.mesh.vertices[t[k]] - bone.mesh.vertices[t[(k + 1) % 3]]).length(),
            ++edges;
  const double meanEdge = edgeSum / edges;
  for (btScalar r : settings.sphereRadii) EXPECT_LE(r, 3 * meanEdge * std::sqrt(2.0) * 1.001);
  bool reported = false;
  for (const auto& warning : scene.report.warnings)
    reported |= warning.find("zero-area") != std::string::npos;
  EXPECT_TRUE(reported);
}

TEST(BoneSpheres, ThinningAndMaxRadius) {
  BoneInput bone = sphereBone("ball", {0, 0, 0}, 0.03f);
  const size_t full = prepareScene({bone}, {}, 1).bones[0]->sphereCentres.size();
  bone.spheres.thinning = 0.5f;
  const auto a = prepareScene({bone}, {}, 1).bones[0];
  const auto b = prepareScene({bone}, {}, 1).bones[0];
  const auto c = prepareScene({bone}, {}, 2).bones[0];
  EXPECT_LT(a->sphereCentres.size(), full);
  EXPECT_GT(a->sphereCentres.size(), 0u);
  EXPECT_EQ(a->sphereCentres, b->sphereCentres);
  EXPECT_NE(a->sphereCentres, c->sphereCentres);
  bone.spheres.thinning = 0;
  const btScalar typical = prepareScene({bone}, {}, 1).bones[0]->sphereRadii.front();
  bone.spheres.maxRadius = typical;
  const auto capped = prepareScene({bone}, {}, 1).bones[0];
  EXPECT_FALSE(capped->sphereRadii.empty());
  for (btScalar r : capped->sphereRadii) EXPECT_LE(r, typical);
  bone.spheres.thinning = 1;
  EXPECT_THROW(prepareScene({bone}, {}, 1), InputError);
}

/// Brute force of the declared-attachment rule: the bone that fixes particle p (-1: free), the
/// nearest area bone within the attachment distance among the areas whose vertices are no more
/// than that distance farther from p than the nearest surface vertex.
int32_t expectedDeclaredBone(const MuscleInput& input, const std::vector<BoneInput>& bones,
                             const btVector3& p) {
  const btScalar attachment = input.parameters.attachmentDistance;
  auto nearestOf = [&](const std::vector<uint32_t>& ids) {
    btScalar best = 1e9f;
    for (uint32_t v : ids) best = std::min(best, p.distance(input.surface.vertices[v]));
    return best;
  };
  std::vector<uint32_t> all(input.surface.vertices.size());
  for (uint32_t v = 0; v < all.size(); ++v) all[v] = v;
  const btScalar toSurface = nearestOf(all);
  int32_t bone = -1;
  btScalar best = attachment;
  for (const DeclaredAttachment& area : input.attachments) {
    if (nearestOf(area.surfaceVertices) - toSurface > attachment) continue;
    for (uint32_t b : area.bones) {
      const btScalar d = bruteDistance(bones[b].mesh, p);
      if (d < best) best = d, bone = int32_t(b);
    }
  }
  return bone;
}

/// The bone each particle of the prepared muscle is fixed to agrees with the brute force (ties
/// within 1 µm of the attachment distance skipped); returns the particles checked.
size_t expectDeclaredBones(const MuscleInput& input, const std::vector<BoneInput>& bones,
                           const MuscleSettings& muscle) {
  size_t checked = 0;
  for (uint32_t i = 0; i < muscle.particleCount(); ++i) {
    const btVector3& p = muscle.restPositions[i];
    bool tie = false;
    for (const BoneInput& bone : bones)
      tie |= std::abs(bruteDistance(bone.mesh, p) - input.parameters.attachmentDistance) < 1e-6f;
    if (tie) continue;
    ++checked;
    EXPECT_EQ(muscle.fixedBone[i], expectedDeclaredBone(input, bones, p)) << "particle " << i;
    EXPECT_EQ(muscle.isFixed(i), muscle.fixedBone[i] >= 0) << "particle " << i;
  }
  return checked;
}

TEST(Attachments, DeclaredAreasFixOnlyTheirParticles) {
  // Fibres run from the left bone to the right one; a sphere touches the muscle's top next to
  // its right end. The nearest-bone rule fixes particles to the sphere; declared areas (the
  // box surface's left corners on the left bone, its right corners on the right bone) do not.
  MuscleInput input = gridMuscle("m", 0, 0.1f, 0, 0.01f, 3, 3, 25);
  input.parameters.attachmentDistance = 0.006f;
  const std::vector<BoneInput> bones = endBonesAnd({sphereBone("side", {0.08f, 0.03f, 0}, 0.02f)});
  const std::vector<size_t> nearestRule =
      fixedParticlesPerBone(*prepareScene(bones, {input}, 3).muscles[0], bones.size());
  ASSERT_GT(nearestRule[2], 0u);

  input.attachments = {{"origin", {0, 2, 4, 6}, {0}}, {"insertion", {1, 3, 5, 7}, {1}}};
  const PreparedScene scene = prepareScene(bones, {input}, 3);
  const MuscleSettings& muscle = *scene.muscles[0];
  EXPECT_GT(expectDeclaredBones(input, bones, muscle), muscle.particleCount() * 9 / 10);
  const std::vector<size_t> declared = fixedParticlesPerBone(muscle, bones.size());
  EXPECT_EQ(declared[0], nearestRule[0]);  // the ends are fixed as before
  EXPECT_EQ(declared[2], 0u);              // the sphere fixes nothing: its particles are free
  size_t nearSide = 0;
  for (uint32_t i = 0; i < muscle.particleCount(); ++i)
    nearSide += bruteDistance(bones[2].mesh, muscle.restPositions[i]) < 0.006f;
  EXPECT_GT(nearSide, 0u);
  EXPECT_EQ(muscle.fixedParticles.size(), declared[0] + declared[1]);
  for (size_t f = 0; f < muscle.fibreCount(); ++f) {  // every fibre from left to right
    EXPECT_EQ(muscle.fixedBone[muscle.fibreParticles[muscle.fibreOffsets[f]]], 0);
    EXPECT_EQ(muscle.fixedBone[muscle.fibreParticles[muscle.fibreOffsets[f + 1] - 1]], 1);
  }
}

TEST(Attachments, AnAreaOnSeveralBonesFixesEachParticleToTheNearest) {
  // The origin is shared by the left bone and a sphere over the muscle's left end; the same
  // sphere's bone near the right end is not part of the insertion's area.
  MuscleInput input = gridMuscle("m", 0, 0.1f, 0, 0.01f, 3, 3, 25);
  input.parameters.attachmentDistance = 0.006f;
  const std::vector<BoneInput> bones =
      endBonesAnd({sphereBone("left-cap", {0.015f, 0.03f, 0}, 0.02f),
                   sphereBone("right-cap", {0.08f, 0.03f, 0}, 0.02f)});
  input.attachments = {{"origin", {0, 2, 4, 6}, {0, 2, 3}}, {"insertion", {1, 3, 5, 7}, {1}}};
  const PreparedScene scene = prepareScene(bones, {input}, 3);
  const MuscleSettings& muscle = *scene.muscles[0];
  EXPECT_GT(expectDeclaredBones(input, bones, muscle), muscle.particleCount() * 9 / 10);
  const std::vector<size_t> perBone = fixedParticlesPerBone(muscle, bones.size());
  EXPECT_GT(perBone[0], 0u);
  EXPECT_GT(perBone[2], 0u);  // the shared area's second bone
  EXPECT_EQ(perBone[3], 0u);  // named by the origin, but nowhere near the origin's area
}

TEST(Attachments, DeclaredAreasMustNameVerticesAndBonesThatExist) {
  MuscleInput input = gridMuscle("m", 0, 0.1f, 0, 0.01f, 3, 3, 10);
  const std::vector<BoneInput> bones = {
      boxBone("left", {-0.03f, -0.02f, -0.02f}, {0, 0.02f, 0.02f})};
  input.attachments = {{"origin", {0, 2}, {}}, {"insertion", {1}, {0}}};
  EXPECT_THROW(prepareScene(bones, {input}, 1), InputError);
  input.attachments = {{"origin", {0, 2}, {1}}, {"insertion", {1}, {0}}};
  EXPECT_THROW(prepareScene(bones, {input}, 1), InputError);
  input.attachments = {{"origin", {0, 99}, {0}}, {"insertion", {1}, {0}}};
  EXPECT_THROW(prepareScene(bones, {input}, 1), InputError);
}

TEST(Blend, TheSecondBonesShareIsContinuousWhereEitherBoneChanges) {
  // Two bones: the plain inverse-square weights, to the bit.
  for (const double d1 : {1e-6, 0.003, 0.01})
    for (const double d2 : {0.01, 0.02, 0.5})
      EXPECT_EQ(detail::blendWeight(d1, d2, HUGE_VAL), d1 * d1 / (d1 * d1 + d2 * d2));
  // Where the nearest bone changes both shares are ½, whatever the third bone.
  EXPECT_DOUBLE_EQ(detail::blendWeight(0.01, 0.01, 0.03), 0.5);
  EXPECT_DOUBLE_EQ(detail::blendWeight(0.01, 0.01, HUGE_VAL), 0.5);
  // Where the second-nearest bone changes (d2 = d3) its share fades to 0, so the particles on
  // either side (second bone B or C) move alike.
  EXPECT_NEAR(detail::blendWeight(0.01, 0.02, 0.02), 0.0, 1e-12);
  const double before = detail::blendWeight(0.01, 0.02, 0.02 * (1 + 1e-6));
  EXPECT_GT(before, 0.0);
  EXPECT_LT(before, 1e-5);
  // In between: below the two-bone share, never negative.
  const double between = detail::blendWeight(0.01, 0.02, 0.04);
  EXPECT_GT(between, 0.0);
  EXPECT_LT(between, detail::blendWeight(0.01, 0.02, HUGE_VAL));
  // (1/d2² − 1/d3²) / (1/d1² + 1/d2² − 2/d3²) at 1, 2, 4: (1/4 − 1/16) / (1 + 1/4 − 2/16) = 1/6.
  EXPECT_NEAR(detail::blendWeight(1, 2, 4), 1.0 / 6, 1e-15);
}

}  // namespace
}  // namespace fibremss
