// glTF 2.0 output (issue 21): a .glb written through assimp's exporter is read back by assimp's
// glTF importer with every mesh, its vertex count and positions; `fibremss run --format gltf`
// writes one per frame with every muscle surface and bone.
#include "fibremss/Gltf.h"

#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <gtest/gtest.h>

#include <assimp/Importer.hpp>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "fibremss/MeshIO.h"
#include "fibremss/Scene.h"
#include "support/Process.h"

namespace fibremss {
namespace {

namespace fs = std::filesystem;

/// The meshes of a glTF file by name, as assimp's importer reads them.
std::map<std::string, const aiMesh*> meshesByName(const aiScene& scene) {
  std::map<std::string, const aiMesh*> meshes;
  for (unsigned m = 0; m < scene.mNumMeshes; ++m)
    meshes[scene.mMeshes[m]->mName.C_Str()] = scene.mMeshes[m];
  return meshes;
}

TEST(Gltf, AGlbRoundTripsThroughAssimpsImporter) {
  testing::TemporaryDirectory dir("fibremss_gltf");
  // A tetrahedron and a bent quad, at positions that are not round in float.
  const std::vector<btVector3> tetra{{0.0125f, -0.003f, 0.25f},
                                     {0.0711f, 0.001f, 0.25f},
                                     {0.02f, 0.05f, 0.26f},
                                     {0.03f, 0.02f, 0.3f}};
  const std::vector<std::array<uint32_t, 3>> tetraFaces{{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  const std::vector<btVector3> quad{{-1, 0, 0}, {1, 0, 0}, {1, 1, 0.5f}, {-1, 1, 0.25f}};
  const std::vector<std::array<uint32_t, 3>> quadFaces{{0, 1, 2}, {0, 2, 3}};
  const GltfMesh meshes[] = {{"muscle", tetra, tetraFaces, {1, 0, 0, 1}},
                             {"bone", quad, quadFaces, {0.9f, 0.9f, 0.8f, 1}}};
  const std::string path = (dir.path() / "two.glb").string();
  writeGlb(path, meshes);

  Assimp::Importer importer;
  const aiScene* scene = importer.ReadFile(path, 0);
  ASSERT_NE(scene, nullptr) << importer.GetErrorString();
  const auto read = meshesByName(*scene);
  ASSERT_EQ(read.size(), 2u);
  for (const GltfMesh& written : meshes) {
    SCOPED_TRACE(written.name);
    ASSERT_EQ(read.count(written.name), 1u);
    const aiMesh& mesh = *read.at(written.name);
    ASSERT_EQ(mesh.mNumVertices, written.vertices.size());
    ASSERT_EQ(mesh.mNumFaces, written.triangles.size());
    for (unsigned i = 0; i < mesh.mNumVertices; ++i)
      for (int k = 0; k < 3; ++k)
        EXPECT_FLOAT_EQ(mesh.mVertices[i][k], float(written.vertices[i][k]));
    for (unsigned f = 0; f < mesh.mNumFaces; ++f) {
      ASSERT_EQ(mesh.mFaces[f].mNumIndices, 3u);
      for (int k = 0; k < 3; ++k) EXPECT_EQ(mesh.mFaces[f].mIndices[k], written.triangles[f][k]);
    }
    ASSERT_TRUE(mesh.HasNormals());
  }
  // A triangle naming a missing vertex is an error, and nothing is written.
  const std::vector<std::array<uint32_t, 3>> bad{{0, 1, 4}};
  const GltfMesh broken[] = {{"broken", quad, bad}};
  EXPECT_THROW(writeGlb((dir.path() / "broken.glb").string(), broken), std::runtime_error);
  EXPECT_FALSE(fs::exists(dir.path() / "broken.glb"));
}

TEST(Gltf, RunWritesAGlbPerFrameWithTheDeformedSurfaces) {
  testing::TemporaryDirectory out("fibremss_gltf_run");
  const auto result = testing::runProcess(std::string(FIBREMSS_CLI) +
                                          " run fusiform --steps 2 --frame-every 1 --format "
                                          "gltf,vtk --out " +
                                          out.path().string());
  ASSERT_EQ(result.exitCode, 0) << result.output;
  // Both formats; the glb of the last frame holds the muscle's deformed surface, the same
  // vertices in metres as the .vtp holds in the scene's millimetres.
  const fs::path glb = out.path() / "gltf" / "frame_00001.glb";
  ASSERT_TRUE(fs::exists(out.path() / "gltf" / "frame_00000.glb"));
  ASSERT_TRUE(fs::exists(glb));
  Assimp::Importer importer;
  const aiScene* scene = importer.ReadFile(glb.string(), 0);
  ASSERT_NE(scene, nullptr) << importer.GetErrorString();
  const auto meshes = meshesByName(*scene);
  ASSERT_EQ(meshes.count("muscle0_fusiform"), 1u);
  const aiMesh& muscle = *meshes.at("muscle0_fusiform");
  const TriangleMesh frame =
      loadSurface((out.path() / "frames" / "muscle0_fusiform_surface_00001.vtp").string());
  ASSERT_EQ(muscle.mNumVertices, frame.vertices.size());
  for (unsigned i = 0; i < muscle.mNumVertices; ++i)
    for (int k = 0; k < 3; ++k)
      EXPECT_NEAR(1000.0 * muscle.mVertices[i][k], frame.vertices[i][k], 1e-3) << i;
  EXPECT_EQ(meshes.size(), 1 + loadScene("fusiform").bones.size());  // the muscle, every bone
}

}  // namespace
}  // namespace fibremss
