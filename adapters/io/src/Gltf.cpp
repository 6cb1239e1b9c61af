#include "fibremss/Gltf.h"

#include <assimp/material.h>
#include <assimp/scene.h>

#include <assimp/Exporter.hpp>
#include <memory>
#include <stdexcept>
#include <string_view>

#include "fibremss/Output.h"

namespace fibremss {
namespace {

/// Area-weighted vertex normals of the mesh (unit length; +y for a vertex of no area).
void setNormals(aiMesh& mesh) {
  mesh.mNormals = new aiVector3D[mesh.mNumVertices];
  for (unsigned f = 0; f < mesh.mNumFaces; ++f) {
    const unsigned* v = mesh.mFaces[f].mIndices;
    const aiVector3D n = (mesh.mVertices[v[1]] - mesh.mVertices[v[0]]) ^
                         (mesh.mVertices[v[2]] - mesh.mVertices[v[0]]);
    for (int k = 0; k < 3; ++k) mesh.mNormals[v[k]] += n;
  }
  for (unsigned i = 0; i < mesh.mNumVertices; ++i) {
    aiVector3D& n = mesh.mNormals[i];
    n = n.SquareLength() > 0 ? n.Normalize() : aiVector3D(0, 1, 0);
  }
}

aiMesh* toAssimp(const GltfMesh& source, unsigned materialIndex) {
  auto mesh = std::make_unique<aiMesh>();
  mesh->mName = source.name;
  mesh->mMaterialIndex = materialIndex;
  mesh->mPrimitiveTypes = aiPrimitiveType_TRIANGLE;
  mesh->mNumVertices = unsigned(source.vertices.size());
  mesh->mVertices = new aiVector3D[mesh->mNumVertices];
  for (size_t i = 0; i < source.vertices.size(); ++i) {
    const btVector3& p = source.vertices[i];
    mesh->mVertices[i] = aiVector3D(float(p.x()), float(p.y()), float(p.z()));
  }
  mesh->mNumFaces = unsigned(source.triangles.size());
  mesh->mFaces = new aiFace[mesh->mNumFaces];
  for (size_t f = 0; f < source.triangles.size(); ++f) {
    aiFace& face = mesh->mFaces[f];
    face.mNumIndices = 3;
    face.mIndices = new unsigned[3];
    for (int k = 0; k < 3; ++k) {
      if (source.triangles[f][k] >= mesh->mNumVertices)
        throw std::runtime_error("glTF mesh '" + source.name + "': triangle " + std::to_string(f) +
                                 " names vertex " + std::to_string(source.triangles[f][k]) +
                                 " of " + std::to_string(mesh->mNumVertices));
      face.mIndices[k] = source.triangles[f][k];
    }
  }
  setNormals(*mesh);
  return mesh.release();
}

aiMaterial* material(const GltfMesh& source) {
  auto result = std::make_unique<aiMaterial>();
  const aiString name(source.name);
  result->AddProperty(&name, AI_MATKEY_NAME);
  const aiColor4D colour(source.colour[0], source.colour[1], source.colour[2], source.colour[3]);
  result->AddProperty(&colour, 1, AI_MATKEY_COLOR_DIFFUSE);
  result->AddProperty(&colour, 1, AI_MATKEY_BASE_COLOR);
  return result.release();
}

}  // namespace

void writeGlb(const std::string& path, std::span<const GltfMesh> meshes) {
  aiScene scene;  // owns (and deletes) everything attached below
  scene.mRootNode = new aiNode("fibremss");
  const auto count = unsigned(meshes.size());
  scene.mMeshes = new aiMesh*[count]();
  scene.mMaterials = new aiMaterial*[count]();
  scene.mRootNode->mChildren = new aiNode*[count]();
  for (unsigned m = 0; m < count; ++m) {
    scene.mMeshes[m] = toAssimp(meshes[m], m);
    scene.mNumMeshes = m + 1;
    scene.mMaterials[m] = material(meshes[m]);
    scene.mNumMaterials = m + 1;
    auto* node = new aiNode(meshes[m].name);
    node->mParent = scene.mRootNode;
    node->mNumMeshes = 1;
    node->mMeshes = new unsigned[1]{m};
    scene.mRootNode->mChildren[m] = node;
    scene.mRootNode->mNumChildren = m + 1;
  }
  Assimp::Exporter exporter;
  const aiExportDataBlob* blob = exporter.ExportToBlob(&scene, "glb2");
  if (!blob)
    throw std::runtime_error("cannot write " + path +
                             " as glTF (assimp: " + exporter.GetErrorString() + ")");
  writeFileAtomically(path, std::string_view(static_cast<const char*>(blob->data), blob->size));
}

}  // namespace fibremss
