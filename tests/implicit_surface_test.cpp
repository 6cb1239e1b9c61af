// The implicit surface (ImplicitSurface.h): closed (every edge shared by two triangles) on
// fusiform at rest and on the `tear` scene once torn, where it falls into pieces; on average
// within 1 mm of the skinned surface at rest, both ways, and nowhere farther than a grid cell
// (the pointed ends of the tendons, thinner than a cell, are lost); dented by a negative field;
// the same for one thread and two.
#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "fibremss/ImplicitSurface.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "fibremss/SceneSystem.h"

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
  extractSurfaces(first, positions, springs, 1);
  extractSurfaces(second, positions, springs, 2);
  const MeshTopology topology = meshTopology(one.mesh());
  RecordProperty("components", std::to_string(topology.components));
  EXPECT_EQ(topology.openEdges, 0u);
  EXPECT_GE(topology.components, 2u);
  EXPECT_EQ(one.mesh().vertices, two.mesh().vertices);
  EXPECT_EQ(one.mesh().triangles, two.mesh().triangles);
}

}  // namespace
}  // namespace fibremss
