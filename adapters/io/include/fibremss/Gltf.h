#pragma once
// Deformed surfaces for game engines, Blender and web pages: glTF 2.0 binary (.glb), one file
// per frame or one animated file for a whole run. Written by FibreMSS itself: only core glTF
// 2.0 (no extension), every accessor with its bounds, every buffer view 4-byte aligned.
#include <LinearMath/btVector3.h>

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace fibremss {

/// One named triangle mesh of a glTF scene (a node of the root, one mesh, one material).
struct GltfMesh {
  std::string name;                                     ///< node and mesh name
  std::span<const btVector3> vertices;                  ///< positions [m]
  std::span<const std::array<uint32_t, 3>> triangles;   ///< vertex indices
  std::array<float, 4> colour{0.8f, 0.8f, 0.8f, 1.0f};  ///< base colour, RGBA in 0..1
};

/// Writes `meshes` as one glTF 2.0 binary file, atomically (positions as glTF takes them: metres,
/// float; normals computed per vertex). Throws std::runtime_error when a triangle names a vertex
/// the mesh does not have.
void writeGlb(const std::string& path, std::span<const GltfMesh> meshes);

/// A run as one animated glTF 2.0 binary: every frame's meshes, each frame after the first a
/// morph target of the first frame's meshes, weighted in by an animation that reaches frame k at
/// its time (linear between frames: positions blend from one frame to the next).
class GltfAnimation {
 public:
  /// The meshes at `time` [s]: the same meshes (names, vertex counts, triangles) in every frame,
  /// times increasing. Throws std::runtime_error otherwise.
  void addFrame(double time, std::span<const GltfMesh> meshes);
  /// Writes the frames so far, atomically (a still scene when there is one frame).
  void write(const std::string& path) const;
  size_t frames() const { return times_.size(); }

 private:
  struct Mesh {
    std::string name;
    std::vector<std::array<uint32_t, 3>> triangles;
    std::array<float, 4> colour;
    std::vector<std::vector<float>> positions;  ///< per frame, x y z per vertex
  };
  std::vector<float> times_;
  std::vector<Mesh> meshes_;
};

}  // namespace fibremss
