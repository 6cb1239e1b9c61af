// glTF 2.0 output: a .glb is read back by assimp's glTF importer with every mesh, its vertex
// count and positions, and keeps the rules of the glTF 2.0 specification a validator checks
// (GlbRules); `fibremss run --format gltf` writes one per frame with every muscle surface and
// bone, and run.glb animating them.
#include "fibremss/Gltf.h"

#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <gtest/gtest.h>

#include <assimp/Importer.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
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

/// A .glb's JSON and binary chunks.
struct Glb {
  nlohmann::json gltf;
  std::string binary;
};

Glb readGlb(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  const std::string file((std::istreambuf_iterator<char>(in)), {});
  const auto word = [&](size_t at) {
    uint32_t value = 0;
    if (at + 4 <= file.size()) std::memcpy(&value, file.data() + at, 4);
    return value;
  };
  Glb glb;
  EXPECT_EQ(word(0), 0x46546C67u);  // "glTF"
  EXPECT_EQ(word(4), 2u);
  EXPECT_EQ(word(8), file.size());
  const uint32_t jsonLength = word(12);
  EXPECT_EQ(word(16), 0x4E4F534Au);  // "JSON"
  EXPECT_EQ(jsonLength % 4, 0u);
  if (20 + jsonLength + 8 > file.size()) return glb;
  glb.gltf = nlohmann::json::parse(file.substr(20, jsonLength));
  const size_t bin = 20 + jsonLength;
  EXPECT_EQ(word(bin + 4), 0x004E4942u);  // "BIN"
  EXPECT_EQ(word(bin) % 4, 0u);
  glb.binary = file.substr(bin + 8, word(bin));
  return glb;
}

size_t componentBytes(int type) {
  return type == 5126 || type == 5125 ? 4 : type == 5123 || type == 5122 ? 2 : 1;
}

size_t componentCount(const std::string& type) {
  const std::map<std::string, size_t> counts{
      {"SCALAR", 1}, {"VEC2", 2}, {"VEC3", 3}, {"VEC4", 4}, {"MAT4", 16}};
  return counts.count(type) ? counts.at(type) : 0;
}

/// An accessor's float values (the tests' files hold floats and unsigned ints only).
std::vector<double> accessorValues(const Glb& glb, size_t index) {
  const auto& accessor = glb.gltf["accessors"][index];
  const auto& view = glb.gltf["bufferViews"][accessor["bufferView"].get<size_t>()];
  const size_t start =
      view.value("byteOffset", size_t(0)) + accessor.value("byteOffset", size_t(0));
  const size_t n = accessor["count"].get<size_t>() * componentCount(accessor["type"]);
  std::vector<double> values(n);
  for (size_t i = 0; i < n && start + 4 * i + 4 <= glb.binary.size(); ++i) {
    if (accessor["componentType"] == 5126) {
      float value;
      std::memcpy(&value, glb.binary.data() + start + 4 * i, 4);
      values[i] = value;
    } else {
      uint32_t value;
      std::memcpy(&value, glb.binary.data() + start + 4 * i, 4);
      values[i] = value;
    }
  }
  return values;
}

/// The rules of the glTF 2.0 specification that a validator reports as errors or warnings and
/// that these files could break: buffers, views and accessors in range and aligned; every
/// POSITION accessor (morph targets included) and every animation input with exact bounds;
/// animation inputs strictly increasing; outputs as long as inputs times the targets; every
/// declared extension used; indices within the vertices; normals of unit length.
void expectGlbRules(const Glb& glb) {
  const nlohmann::json& gltf = glb.gltf;
  EXPECT_EQ(gltf["asset"]["version"], "2.0");
  ASSERT_EQ(gltf["buffers"].size(), 1u);
  EXPECT_EQ(gltf["buffers"][0]["byteLength"].get<size_t>(), glb.binary.size());
  for (const auto& view : gltf["bufferViews"]) {
    EXPECT_GT(view["byteLength"].get<size_t>(), 0u);
    EXPECT_LE(view.value("byteOffset", size_t(0)) + view["byteLength"].get<size_t>(),
              glb.binary.size());
  }
  for (const auto& accessor : gltf["accessors"]) {
    const auto& view = gltf["bufferViews"][accessor["bufferView"].get<size_t>()];
    const size_t bytes = componentBytes(accessor["componentType"]);
    const size_t offset =
        view.value("byteOffset", size_t(0)) + accessor.value("byteOffset", size_t(0));
    EXPECT_EQ(offset % bytes, 0u) << accessor;
    EXPECT_LE(accessor.value("byteOffset", size_t(0)) +
                  accessor["count"].get<size_t>() * componentCount(accessor["type"]) * bytes,
              view["byteLength"].get<size_t>());
  }
  const auto expectBounds = [&](size_t index) {
    const auto& accessor = gltf["accessors"][index];
    ASSERT_TRUE(accessor.contains("min") && accessor.contains("max")) << index;
    const std::vector<double> values = accessorValues(glb, index);
    const size_t components = componentCount(accessor["type"]);
    for (size_t c = 0; c < components; ++c) {
      double low = INFINITY, high = -INFINITY;
      for (size_t i = c; i < values.size(); i += components)
        low = std::min(low, values[i]), high = std::max(high, values[i]);
      EXPECT_EQ(float(accessor["min"][c].get<double>()), float(low)) << index;
      EXPECT_EQ(float(accessor["max"][c].get<double>()), float(high)) << index;
    }
  };
  for (const auto& mesh : gltf["meshes"])
    for (const auto& primitive : mesh["primitives"]) {
      const size_t position = primitive["attributes"]["POSITION"];
      const size_t vertices = gltf["accessors"][position]["count"];
      expectBounds(position);
      for (const auto& target : primitive.value("targets", nlohmann::json::array()))
        expectBounds(target["POSITION"]);
      EXPECT_EQ(mesh.value("weights", nlohmann::json::array()).size(),
                primitive.value("targets", nlohmann::json::array()).size());
      for (double index : accessorValues(glb, primitive["indices"])) EXPECT_LT(index, vertices);
      const std::vector<double> normals = accessorValues(glb, primitive["attributes"]["NORMAL"]);
      for (size_t i = 0; i + 2 < normals.size(); i += 3)
        EXPECT_NEAR(std::hypot(normals[i], normals[i + 1], normals[i + 2]), 1.0, 5e-4) << i;
    }
  for (const auto& animation : gltf.value("animations", nlohmann::json::array()))
    for (const auto& channel : animation["channels"]) {
      const auto& sampler = animation["samplers"][channel["sampler"].get<size_t>()];
      expectBounds(sampler["input"]);
      const std::vector<double> times = accessorValues(glb, sampler["input"]);
      for (size_t i = 1; i < times.size(); ++i) EXPECT_GT(times[i], times[i - 1]) << i;
      const auto& node = gltf["nodes"][channel["target"]["node"].get<size_t>()];
      const size_t targets = gltf["meshes"][node["mesh"].get<size_t>()]["weights"].size();
      EXPECT_EQ(channel["target"]["path"], "weights");
      EXPECT_EQ(gltf["accessors"][sampler["output"].get<size_t>()]["count"].get<size_t>(),
                times.size() * targets);
    }
  // Declared extensions: each must be used by some object (these files use none).
  EXPECT_FALSE(gltf.contains("extensionsUsed")) << gltf["extensionsUsed"];
  EXPECT_FALSE(gltf.contains("extensionsRequired"));
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
  expectGlbRules(readGlb(path));
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
  expectGlbRules(readGlb(glb));
}

/// assimp's glTF importer reads DIR/run.glb as `frames` frames: every mesh with a morph target
/// per frame after the first, at that frame's positions (as DIR/frame_*.glb read by assimp), and
/// one animation that weights the targets in, a key per frame.
void expectAssimpReadsTheAnimation(const fs::path& dir, unsigned frames) {
  Assimp::Importer importer;
  const aiScene* scene = importer.ReadFile((dir / "run.glb").string(), 0);
  ASSERT_NE(scene, nullptr) << importer.GetErrorString();
  const auto meshes = meshesByName(*scene);
  for (unsigned k = 1; k < frames; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%05u.glb", k);
    Assimp::Importer frameImporter;
    const aiScene* frame = frameImporter.ReadFile((dir / name).string(), 0);
    ASSERT_NE(frame, nullptr) << frameImporter.GetErrorString();
    for (const auto& [meshName, expected] : meshesByName(*frame)) {
      ASSERT_EQ(meshes.count(meshName), 1u) << meshName;
      const aiMesh& mesh = *meshes.at(meshName);
      ASSERT_EQ(mesh.mNumAnimMeshes, frames - 1) << meshName;
      const aiAnimMesh& target = *mesh.mAnimMeshes[k - 1];
      ASSERT_EQ(target.mNumVertices, expected->mNumVertices) << meshName;
      for (unsigned i = 0; i < target.mNumVertices; ++i)
        for (int c = 0; c < 3; ++c)
          EXPECT_NEAR(target.mVertices[i][c], expected->mVertices[i][c], 1e-6)
              << meshName << " frame " << k << " vertex " << i;
    }
  }
  ASSERT_EQ(scene->mNumAnimations, 1u);
  const aiAnimation& animation = *scene->mAnimations[0];
  EXPECT_EQ(animation.mNumMorphMeshChannels, meshes.size());
  for (unsigned c = 0; c < animation.mNumMorphMeshChannels; ++c) {
    const aiMeshMorphAnim& channel = *animation.mMorphMeshChannels[c];
    ASSERT_EQ(channel.mNumKeys, frames) << channel.mName.C_Str();
    for (unsigned k = 1; k < frames; ++k)
      EXPECT_GT(channel.mKeys[k].mTime, channel.mKeys[k - 1].mTime) << channel.mName.C_Str();
  }
}

TEST(Gltf, RunWritesOneAnimatedGlbWhoseFramesAreThePerFrameFiles) {
  testing::TemporaryDirectory out("fibremss_gltf_animated");
  const auto result = testing::runProcess(std::string(FIBREMSS_CLI) +
                                          " run fusiform --steps 3 --frame-every 1 --format gltf "
                                          "--out " +
                                          out.path().string());
  ASSERT_EQ(result.exitCode, 0) << result.output;
  const Glb animated = readGlb(out.path() / "gltf" / "run.glb");
  expectGlbRules(animated);
  ASSERT_EQ(animated.gltf["animations"].size(), 1u);
  const auto& gltf = animated.gltf;
  // Frame k is the first frame's positions plus morph target k-1 (weight 1 at frame k's time).
  for (int k = 1; k < 3; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%05d.glb", k);
    const Glb frame = readGlb(out.path() / "gltf" / name);
    ASSERT_EQ(frame.gltf["meshes"].size(), gltf["meshes"].size());
    for (size_t m = 0; m < gltf["meshes"].size(); ++m) {
      const auto& primitive = gltf["meshes"][m]["primitives"][0];
      const std::vector<double> base =
          accessorValues(animated, primitive["attributes"]["POSITION"]);
      const std::vector<double> moved =
          accessorValues(animated, primitive["targets"][k - 1]["POSITION"]);
      const std::vector<double> expected =
          accessorValues(frame, frame.gltf["meshes"][m]["primitives"][0]["attributes"]["POSITION"]);
      ASSERT_EQ(base.size(), expected.size());
      for (size_t i = 0; i < base.size(); ++i)
        EXPECT_NEAR(base[i] + moved[i], expected[i], 1e-6) << "frame " << k << " mesh " << m;
    }
  }
  const auto& sampler = gltf["animations"][0]["samplers"][0];
  EXPECT_EQ(gltf["accessors"][sampler["input"].get<size_t>()]["count"], 3);
  EXPECT_EQ(sampler["interpolation"], "LINEAR");
  expectAssimpReadsTheAnimation(out.path() / "gltf", 3);
}

}  // namespace
}  // namespace fibremss
