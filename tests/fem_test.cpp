// The FEM reference and its tetrahedral mesher, and the btSoftBody baseline, on small scenes
// made here with known geometry.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>

#include "fibremss/Error.h"
#include "fibremss/FemBuilder.h"
#include "fibremss/Measures.h"
#include "fibremss/Scene.h"
#include "fibremss/SoftBodyBuilder.h"
#include "fibremss/TetMesher.h"
#include "support/PrepFixtures.h"

namespace fibremss {
namespace {

using testing::boxMesh;
using testing::sphereMesh;

double surfaceArea(const TriangleMesh& mesh) {
  double area = 0;
  for (const auto& t : mesh.triangles) {
    area += 0.5 * (mesh.vertices[t[1]] - mesh.vertices[t[0]])
                      .cross(mesh.vertices[t[2]] - mesh.vertices[t[0]])
                      .length();
  }
  return area;
}

TEST(TetMesher, SphereGivesPositiveTetrahedraWhoseVolumeMatchesTheSurface) {
  const TriangleMesh sphere = sphereMesh(btVector3(0.1f, -0.2f, 0.3f), 0.05f, 3);
  const double surfaceVolume = meshVolume(sphere);
  const double area = surfaceArea(sphere);
  double previousError = INFINITY;
  for (const int cells : {300, 2500}) {
    const TetMesh mesh = tetrahedralize(sphere, {.targetCells = cells});
    ASSERT_FALSE(mesh.tetrahedra.empty());
    for (const auto& t : mesh.tetrahedra) {
      ASSERT_GT(
          tetrahedronVolume(mesh.nodes[t[0]], mesh.nodes[t[1]], mesh.nodes[t[2]], mesh.nodes[t[3]]),
          0);
    }
    // Voxels count by their centres, so only voxels within half a voxel diagonal of the
    // surface can be wrong: |error| <= area · h·√3/2.
    const double error = std::abs(totalVolume(mesh) - surfaceVolume);
    EXPECT_LE(error, area * mesh.cellSize * std::sqrt(3.0) / 2) << cells << " cells";
    // and in practice far less: within 5 % at ~300 voxels
    EXPECT_LE(error / surfaceVolume, 0.05) << cells << " cells";
    EXPECT_LT(error, previousError) << "finer voxels must fit better";
    previousError = error;
  }
}

TEST(TetMesher, EveryTetrahedronIsPositiveOnAThinBox) {
  const TriangleMesh box = boxMesh(btVector3(0, 0, 0), btVector3(0.2f, 0.01f, 0.03f));
  const TetMesh mesh = tetrahedralize(box, {.targetCells = 50, .minCells = 40});
  EXPECT_GE(mesh.tetrahedra.size(), 6u * 40);
  for (const auto& t : mesh.tetrahedra) {
    ASSERT_GT(
        tetrahedronVolume(mesh.nodes[t[0]], mesh.nodes[t[1]], mesh.nodes[t[2]], mesh.nodes[t[3]]),
        0);
  }
}

TEST(TetMesher, RejectsAnInsideOutSurface) {
  TriangleMesh inverted = sphereMesh(btVector3(0, 0, 0), 0.05f, 1);
  for (auto& t : inverted.triangles) std::swap(t[1], t[2]);
  EXPECT_THROW(tetrahedralize(inverted), InputError);
}

TEST(TetEmbedding, ReproducesPointsAndFollowsAffineMaps) {
  const TriangleMesh sphere = sphereMesh(btVector3(0, 0, 0), 0.04f, 2);
  const TetMesh mesh = tetrahedralize(sphere, {.targetCells = 200});
  const TetEmbedding embedding = embed(mesh, sphere.vertices);
  std::vector<btVector3> out;
  embeddedPositions(mesh, embedding, mesh.nodes, out);
  EXPECT_LT(rmsDistanceMm(out, sphere.vertices), 1e-3);
  // Barycentric weights (also extrapolated ones) reproduce any affine map of the nodes.
  const btMatrix3x3 stretch(1.2f, 0.1f, 0, 0, 0.9f, 0, 0.05f, 0, 1.1f);
  const btVector3 shift(0.01f, 0.02f, -0.03f);
  std::vector<btVector3> nodes, expected;
  for (const btVector3& n : mesh.nodes) nodes.push_back(stretch * n + shift);
  for (const btVector3& v : sphere.vertices) expected.push_back(stretch * v + shift);
  embeddedPositions(mesh, embedding, nodes, out);
  EXPECT_LT(rmsDistanceMm(out, expected), 1e-3);
}

/// A box muscle 60 × 20 × 20 mm along +x from x = 0, shifted by `offset`: 7 × 3 × 3 particles
/// 10 mm (x) and 8 mm (y, z) apart, springs to all neighbours within 1.8 cells, the x = 0 layer
/// fixed to bone 0, each surface vertex skinned by its three nearest particles. Particle p is
/// grid point (p · stride) mod 63 (stride coprime to 63): the same muscle in another node order.
std::shared_ptr<MuscleSettings> rodMuscle(const btVector3& offset = btVector3(0, 0, 0),
                                          uint32_t stride = 1) {
  auto muscle = std::make_shared<MuscleSettings>();
  MuscleSettings& m = *muscle;
  m.name = "rod";
  m.restSurface =
      boxMesh(btVector3(0, -0.01f, -0.01f) + offset, btVector3(0.06f, 0.01f, 0.01f) + offset);
  constexpr uint32_t kCount = 7 * 3 * 3;
  for (uint32_t index = 0; index < kCount; ++index) {
    const uint32_t grid = index * stride % kCount;
    const int i = static_cast<int>(grid / 9), j = static_cast<int>(grid / 3 % 3) - 1,
              k = static_cast<int>(grid % 3) - 1;
    m.restPositions.push_back(btVector3(0.01f * i, 0.008f * j, 0.008f * k) + offset);
    const bool fixed = i == 0;
    m.flags.push_back(fixed ? kFixed | kBoundary : kBoundary);
    m.fixedBone.push_back(fixed ? 0 : -1);
    m.nearestBone.push_back(0);
    m.radii.push_back(0.004f);
    m.boundaryParticles.push_back(index);
    if (fixed) m.fixedParticles.push_back(index);
  }
  m.particleMass = 1060 * 0.06f * 0.02f * 0.02f / static_cast<btScalar>(m.particleCount());
  m.damping = 0.05f;
  for (uint32_t a = 0; a < m.particleCount(); ++a) {
    for (uint32_t b = a + 1; b < m.particleCount(); ++b) {
      const btScalar length = m.restPositions[a].distance(m.restPositions[b]);
      if (length < 0.018f) m.springs.push_back({a, b, length, 1.0f / length});
    }
  }
  m.skinNeighbours = 3;
  for (const btVector3& v : m.restSurface.vertices) {
    std::vector<std::pair<btScalar, uint32_t>> byDistance;
    for (uint32_t p = 0; p < m.particleCount(); ++p) {
      byDistance.emplace_back(v.distance(m.restPositions[p]), p);
    }
    std::partial_sort(byDistance.begin(), byDistance.begin() + 3, byDistance.end());
    for (int n = 0; n < 3; ++n) {
      m.skinParticles.push_back(byDistance[n].second);
      m.skinWeights.push_back(btScalar(1) / 3);
    }
  }
  return muscle;
}

/// The bone box on the −x side of the rods, wide enough for `rods` rods side by side.
std::shared_ptr<BoneSettings> rodBone(int rods = 1) {
  auto bone = std::make_shared<BoneSettings>();
  bone->name = "bone";
  bone->mesh = boxMesh(btVector3(-0.05f, -0.02f, -0.02f),
                       btVector3(-0.001f, 0.02f + 0.03f * static_cast<btScalar>(rods - 1), 0.02f));
  return bone;
}

/// One rod (rodMuscle) fixed to its bone.
PreparedScene rodScene() {
  PreparedScene scene;
  scene.bones.push_back(rodBone());
  scene.muscles.push_back(rodMuscle());
  return scene;
}

/// Three rods side by side along +y whose outer particle layers are `gap` apart (less than
/// their spheres' 8 mm: they touch at rest, as the muscles of thigh13 do), each in another
/// node order (strides 1, 62 = reversed, 29).
PreparedScene touchingRodsScene(btScalar gap) {
  PreparedScene scene;
  scene.bones.push_back(rodBone(3));
  const uint32_t strides[] = {1, 62, 29};
  for (int r = 0; r < 3; ++r) {
    scene.muscles.push_back(
        rodMuscle(btVector3(0, (0.016f + gap) * static_cast<btScalar>(r), 0), strides[r]));
  }
  return scene;
}

std::vector<btVector3> restSurfaceAt(const PreparedScene& scene, const btTransform& transform) {
  std::vector<btVector3> moved;
  for (const btVector3& v : scene.muscles[0]->restSurface.vertices) moved.push_back(transform * v);
  return moved;
}

bool finite(std::span<const btVector3> points) {
  for (const btVector3& p : points) {
    if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || !std::isfinite(p.z())) return false;
  }
  return true;
}

TEST(SkinSurface, ReproducesARigidMotionExactly) {
  const PreparedScene scene = rodScene();
  const MuscleSettings& m = *scene.muscles[0];
  const btTransform motion(btQuaternion(btVector3(0, 0, 1), 0.4f), btVector3(0.01f, 0, 0.02f));
  std::vector<btVector3> particles;
  for (const btVector3& p : m.restPositions) particles.push_back(motion * p);
  std::vector<btVector3> surface;
  skinSurface(m, particles, {&motion, 1}, surface);
  EXPECT_LT(rmsDistanceMm(surface, restSurfaceAt(scene, motion)), 1e-3);
}

TEST(FemScene, StaysAtRestWithoutMotion) {
  const PreparedScene scene = rodScene();
  const btTransform rest = btTransform::getIdentity();
  FemScene fem(scene, {&rest, 1}, {.mesher = {.targetCells = 60}});
  EXPECT_GT(fem.pinnedCount(), 0u);
  EXPECT_LT(fem.pinnedCount(), fem.nodeCount());
  for (int pose = 0; pose < 3; ++pose) fem.stepPose({&rest, 1});
  std::vector<btVector3> surface;
  fem.surface(0, surface);
  EXPECT_LT(rmsDistanceMm(surface, restSurfaceAt(scene, rest)), 0.01);
}

TEST(FemScene, FollowsATranslatedBone) {
  // The bone moves 10 mm along y: the attached end goes with it and the free end follows
  // elastically, so the surface ends between rest and the translated rest, closer to the
  // latter than the rest pose is (10 mm), with the volume nearly kept.
  const PreparedScene scene = rodScene();
  const btTransform rest = btTransform::getIdentity();
  const btTransform moved(btQuaternion::getIdentity(), btVector3(0, 0.01f, 0));
  FemScene fem(scene, {&rest, 1}, {.mesher = {.targetCells = 60}});
  for (int pose = 0; pose < 6; ++pose) fem.stepPose({&moved, 1});
  std::vector<btVector3> surface;
  fem.surface(0, surface);
  ASSERT_TRUE(finite(surface));
  EXPECT_LT(rmsDistanceMm(surface, restSurfaceAt(scene, moved)), 10.0);
  EXPECT_LT(std::abs(volumeChangePercent(scene.muscles[0]->restSurface, surface)), 10.0);
}

/// How far the free-swinging rod's surface moves [mm RMS] when a pose reached in 10 substeps
/// (too few: the free end still swings) is held for one more pose.
double heldPoseMotionMm(const PreparedScene& scene, FemDefinition definition) {
  const btTransform rest = btTransform::getIdentity();
  const btTransform moved(btQuaternion::getIdentity(), btVector3(0, 0.01f, 0));
  definition.substepsPerPose = 10;
  definition.freeNodesFollowBones = false;
  FemScene fem(scene, {&rest, 1}, definition);
  std::vector<btVector3> reached, held;
  fem.stepPose({&moved, 1});
  fem.surface(0, reached);
  fem.stepPose({&moved, 1});
  fem.surface(0, held);
  return rmsDistanceMm(held, reached);
}

TEST(FemScene, EveryAttachingBoneHoldsTheMinimumPinsAndAPoseSettles) {
  // A coarse grid pins few nodes by distance alone; each bone then gets its nearest nodes.
  const PreparedScene scene = rodScene();
  const btTransform rest = btTransform::getIdentity();
  const FemDefinition few{.mesher = {.targetCells = 60}, .minPinsPerBone = 0};
  const size_t byDistance = FemScene(scene, {&rest, 1}, few).fewestPinsPerBone();
  FemDefinition definition = few;
  definition.minPinsPerBone = static_cast<int>(byDistance) + 5;
  EXPECT_EQ(FemScene(scene, {&rest, 1}, definition).fewestPinsPerBone(), byDistance + 5);
  // Settling brings a pose nearer its equilibrium: holding it moves the surface less.
  FemDefinition unsettled = definition;
  unsettled.settleSubsteps = 0;
  const double without = heldPoseMotionMm(scene, unsettled);
  const double with = heldPoseMotionMm(scene, definition);
  EXPECT_GT(without, 0.5) << "10 substeps leave the free end swinging";
  EXPECT_LT(with, 0.5 * without);
}

TEST(FemScene, BoneContactKeepsFreeNodesOutsideAMovingBone) {
  // A plate bone under the rod rises 6 mm, 4 mm into it: without contact the nodes it
  // passes stay inside; with contact every node ends outside the moved plate.
  PreparedScene scene = rodScene();
  auto plate = std::make_shared<BoneSettings>();
  plate->name = "plate";
  plate->mesh = boxMesh(btVector3(0.015f, -0.04f, -0.03f), btVector3(0.07f, -0.012f, 0.03f));
  scene.bones.push_back(plate);
  const btTransform rest = btTransform::getIdentity();
  const btTransform raised(btQuaternion::getIdentity(), btVector3(0, 0.006f, 0));
  const std::array<btTransform, 2> start{rest, rest}, pressed{rest, raised};
  const MeshDistance plateSurface(plate->mesh);
  auto deepest = [&](bool contact) {
    FemScene fem(scene, start, {.mesher = {.targetCells = 60}, .boneContact = contact});
    for (int pose = 0; pose < 4; ++pose) fem.stepPose(pressed);
    btScalar depth = -1;
    for (const btVector3& node : fem.nodePositions(0)) {
      depth = std::max(depth, -plateSurface.signedDistance(raised.invXform(node)));
    }
    return depth;
  };
  EXPECT_GT(deepest(false), 0.002f);
  EXPECT_LT(deepest(true), 1e-5f);
}

TEST(FemScene, SurvivesHipFlexionPosesWithoutInvertedTetrahedra) {
  // The first two 5° steps of hip-flexion: with 50 substeps, no mass scaling and free nodes
  // left to the pinned ones, tetrahedra of muscle 3 inverted within the first moving pose
  // (Bullet's elastic forces are explicit; FemDefinition::stableOmegaDt). After every pose
  // each node must be finite, each tetrahedron positively oriented, each edge within 3× rest.
  const LoadedScene loaded = loadScene("hip-flexion", {});
  const PreparedScene scene = prepareScene(loaded.bones, loaded.muscles, loaded.simulation.seed);
  const auto posesAt = [&](int pose) {
    std::vector<btTransform> transforms;
    for (size_t b = 0; b < loaded.bones.size(); ++b) transforms.push_back(loaded.bonePose(b, pose));
    return transforms;
  };
  FemScene fem(scene, posesAt(0), {.mesher = {.targetCells = 60}});
  EXPECT_GT(fem.addedMassShare(), 0) << "hip-flexion's stiff muscles need mass scaling";
  for (int pose = 1; pose <= 2; ++pose) {
    fem.stepPose(posesAt(pose));
    for (size_t m = 0; m < fem.muscleCount(); ++m) {
      const TetMesh& mesh = fem.tetMesh(m);
      const std::span<const btVector3> x = fem.nodePositions(m);
      ASSERT_TRUE(std::all_of(x.begin(), x.end(),
                              [](const btVector3& p) {
                                return std::isfinite(p.x()) && std::isfinite(p.y()) &&
                                       std::isfinite(p.z());
                              }))
          << "pose " << pose << " muscle " << m;
      for (const auto& t : mesh.tetrahedra) {
        ASSERT_GT(tetrahedronVolume(x[t[0]], x[t[1]], x[t[2]], x[t[3]]), 0)
            << "pose " << pose << " muscle " << m;
        for (int a = 0; a < 4; ++a) {
          for (int b = a + 1; b < 4; ++b) {
            ASSERT_LT(x[t[a]].distance(x[t[b]]), 3 * mesh.nodes[t[a]].distance(mesh.nodes[t[b]]))
                << "pose " << pose << " muscle " << m;
          }
        }
      }
    }
  }
}

TEST(SoftBodyScene, ClustersHoldOnlyFreeNodesAndHaveFiniteInertia) {
  // Bullet weighs a pinned node as 1e18 in its cluster; in float its inverse inertia is NaN.
  const PreparedScene scene = rodScene();
  const btTransform rest = btTransform::getIdentity();
  SoftBodyScene soft(scene, {&rest, 1}, {.clustersPerMuscle = 8});
  btSoftBody& body = soft.body(0);
  ASSERT_GT(body.m_clusters.size(), 0);
  for (int c = 0; c < body.m_clusters.size(); ++c) {
    const btSoftBody::Cluster& cluster = *body.m_clusters[c];
    EXPECT_GE(cluster.m_nodes.size(), 4);
    for (int n = 0; n < cluster.m_nodes.size(); ++n) EXPECT_GT(cluster.m_nodes[n]->m_im, 0);
    for (int r = 0; r < 3; ++r) {
      EXPECT_TRUE(std::isfinite(cluster.m_invwi[r].length())) << "cluster " << c;
    }
  }
}

TEST(SoftBodyScene, StaysAtRestWithoutMotion) {
  const PreparedScene scene = rodScene();
  const btTransform rest = btTransform::getIdentity();
  SoftBodyScene soft(scene, {&rest, 1});
  EXPECT_EQ(soft.nodeCount(), scene.muscles[0]->particleCount());
  EXPECT_EQ(soft.elementCount(), scene.muscles[0]->springs.size());
  for (int pose = 0; pose < 3; ++pose) soft.stepPose({&rest, 1});
  std::vector<btVector3> surface;
  soft.surface(0, surface);
  EXPECT_LT(rmsDistanceMm(surface, restSurfaceAt(scene, rest)), 0.01);
}

TEST(SoftBodyScene, PinnedNodesMoveWithTheirBoneAndTheRestFollows) {
  const PreparedScene scene = rodScene();
  const MuscleSettings& m = *scene.muscles[0];
  const btTransform rest = btTransform::getIdentity();
  const btTransform moved(btQuaternion::getIdentity(), btVector3(0, 0.01f, 0));
  SoftBodyScene soft(scene, {&rest, 1});
  for (int pose = 0; pose < 6; ++pose) soft.stepPose({&moved, 1});
  const auto positions = soft.nodePositions(0);
  ASSERT_TRUE(finite(positions));
  for (uint32_t i : m.fixedParticles) {
    EXPECT_LT(positions[i].distance(moved * m.restPositions[i]), 1e-6f);
  }
  // The free end moved towards the bone's displacement.
  const btVector3 tip = positions[m.particleCount() - 5];  // centre of the x = 60 mm layer
  EXPECT_GT(tip.y(), 0.002f);
  EXPECT_LT(springDeviationRatio(m.springs, positions), 0.1);
}

TEST(SoftBodyScene, MusclesTouchingAtRestStayAtRest) {
  // Muscles closer at rest than their spheres' radii (thigh13: 0.6 mm apart, 2–4 mm radii):
  // cluster contacts must not push them apart before anything moves (thigh13 exploded at
  // pose 0, a link at 4.2×). Nothing moves, so every link keeps its rest length.
  const PreparedScene scene = touchingRodsScene(0.002f);
  const btTransform rest = btTransform::getIdentity();
  SoftBodyScene soft(scene, {&rest, 1}, {.clustersPerMuscle = 4});
  for (size_t m = 0; m < scene.muscles.size(); ++m) ASSERT_GT(soft.body(m).m_clusters.size(), 1);
  for (int pose = 0; pose < 3; ++pose) soft.stepPose({&rest, 1});
  for (size_t m = 0; m < scene.muscles.size(); ++m) {
    const auto positions = soft.nodePositions(m);
    ASSERT_TRUE(finite(positions)) << "muscle " << m;
    double worst = 0;  // largest relative change of a link's length
    for (const Spring& spring : scene.muscles[m]->springs) {
      const double length = positions[spring.a].distance(positions[spring.b]);
      worst = std::max(worst, std::abs(length / spring.restLength - 1));
    }
    EXPECT_LT(worst, 0.01) << "muscle " << m;
  }
}

TEST(SoftBodyScene, ClustersDoNotDependOnTheNodeOrder) {
  // The rods of touchingRodsScene are one muscle numbered three ways: each must get the same
  // clusters (as sets of rest positions relative to the rod).
  const PreparedScene scene = touchingRodsScene(0.002f);
  const btTransform rest = btTransform::getIdentity();
  SoftBodyScene soft(scene, {&rest, 1}, {.clustersPerMuscle = 4});
  // Node positions relative to the rod, in 0.1 mm (exact for the rods' 8 and 10 mm grid).
  std::vector<std::vector<std::vector<std::array<long, 3>>>> clusters(scene.muscles.size());
  for (size_t m = 0; m < scene.muscles.size(); ++m) {
    const btSoftBody& body = soft.body(m);
    const btVector3 origin = scene.muscles[m]->restSurface.vertices.front();
    for (int c = 0; c < body.m_clusters.size(); ++c) {
      auto& nodes = clusters[m].emplace_back();
      const auto& members = body.m_clusters[c]->m_nodes;
      for (int n = 0; n < members.size(); ++n) {
        const btVector3 x = (members[n]->m_x / soft.definition().lengthScale - origin) * 1e4f;
        nodes.push_back({std::lround(x.x()), std::lround(x.y()), std::lround(x.z())});
      }
      std::sort(nodes.begin(), nodes.end());
    }
    std::sort(clusters[m].begin(), clusters[m].end());
  }
  ASSERT_GT(clusters[0].size(), 1u);
  EXPECT_EQ(clusters[1], clusters[0]);
  EXPECT_EQ(clusters[2], clusters[0]);
}

/// A fibre 60 mm along +x between bone 0 (x < 0) and bone 1 (x > 60 mm): particles 10 mm
/// apart plus one only `gap` beyond x = 30 mm (converging fibres leave such pairs: thigh13's
/// shortest spring at resolution 40 is 0.078 mm), springs to the first and second neighbours
/// along the fibre, k = κ/L0 with thigh13's κ and particle mass, the ends fixed to the bones,
/// free particles blended between the bones by their place along the fibre.
PreparedScene fibreWithAShortSpringScene(btScalar gap) {
  PreparedScene scene;
  for (int b = 0; b < 2; ++b) {
    auto bone = std::make_shared<BoneSettings>();
    bone->name = b == 0 ? "origin" : "insertion";
    bone->mesh = b == 0
                     ? boxMesh(btVector3(-0.02f, -0.01f, -0.01f), btVector3(-0.002f, 0.01f, 0.01f))
                     : boxMesh(btVector3(0.062f, -0.01f, -0.01f), btVector3(0.08f, 0.01f, 0.01f));
    scene.bones.push_back(bone);
  }
  auto muscle = std::make_shared<MuscleSettings>();
  MuscleSettings& m = *muscle;
  m.name = "fibre";
  const btScalar xs[] = {0, 0.01f, 0.02f, 0.03f, 0.03f + gap, 0.04f, 0.05f, 0.06f};
  for (btScalar x : xs) {
    const uint32_t i = static_cast<uint32_t>(m.restPositions.size());
    const bool fixed = x == 0 || x == xs[std::size(xs) - 1];
    const int32_t nearest = x < 0.03f ? 0 : 1;
    m.restPositions.push_back(btVector3(x, 0, 0));
    m.radii.push_back(0.002f);
    m.flags.push_back(fixed ? kFixed | kBoundary : kBoundary);
    m.fixedBone.push_back(fixed ? nearest : -1);
    m.nearestBone.push_back(nearest);
    m.blendBoneA.push_back(nearest);
    m.blendBoneB.push_back(1 - nearest);
    m.blendWeight.push_back(nearest == 0 ? x / 0.06f : 1 - x / 0.06f);
    m.boundaryParticles.push_back(i);
    if (fixed) m.fixedParticles.push_back(i);
    m.fibreParticles.push_back(i);
  }
  m.fibreOffsets.push_back(static_cast<uint32_t>(m.particleCount()));
  m.particleMass = 3.2e-5f;
  for (uint32_t a = 0; a < m.particleCount(); ++a) {
    for (uint32_t b = a + 1; b < m.particleCount() && b <= a + 2; ++b) {
      const btScalar length = m.restPositions[a].distance(m.restPositions[b]);
      m.springs.push_back({a, b, length, 1.0f / length});
    }
  }
  scene.muscles.push_back(muscle);
  return scene;
}

TEST(SoftBodyScene, AShortLinkTakesNoMoreThanItsShareOfAStretch) {
  // The insertion bone moves 3 mm per pose along the fibre: FibreMSS stretches every spring
  // alike (k = κ/L0), to 1.2× after four poses. At the baseline's substep every link is
  // saturated (m_kLST = 1, as on thigh13): solved in fibre order, the 0.1 mm link took about
  // as many millimetres as the 10 mm links (thigh13 R=40: a 0.078 mm link past 3× at pose 3);
  // solved stiffest last no link passes 1.5× the fibre's stretch. (The short link then ends
  // shorter than at rest: Bullet's linearised projection overshoots a link stretched to many
  // times its length, and in this series chain it is stretched so before it is solved.)
  const PreparedScene scene = fibreWithAShortSpringScene(0.0001f);
  const btTransform rest = btTransform::getIdentity();
  const std::array<btTransform, 2> start{rest, rest};
  SoftBodyScene soft(scene, start);
  const MuscleSettings& m = *scene.muscles[0];
  for (int pose = 1; pose <= 4; ++pose) {
    const btTransform pulled(btQuaternion::getIdentity(),
                             btVector3(0.003f * static_cast<btScalar>(pose), 0, 0));
    soft.stepPose(std::array<btTransform, 2>{rest, pulled});
    const auto positions = soft.nodePositions(0);
    ASSERT_TRUE(finite(positions)) << "pose " << pose;
    const double stretch = 1 + 0.003 * pose / 0.06;  // the whole fibre's
    for (const Spring& spring : m.springs) {
      const double ratio = positions[spring.a].distance(positions[spring.b]) / spring.restLength;
      EXPECT_LT(ratio, 1.5 * stretch) << "pose " << pose << " spring " << spring.a << "-"
                                      << spring.b << " rest " << spring.restLength * 1e3 << " mm";
    }
  }
}

}  // namespace
}  // namespace fibremss
