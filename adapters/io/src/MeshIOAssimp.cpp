// Surfaces in every other format (OBJ, STL, PLY, glTF, FBX, ...) through assimp. Only
// positions are kept, so identical positions are joined even where normals differ (STL).
#include <assimp/config.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <assimp/Importer.hpp>
#include <cmath>
#include <exception>

#include "MeshIOInternal.h"
#include "fibremss/Error.h"

namespace fibremss::meshio {

TriangleMesh readAssimpSurface(const std::string& path, double scale) {
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
                     std::string("expected a surface mesh (legacy VTK, OBJ, STL, PLY, glTF, FBX, "
                                 "...); assimp says: ") +
                         importer.GetErrorString());
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

}  // namespace fibremss::meshio
