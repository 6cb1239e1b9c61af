#include "fibremss/TetMesher.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "fibremss/Error.h"

namespace fibremss {

double tetrahedronVolume(const btVector3& a, const btVector3& b, const btVector3& c,
                         const btVector3& d) {
  const btVector3 u = b - a, v = c - a, w = d - a;
  const double ux = u.x(), uy = u.y(), uz = u.z();
  const double vx = v.x(), vy = v.y(), vz = v.z();
  const double wx = w.x(), wy = w.y(), wz = w.z();
  return (ux * (vy * wz - vz * wy) - uy * (vx * wz - vz * wx) + uz * (vx * wy - vy * wx)) / 6.0;
}

double totalVolume(const TetMesh& mesh, std::span<const btVector3> positions) {
  const std::span<const btVector3> x = positions.empty() ? mesh.nodes : positions;
  double volume = 0;
  for (const auto& t : mesh.tetrahedra)
    volume += tetrahedronVolume(x[t[0]], x[t[1]], x[t[2]], x[t[3]]);
  return volume;
}

namespace {

/// Voxel grid over the surface's bounds.
struct Grid {
  btVector3 origin;
  btScalar h = 0;
  int nx = 0, ny = 0, nz = 0;
  size_t cell(int i, int j, int k) const { return (size_t(k) * ny + j) * nx + i; }
  size_t node(int i, int j, int k) const { return (size_t(k) * (ny + 1) + j) * (nx + 1) + i; }
  btVector3 corner(int i, int j, int k) const {
    return origin + btVector3(btScalar(i), btScalar(j), btScalar(k)) * h;
  }
};

Grid makeGrid(const TriangleMesh& surface, btScalar h) {
  btVector3 lower, upper;
  pointBounds(surface.vertices, lower, upper);
  Grid grid;
  grid.h = h;
  const btVector3 extent = upper - lower;
  grid.nx = std::max(1, static_cast<int>(std::ceil(extent.x() / h)));
  grid.ny = std::max(1, static_cast<int>(std::ceil(extent.y() / h)));
  grid.nz = std::max(1, static_cast<int>(std::ceil(extent.z() / h)));
  // Centre the grid on the surface's bounds.
  const btVector3 span(grid.nx * h, grid.ny * h, grid.nz * h);
  grid.origin = (lower + upper - span) * btScalar(0.5);
  return grid;
}

/// The six tetrahedra of Kuhn's subdivision of a cube: corner bits (x = 1, y = 2, z = 4),
/// each a path 0 → one axis → two axes → 7.
constexpr std::array<std::array<int, 4>, 6> kKuhn = {
    {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}}};

TetMesh voxelize(const MeshDistance& inside, const Grid& grid) {
  TetMesh mesh;
  mesh.cellSize = grid.h;
  std::vector<uint32_t> nodeIndex(size_t(grid.nx + 1) * (grid.ny + 1) * (grid.nz + 1), UINT32_MAX);
  auto nodeAt = [&](int i, int j, int k) {
    uint32_t& index = nodeIndex[grid.node(i, j, k)];
    if (index == UINT32_MAX) {
      index = static_cast<uint32_t>(mesh.nodes.size());
      mesh.nodes.push_back(grid.corner(i, j, k));
    }
    return index;
  };
  for (int k = 0; k < grid.nz; ++k) {
    for (int j = 0; j < grid.ny; ++j) {
      for (int i = 0; i < grid.nx; ++i) {
        const btVector3 centre = grid.corner(i, j, k) + btVector3(1, 1, 1) * (grid.h / 2);
        if (!inside.inside(centre)) continue;
        std::array<uint32_t, 8> corners;
        for (int c = 0; c < 8; ++c)
          corners[c] = nodeAt(i + (c & 1), j + (c >> 1 & 1), k + (c >> 2 & 1));
        for (const auto& kuhn : kKuhn) {
          std::array<uint32_t, 4> t = {corners[kuhn[0]], corners[kuhn[1]], corners[kuhn[2]],
                                       corners[kuhn[3]]};
          const auto& x = mesh.nodes;
          if (tetrahedronVolume(x[t[0]], x[t[1]], x[t[2]], x[t[3]]) < 0) std::swap(t[2], t[3]);
          mesh.tetrahedra.push_back(t);
        }
      }
    }
  }
  return mesh;
}

/// Barycentric coordinates of p in tetrahedron t of `x`.
std::array<btScalar, 4> barycentric(std::span<const btVector3> x, const std::array<uint32_t, 4>& t,
                                    const btVector3& p) {
  const double whole = tetrahedronVolume(x[t[0]], x[t[1]], x[t[2]], x[t[3]]);
  std::array<btScalar, 4> w;
  w[0] = static_cast<btScalar>(tetrahedronVolume(p, x[t[1]], x[t[2]], x[t[3]]) / whole);
  w[1] = static_cast<btScalar>(tetrahedronVolume(x[t[0]], p, x[t[2]], x[t[3]]) / whole);
  w[2] = static_cast<btScalar>(tetrahedronVolume(x[t[0]], x[t[1]], p, x[t[3]]) / whole);
  w[3] = 1 - w[0] - w[1] - w[2];
  return w;
}

}  // namespace

TetMesh tetrahedralize(const TriangleMesh& surface, const TetMesherDefinition& definition) {
  const double volume = meshVolume(surface);
  if (!(volume > 0)) {
    throw InputError("surface", "", "a closed surface with outward normals and positive volume");
  }
  const MeshDistance inside(surface);
  btScalar h = definition.cellSize > 0
                   ? definition.cellSize
                   : static_cast<btScalar>(std::cbrt(volume / std::max(1, definition.targetCells)));
  TetMesh mesh = voxelize(inside, makeGrid(surface, h));
  for (int attempt = 0; attempt < 8 && mesh.tetrahedra.size() < 6u * definition.minCells;
       ++attempt) {
    h *= btScalar(0.75);
    mesh = voxelize(inside, makeGrid(surface, h));
  }
  if (mesh.tetrahedra.empty()) {
    throw InputError("surface", "",
                     "no voxel of edge " + std::to_string(h) +
                         " m lies inside the surface (too thin to tetrahedralize)");
  }
  return mesh;
}

TetEmbedding embed(const TetMesh& mesh, std::span<const btVector3> points) {
  // Tetrahedra by voxel: the six of a cube are consecutive, so a voxel's first node (its
  // lowest corner, node of Kuhn index 0) identifies it. Search nearby voxels first.
  const btScalar h = mesh.cellSize;
  const size_t cubes = mesh.tetrahedra.size() / 6;
  std::vector<btVector3> cubeCentres(cubes);
  for (size_t c = 0; c < cubes; ++c) {
    const auto& t = mesh.tetrahedra[6 * c];
    cubeCentres[c] = (mesh.nodes[t[0]] + mesh.nodes[t[3]]) * btScalar(0.5);
  }
  TetEmbedding embedding;
  embedding.tetrahedron.resize(points.size());
  embedding.weights.resize(points.size());
  std::vector<std::pair<btScalar, size_t>> near;
  for (size_t p = 0; p < points.size(); ++p) {
    // The cubes within reach, nearest first; the first containing tetrahedron wins, else the
    // one the point is least outside of.
    near.clear();
    btScalar reach = 2 * h;
    while (near.empty()) {
      for (size_t c = 0; c < cubes; ++c) {
        const btScalar d = (cubeCentres[c] - points[p]).length();
        if (d <= reach) near.emplace_back(d, c);
      }
      reach *= 2;
    }
    std::sort(near.begin(), near.end());
    btScalar best = -std::numeric_limits<btScalar>::infinity();
    for (const auto& [distance, cube] : near) {
      for (size_t t = 6 * cube; t < 6 * cube + 6; ++t) {
        const auto w = barycentric(mesh.nodes, mesh.tetrahedra[t], points[p]);
        const btScalar worst = *std::min_element(w.begin(), w.end());
        if (worst > best) {
          best = worst;
          embedding.tetrahedron[p] = static_cast<uint32_t>(t);
          embedding.weights[p] = w;
        }
      }
      if (best >= -1e-5f) break;
    }
  }
  return embedding;
}

void embeddedPositions(const TetMesh& mesh, const TetEmbedding& embedding,
                       std::span<const btVector3> nodePositions, std::vector<btVector3>& out) {
  out.resize(embedding.tetrahedron.size());
  for (size_t p = 0; p < out.size(); ++p) {
    const auto& t = mesh.tetrahedra[embedding.tetrahedron[p]];
    const auto& w = embedding.weights[p];
    out[p] = nodePositions[t[0]] * w[0] + nodePositions[t[1]] * w[1] + nodePositions[t[2]] * w[2] +
             nodePositions[t[3]] * w[3];
  }
}

}  // namespace fibremss
