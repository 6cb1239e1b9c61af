// The implicit surface (ImplicitSurface.h): closed (every edge shared by two triangles) on
// fusiform at rest and on the `tear` scene once torn, where it falls into pieces; on average
// within 1 mm of the skinned surface at rest, both ways, and nowhere farther than a grid cell;
// every thigh13 muscle at rest nowhere farther than a cell of its rest distance grid (the
// tendons' pointed ends met, the thinly covered parts not dipping in); the rest surface moved with
// the muscle when it moves as a rigid body (the map back to rest interpolated between every
// second grid point is exact there); dented by a negative field; the same for one thread and
// two, on one muscle and on thigh13's thirteen (and on a host's scheduler); one surface twice in
// one extraction refused; a repeated extraction allocates nothing.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "fibremss/Error.h"
#include "fibremss/ImplicitSurface.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "fibremss/SceneSystem.h"
#include "fibremss/TaskPool.h"
#include "support/AllocationCounter.h"
#include "support/BackwardsScheduler.h"

namespace fibremss {
namespace {

/// Mean and largest distance from the vertices of `from` to the surface `to` [m].
std::pair<double, double> distances(const TriangleMesh& from, const TriangleMesh& to) {
  const MeshDistance distance(to);
  double sum = 0, worst = 0;
  for (const btVector3& v : from.vertices) {
    const double d = distance.closest(v).distance;
    sum += d;
    worst = std::max(worst, d);
  }
  return {sum / double(from.vertices.size()), worst};
}

std::shared_ptr<const MuscleSettings> firstMuscle(const std::string& name) {
  const LoadedScene scene = loadScene(name, {});
  return prepareScene(scene.bones, scene.muscles, scene.simulation.seed).muscles[0];
}

TEST(ImplicitSurface, FusiformAtRestIsClosedAndOnAverageWithinAMillimetreOfTheSkinnedSurface) {
  const auto muscle = firstMuscle("fusiform");
  ImplicitSurface surface(muscle);
  surface.extract(muscle->restPositions);
  const MeshTopology topology = meshTopology(surface.mesh());
  EXPECT_GT(surface.mesh().triangles.size(), 100u);
  EXPECT_EQ(topology.openEdges, 0u);
  EXPECT_EQ(topology.components, 1u);
  // At rest the skinned surface is the rest surface.
  const auto [meanOut, worstOut] = distances(surface.mesh(), muscle->restSurface);
  const auto [meanIn, worstIn] = distances(muscle->restSurface, surface.mesh());
  RecordProperty("mean_mm", std::to_string(1000 * std::max(meanOut, meanIn)));
  RecordProperty("worst_mm", std::to_string(1000 * std::max(worstOut, worstIn)));
  EXPECT_LE(std::max(meanOut, meanIn), 1e-3);
  EXPECT_LE(std::max(worstOut, worstIn), surface.voxel());
}

/// The muscle's rest positions and rest surface turned about an oblique axis and moved [m].
struct Moved {
  std::vector<btVector3> positions;
  TriangleMesh surface;
};
Moved rigidlyMoved(const MuscleSettings& muscle) {
  const btTransform motion(btQuaternion(btVector3(1, 2, 3).normalized(), btScalar(0.7)),
                           btVector3(btScalar(0.011), btScalar(-0.023), btScalar(0.017)));
  Moved moved{muscle.restPositions, muscle.restSurface};
  for (btVector3& p : moved.positions) p = motion * p;
  for (btVector3& v : moved.surface.vertices) v = motion * v;
  return moved;
}

TEST(ImplicitSurface, ARigidlyMovedMuscleKeepsItsRestSurfaceMoved) {
  const auto muscle = firstMuscle("fusiform");
  const Moved moved = rigidlyMoved(*muscle);
  ImplicitSurface surface(muscle);
  surface.extract(moved.positions);
  EXPECT_EQ(meshTopology(surface.mesh()).openEdges, 0u);
  const auto [meanOut, worstOut] = distances(surface.mesh(), moved.surface);
  const auto [meanIn, worstIn] = distances(moved.surface, surface.mesh());
  RecordProperty("mean_mm", std::to_string(1000 * std::max(meanOut, meanIn)));
  RecordProperty("worst_mm", std::to_string(1000 * std::max(worstOut, worstIn)));
  // Not as close as at rest (the identity stands in for F⁻¹ where a particle's springs do not
  // span 3D, and the grid meets the tendons' ends otherwise), but the interpolated map adds
  // nothing (mean 0.35 mm, and 0.36 mm with the map at every grid point); mixing in the empty
  // maps of points without particles within h would give 0.87 mm.
  EXPECT_LE(std::max(meanOut, meanIn), 0.5e-3);
}

TEST(ImplicitSurface, ARepeatedExtractionAllocatesNothing) {
  const auto muscle = firstMuscle("fusiform");
  const Moved moved = rigidlyMoved(*muscle);
  ImplicitSurface surface(muscle);
  surface.extract(muscle->restPositions);
  surface.extract(moved.positions);
  const size_t triangles = surface.mesh().triangles.size();
  testing::allocationCount = 0;
  testing::countingArmed = true;
  surface.extract(muscle->restPositions);
  surface.extract(moved.positions);
  testing::countingArmed = false;
  EXPECT_EQ(testing::allocationCount.load(), 0);
  EXPECT_EQ(surface.mesh().triangles.size(), triangles);
}

TEST(ImplicitSurface, ADentPushesTheSurfaceIn) {
  const auto muscle = firstMuscle("fusiform");
  ImplicitSurface surface(muscle);
  const btVector3 centre = muscle->restSurface.vertices[0];
  const SurfaceDent dent{centre, btScalar(0.006), btScalar(0.004)};
  surface.setDents({&dent, 1});
  surface.extract(muscle->restPositions);
  EXPECT_EQ(meshTopology(surface.mesh()).openEdges, 0u);
  EXPECT_GT(MeshDistance(surface.mesh()).closest(centre).distance, 1e-3);
}

TEST(ImplicitSurface, TheTornTearSceneIsClosedInPieces) {
  const LoadedScene scene = loadScene("tear", {"resolution=12", "fibre_count=48"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  MuscleSystem system(scene.simulation);
  const SceneHandles handles = addScene(system, prepared);
  const std::vector<BoneHandle>& bones = handles.bones;
  const MuscleHandle muscle = handles.muscles[0];
  for (int pose = 0; pose < scene.poseCount; ++pose) {
    for (size_t b = 0; b < bones.size(); ++b)
      system.setBoneTransform(bones[b], scene.bonePose(b, pose));
    system.step();
  }
  ASSERT_GE(system.tear(muscle).pieces, 2u);
  ImplicitSurface one(prepared.muscles[0]), two(prepared.muscles[0]);
  const std::span<const btVector3> positions[] = {system.positions(muscle)};
  const std::span<const Spring> springs[] = {system.settings(muscle).springs};
  ImplicitSurface* const first[] = {&one};
  ImplicitSurface* const second[] = {&two};
  TaskPool serial(1), pair(2);
  extractSurfaces(first, positions, springs, serial);
  extractSurfaces(second, positions, springs, pair);
  const MeshTopology topology = meshTopology(one.mesh());
  RecordProperty("components", std::to_string(topology.components));
  EXPECT_EQ(topology.openEdges, 0u);
  EXPECT_GE(topology.components, 2u);
  EXPECT_EQ(one.mesh().vertices, two.mesh().vertices);
  EXPECT_EQ(one.mesh().triangles, two.mesh().triangles);
}

/// Every muscle's implicit surface at rest, extracted on `pool`.
std::vector<ImplicitSurface> restSurfaces(const PreparedScene& prepared, TaskPool& pool) {
  std::vector<ImplicitSurface> surfaces;
  std::vector<std::span<const btVector3>> positions;
  std::vector<std::span<const Spring>> springs;
  for (const auto& muscle : prepared.muscles) {
    surfaces.emplace_back(muscle);
    positions.push_back(muscle->restPositions);
    springs.push_back(muscle->springs);
  }
  std::vector<ImplicitSurface*> pointers;
  for (ImplicitSurface& surface : surfaces) pointers.push_back(&surface);
  extractSurfaces(pointers, positions, springs, pool);
  return surfaces;
}

TEST(ImplicitSurface, EveryThigh13MuscleIsClosedAndTheSameForOneThreadTwoAndAHostScheduler) {
  const LoadedScene scene = loadScene("thigh13", {"resolution=8"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  ASSERT_GE(prepared.muscles.size(), 2u);
  TaskPool serial(1), pair(2), host(1, testing::backwards());
  const std::vector<ImplicitSurface> one = restSurfaces(prepared, serial);
  for (TaskPool* pool : {&pair, &host}) {
    const std::vector<ImplicitSurface> other = restSurfaces(prepared, *pool);
    for (size_t m = 0; m < one.size(); ++m) {
      SCOPED_TRACE(prepared.muscles[m]->name + (pool == &host ? " on the host" : " on 2 threads"));
      EXPECT_GT(one[m].mesh().triangles.size(), 100u);
      EXPECT_EQ(meshTopology(one[m].mesh()).openEdges, 0u);
      EXPECT_EQ(one[m].mesh().vertices, other[m].mesh().vertices);
      EXPECT_EQ(one[m].mesh().triangles, other[m].mesh().triangles);
    }
  }
}

// At rest every thigh13 muscle's implicit surface lies within 1 mm of the skinned surface, both
// ways: the tendons' pointed ends, thinner than a grid cell, are met (the rest surface thickened
// beside the fixed particles, the vertices made there moved back onto it), the rest surface's
// pits, which no vertex moved to its nearest rest surface point reaches, are met (a vertex pinned
// to each), and the parts the particles cover thinly do not dip into the muscle (h widened to
// cover them). Without those, adductor longus dipped 3.5 mm and sartorius's tip lay 6.0 mm from
// the surface; without the pins, a pit of vastus medialis lay 1.02 mm from it.
TEST(ImplicitSurface, EveryThigh13MuscleAtRestLiesWithin1MmOfItsSkinnedSurface) {
  const LoadedScene scene = loadScene("thigh13", {"resolution=20"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  for (const auto& muscle : prepared.muscles) {
    SCOPED_TRACE(muscle->name);
    ImplicitSurface surface(muscle);
    surface.extract(muscle->restPositions);
    const auto [meanOut, worstOut] = distances(surface.mesh(), muscle->restSurface);
    const auto [meanIn, worstIn] = distances(muscle->restSurface, surface.mesh());
    RecordProperty(muscle->name + "_worst_mm", std::to_string(1000 * std::max(worstOut, worstIn)));
    EXPECT_LE(std::max(worstOut, worstIn), 1e-3);
    const MeshTopology topology = meshTopology(surface.mesh());
    EXPECT_EQ(topology.openEdges, 0u);
    EXPECT_EQ(topology.components, 1u);
  }
}

// Posed, no spring of thigh13 breaks: each muscle's surface stays one closed piece at every pose
// (the spread of the particles' maps where they deform near their attachments opened pieces
// off, and the tendons' pointed ends left beads of less than a grid cell).
TEST(ImplicitSurface, EveryPosedThigh13MuscleIsOneClosedPiece) {
  const LoadedScene scene = loadScene("thigh13", {"resolution=12"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  MuscleSystem system(scene.simulation);
  const SceneHandles handles = addScene(system, prepared);
  std::vector<ImplicitSurface> surfaces;
  std::vector<ImplicitSurface*> pointers;
  for (const auto& muscle : prepared.muscles) surfaces.emplace_back(muscle);
  for (ImplicitSurface& surface : surfaces) pointers.push_back(&surface);
  TaskPool pool(2);
  for (int pose = 0; pose < std::min(scene.poseCount, 7); ++pose) {
    for (size_t b = 0; b < handles.bones.size(); ++b)
      system.setBoneTransform(handles.bones[b], scene.bonePose(b, pose));
    system.step();
    std::vector<std::span<const btVector3>> positions;
    std::vector<std::span<const Spring>> springs;
    for (MuscleHandle muscle : handles.muscles) {
      ASSERT_EQ(system.tear(muscle).pieces, 1u);
      positions.push_back(system.positions(muscle));
      springs.push_back(system.settings(muscle).springs);
    }
    extractSurfaces(pointers, positions, springs, pool);
    for (size_t m = 0; m < surfaces.size(); ++m) {
      SCOPED_TRACE(prepared.muscles[m]->name + " at pose " + std::to_string(pose));
      const MeshTopology topology = meshTopology(surfaces[m].mesh());
      EXPECT_EQ(topology.openEdges, 0u);
      EXPECT_EQ(topology.components, 1u);
    }
  }
}

// Two tasks on one surface would share its grids: the same surface twice is refused.
TEST(ImplicitSurface, ExtractingOneSurfaceTwiceAtOnceIsAnInputError) {
  const auto muscle = firstMuscle("fusiform");
  ImplicitSurface surface(muscle);
  ImplicitSurface* const twice[] = {&surface, &surface};
  const std::span<const btVector3> positions[] = {muscle->restPositions, muscle->restPositions};
  const std::span<const Spring> springs[] = {muscle->springs, muscle->springs};
  TaskPool pool(2);
  EXPECT_THROW(extractSurfaces(twice, positions, springs, pool), InputError);
  EXPECT_TRUE(surface.mesh().triangles.empty());  // nothing ran
}

}  // namespace
}  // namespace fibremss
