// Surfaces in every other format (OBJ, STL, PLY, glTF, FBX, ...) through assimp. Only
// positions are kept, so identical positions are joined even where normals differ (STL).
#include <assimp/config.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <assimp/Importer.hpp>
#include <cmath>
#include <exception>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "MeshIOInternal.h"
#include "fibremss/Error.h"

namespace fibremss::meshio {
namespace {

/// Least bytes one value of a PLY property type takes (binary; ASCII takes at least 2: a digit
/// and a separator).
uint64_t plyTypeBytes(const std::string& type) {
  if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
  if (type == "int" || type == "uint" || type == "float" || type == "int32" || type == "uint32" ||
      type == "float32")
    return 4;
  if (type == "double" || type == "float64") return 8;
  return 1;
}

/// A PLY header's element counts against the bytes after it: assimp reserves memory for the
/// counts as declared (2 000 000 000 vertices in a 340-byte file would commit gigabytes).
void checkPlyCounts(const std::string& path) {
  constexpr size_t kHeaderLimit = 64 * 1024;
  std::ifstream file(path, std::ios::binary);
  std::string head(kHeaderLimit, '\0');
  file.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<size_t>(file.gcount()));
  const size_t end = head.find("end_header");
  if (head.rfind("ply", 0) != 0 || end == std::string::npos) return;  // assimp judges the rest
  const uint64_t size = std::filesystem::file_size(path);
  const uint64_t left = size - std::min<uint64_t>(head.find('\n', end) + 1, size);
  std::istringstream lines(head.substr(0, end));
  std::string line, name;
  bool ascii = false;
  uint64_t count = 0, bytesPerElement = 0;
  long double needed = 0;
  auto closeElement = [&] {
    needed += static_cast<long double>(count) * std::max<uint64_t>(bytesPerElement, 1);
    if (needed > static_cast<long double>(left))
      throw InputError(path, "header, element " + meshio::quoted(name),
                       "declares " + std::to_string(count) + " elements, which need at least " +
                           std::to_string(static_cast<uint64_t>(needed)) +
                           " bytes with the elements before them, but only " +
                           std::to_string(left) + " bytes follow the header");
  };
  while (std::getline(lines, line)) {
    std::istringstream words(line);
    std::string word, type;
    words >> word;
    if (word == "format") {
      words >> type;
      ascii = type == "ascii";
    } else if (word == "element") {
      if (!name.empty()) closeElement();
      if (!(words >> name >> count)) return;
      bytesPerElement = 0;
    } else if (word == "property" && !name.empty() && (words >> type)) {
      if (type == "list") words >> type;  // a list holds at least its count
      bytesPerElement += ascii ? 2 : plyTypeBytes(type);
    }
  }
  if (!name.empty()) closeElement();
}

/// An OFF header's vertex and face counts against the file's size: assimp reserves memory for
/// them as declared. An ASCII vertex takes at least 6 bytes ("0 0 0\n"), a face at least 2.
void checkOffCounts(const std::string& path) {
  std::ifstream file(path);
  std::string line, word;
  uint64_t vertices = 0, faces = 0;
  if (!std::getline(file, line)) return;
  std::istringstream first(line);
  first >> word;
  if (word.size() < 3 || word.compare(word.size() - 3, 3, "OFF") != 0) return;
  std::istringstream counts(line.substr(line.find(word) + word.size()));
  while (!(counts >> vertices >> faces)) {  // counts on the next line that is no comment
    if (!std::getline(file, line)) return;
    if (line.empty() || line[0] == '#') continue;
    counts = std::istringstream(line);
  }
  const long double needed = 6.0L * vertices + 2.0L * faces;
  const uint64_t size = std::filesystem::file_size(path);
  if (needed > static_cast<long double>(size))
    throw InputError(path, "header",
                     "declares " + std::to_string(vertices) + " vertices and " +
                         std::to_string(faces) + " faces, which need at least " +
                         std::to_string(static_cast<uint64_t>(needed)) +
                         " bytes, but the file has " + std::to_string(size));
}

}  // namespace

TriangleMesh readAssimpSurface(const std::string& path, double scale) {
  checkPlyCounts(path);
  checkOffCounts(path);
  Assimp::Importer importer;
  importer.SetPropertyInteger(AI_CONFIG_PP_RVC_FLAGS,
                              aiComponent_NORMALS | aiComponent_TANGENTS_AND_BITANGENTS |
                                  aiComponent_COLORS | aiComponent_TEXCOORDS |
                                  aiComponent_BONEWEIGHTS | aiComponent_ANIMATIONS |
                                  aiComponent_TEXTURES | aiComponent_LIGHTS | aiComponent_CAMERAS);
  constexpr unsigned kSteps = aiProcess_RemoveComponent | aiProcess_Triangulate |
                              aiProcess_JoinIdenticalVertices | aiProcess_PreTransformVertices |
                              aiProcess_ValidateDataStructure;
  const aiScene* scene = nullptr;
  try {
    scene = importer.ReadFile(path, kSteps);
  } catch (const std::exception& error) {
    throw InputError(path, "", std::string("cannot read the surface: ") + error.what());
  }
  if (!scene) {
    throw InputError(path, "",
                     "expected a surface mesh (" + surfaceFormatList() +
                         "); assimp says: " + importer.GetErrorString());
  }
  TriangleMesh mesh;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh& part = *scene->mMeshes[m];
    const size_t base = mesh.vertices.size();
    if (base + part.mNumVertices > UINT32_MAX) {
      throw InputError(path, "mesh " + std::to_string(m), "expected at most 2^32-1 vertices");
    }
    for (unsigned v = 0; v < part.mNumVertices; ++v) {
      const aiVector3D& p = part.mVertices[v];
      const btVector3 point(static_cast<btScalar>(double(p.x) * scale),
                            static_cast<btScalar>(double(p.y) * scale),
                            static_cast<btScalar>(double(p.z) * scale));
      mesh.vertices.push_back(point);
    }
    for (unsigned f = 0; f < part.mNumFaces; ++f) {
      const aiFace& face = part.mFaces[f];
      if (face.mNumIndices != 3) continue;  // points and lines carry no surface
      std::array<uint32_t, 3> triangle{};
      for (int k = 0; k < 3; ++k) {
        if (face.mIndices[k] >= part.mNumVertices) {
          throw InputError(path, "mesh " + std::to_string(m) + ", face " + std::to_string(f),
                           "expected vertex indices below " + std::to_string(part.mNumVertices) +
                               ", found " + std::to_string(face.mIndices[k]));
        }
        triangle[static_cast<size_t>(k)] = static_cast<uint32_t>(base + face.mIndices[k]);
      }
      mesh.triangles.push_back(triangle);
    }
  }
  if (mesh.triangles.empty()) {
    throw InputError(path, "",
                     "expected a surface with triangles, found " +
                         std::to_string(scene->mNumMeshes) + " meshes and no triangles");
  }
  return mesh;
}

namespace {

const MeshFormatRegistration registration({
    .name = "OBJ, STL, PLY, glTF, FBX, ...",
    .readSurface =
        [](const std::string& path, double scale) {
          return SurfaceRead{readAssimpSurface(path, scale), {}};
        },
    .fallback = true,
});

}  // namespace

}  // namespace fibremss::meshio
