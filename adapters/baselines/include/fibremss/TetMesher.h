#pragma once
// Tetrahedral meshes of closed surfaces for the FEM reference: the voxels whose centres lie
// inside the surface, each split into six positively oriented tetrahedra (Kuhn's
// subdivision along the cube diagonal, conforming between neighbouring cubes).
#include <LinearMath/btVector3.h>

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "fibremss/Geometry.h"

namespace fibremss {

/// A tetrahedral mesh; every tetrahedron (a, b, c, d) has (b−a)·((c−a)×(d−a)) > 0.
struct TetMesh {
  std::vector<btVector3> nodes;                     ///< node positions [m]
  std::vector<std::array<uint32_t, 4>> tetrahedra;  ///< node indices, positively oriented
  btScalar cellSize = 0;                            ///< voxel edge it was made with [m]
};

/// How fine the voxel grid is.
struct TetMesherDefinition {
  btScalar cellSize = 0;  ///< voxel edge [m]; 0: chosen so the surface holds ~targetCells voxels
  int targetCells = 300;  ///< voxels wanted when cellSize is 0
  int minCells = 24;      ///< finer grids are tried (up to 8 times) until at least this many
};

/// Signed volume of a tetrahedron, positive when positively oriented.
double tetrahedronVolume(const btVector3& a, const btVector3& b, const btVector3& c,
                         const btVector3& d);

/// Sum of the signed volumes of all tetrahedra of `mesh` at `positions` (its nodes by default).
double totalVolume(const TetMesh& mesh, std::span<const btVector3> positions = {});

/// Tetrahedralizes the closed surface (inside test: MeshDistance). Throws InputError when the
/// surface has no volume or no voxel centre falls inside it.
TetMesh tetrahedralize(const TriangleMesh& surface, const TetMesherDefinition& definition = {});

/// Points expressed in the tetrahedra: tetrahedron index and barycentric weights (summing to
/// 1; slightly outside the mesh they extrapolate from the nearest tetrahedron).
struct TetEmbedding {
  std::vector<uint32_t> tetrahedron;             ///< per point
  std::vector<std::array<btScalar, 4>> weights;  ///< per point, one per tetrahedron node
};

/// Embeds points (e.g. the muscle's surface vertices) in the mesh at its rest node positions.
TetEmbedding embed(const TetMesh& mesh, std::span<const btVector3> points);

/// The embedded points at deformed node positions.
void embeddedPositions(const TetMesh& mesh, const TetEmbedding& embedding,
                       std::span<const btVector3> nodePositions, std::vector<btVector3>& out);

}  // namespace fibremss
