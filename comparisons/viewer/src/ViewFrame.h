#pragma once
// What the viewer draws at one moment, whatever it comes from (a live simulation or a run's
// frames): muscle surfaces with arrays to colour them by, and bones.
#include <LinearMath/btTransform.h>
#include <LinearMath/btVector3.h>

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace fibremss::viewer {

using Triangles = std::vector<std::array<uint32_t, 3>>;

/// One triangle mesh: its vertices placed by `transform`, and per-vertex arrays.
struct ViewMesh {
  std::string name;                                    ///< muscle or bone name
  std::vector<btVector3> vertices;                     ///< vertex positions [m]
  std::shared_ptr<const Triangles> triangles;          ///< vertex indices, three per triangle
  btTransform transform = btTransform::getIdentity();  ///< maps `vertices` to the world
  /// Named per-vertex arrays (e.g. "fibre_stretch" [1], "displacement" [scene units]).
  std::vector<std::pair<std::string, std::vector<float>>> arrays;

  /// The array called `arrayName`, or nullptr.
  const std::vector<float>* array(const std::string& arrayName) const {
    for (const auto& [key, values] : arrays)
      if (key == arrayName) return &values;
    return nullptr;
  }
};

/// Everything drawn at one moment.
struct ViewFrame {
  std::vector<ViewMesh> muscles;  ///< deformed muscle surfaces
  std::vector<ViewMesh> bones;    ///< bone meshes at rest, placed by their transforms
  std::vector<ViewMesh> tools;    ///< the pointer's tools (a probe), placed by their transforms
  std::string lengthUnit = "m";   ///< unit of the length arrays: the scene's ("mm" or "m")
};

}  // namespace fibremss::viewer
