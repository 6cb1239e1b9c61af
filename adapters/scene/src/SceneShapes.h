#pragma once
// Internal to the scene loader: procedural meshes and fibres from {"generator": {...}} entries.
#include <optional>

#include "SceneFields.h"
#include "fibremss/Geometry.h"
#include "fibremss/Procedural.h"

namespace fibremss::scene {

/// A generated surface and what fibre generators need to know about it.
struct Shape {
  TriangleMesh mesh;          ///< closed surface [m]
  std::optional<Tube> tube;   ///< set for "tube" generators
  bool ellipsoid = false;     ///< set for "ellipsoid" generators
  btVector3 centre{0, 0, 0};  ///< ellipsoid centre [m]
  btVector3 radii{0, 0, 0};   ///< ellipsoid radii [m]
};

/// Reads a mesh generator ({"type": "tube" | "ellipsoid" | "box", ...}); lengths in scene
/// units, multiplied by `scale` to metres.
Shape generateShape(Fields& generator, double scale);

/// Reads a fibre generator ({"type": "tube" | "chords", ...}) and makes `count` fibres through
/// `surface` (which must come from a matching generator). `lattice`: the spring layout needs a
/// fibre grid ("pattern": "auto" then means a grid). `columns` receives the grid's columns.
FibreSet generateFibres(Fields& generator, const Shape* surface, int count, bool lattice,
                        int* columns);

}  // namespace fibremss::scene
