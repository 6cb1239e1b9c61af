#pragma once
// Deformed surfaces for game engines and web pages: glTF 2.0 binary (.glb) through assimp's
// exporter ("glb2").
#include <LinearMath/btVector3.h>

#include <array>
#include <cstdint>
#include <span>
#include <string>

namespace fibremss {

/// One named triangle mesh of a glTF scene (a node of the root, one mesh, one material).
struct GltfMesh {
  std::string name;                                     ///< node and mesh name
  std::span<const btVector3> vertices;                  ///< positions [m]
  std::span<const std::array<uint32_t, 3>> triangles;   ///< vertex indices
  std::array<float, 4> colour{0.8f, 0.8f, 0.8f, 1.0f};  ///< base colour, RGBA in 0..1
};

/// Writes `meshes` as one glTF 2.0 binary file, atomically (positions as glTF takes them: metres,
/// float; normals computed per vertex). Throws std::runtime_error when assimp cannot export or
/// a triangle names a vertex the mesh does not have.
void writeGlb(const std::string& path, std::span<const GltfMesh> meshes);

}  // namespace fibremss
