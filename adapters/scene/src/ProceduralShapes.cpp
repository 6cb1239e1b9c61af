#include <algorithm>
#include <cmath>
#include <map>
#include <utility>

#include "fibremss/Procedural.h"

namespace fibremss {

TriangleMesh makeEllipsoid(const btVector3& centre, const btVector3& radii, int subdivisions) {
  // Icosahedron, outward counter-clockwise faces, then midpoint subdivision on the unit sphere.
  const double g = (1 + std::sqrt(5.0)) / 2;
  std::vector<btVector3> unit = {
      {-1, btScalar(g), 0}, {1, btScalar(g), 0}, {-1, btScalar(-g), 0}, {1, btScalar(-g), 0},
      {0, -1, btScalar(g)}, {0, 1, btScalar(g)}, {0, -1, btScalar(-g)}, {0, 1, btScalar(-g)},
      {btScalar(g), 0, -1}, {btScalar(g), 0, 1}, {btScalar(-g), 0, -1}, {btScalar(-g), 0, 1}};
  for (auto& v : unit) v.normalize();
  std::vector<std::array<uint32_t, 3>> faces = {
      {0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
      {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
      {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int level = 0; level < subdivisions; ++level) {
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> midpoints;
    auto midpoint = [&](uint32_t a, uint32_t b) {
      const auto key = std::minmax(a, b);
      const auto found = midpoints.find(key);
      if (found != midpoints.end()) return found->second;
      unit.push_back(((unit[a] + unit[b]) * btScalar(0.5)).normalized());
      return midpoints[key] = uint32_t(unit.size() - 1);
    };
    std::vector<std::array<uint32_t, 3>> finer;
    finer.reserve(faces.size() * 4);
    for (const auto& [a, b, c] : faces) {
      const uint32_t ab = midpoint(a, b), bc = midpoint(b, c), ca = midpoint(c, a);
      finer.push_back({a, ab, ca});
      finer.push_back({b, bc, ab});
      finer.push_back({c, ca, bc});
      finer.push_back({ab, bc, ca});
    }
    faces = std::move(finer);
  }
  TriangleMesh mesh;
  mesh.vertices.reserve(unit.size());
  for (const auto& v : unit) mesh.vertices.push_back(centre + v * radii);
  mesh.triangles = std::move(faces);
  return mesh;
}

TriangleMesh makeBox(const btVector3& centre, const btVector3& size,
                     const std::array<int, 3>& divisions) {
  const std::array<int, 3> n = {std::max(1, divisions[0]), std::max(1, divisions[1]),
                                std::max(1, divisions[2])};
  // Lattice coordinates per axis, shared by every face so that edges weld exactly.
  std::array<std::vector<btScalar>, 3> coordinates;
  for (int axis = 0; axis < 3; ++axis)
    for (int i = 0; i <= n[axis]; ++i)
      coordinates[axis].push_back(centre[axis] - size[axis] / 2 + size[axis] * i / n[axis]);
  TriangleMesh mesh;
  std::map<std::array<int, 3>, uint32_t> index;
  auto vertex = [&](const std::array<int, 3>& key) {
    const auto found = index.find(key);
    if (found != index.end()) return found->second;
    mesh.vertices.emplace_back(coordinates[0][key[0]], coordinates[1][key[1]],
                               coordinates[2][key[2]]);
    return index[key] = uint32_t(mesh.vertices.size() - 1);
  };
  // Each face: fixed axis and side, (u, v) axes with u × v pointing outward.
  struct Face {
    int fixed, u, v;
    bool upper;
  };
  const Face faces[6] = {{0, 1, 2, true},  {0, 2, 1, false}, {1, 2, 0, true},
                         {1, 0, 2, false}, {2, 0, 1, true},  {2, 1, 0, false}};
  for (const Face& face : faces)
    for (int i = 0; i < n[face.u]; ++i)
      for (int j = 0; j < n[face.v]; ++j) {
        auto key = [&](int du, int dv) {
          std::array<int, 3> k{};
          k[face.fixed] = face.upper ? n[face.fixed] : 0;
          k[face.u] = i + du;
          k[face.v] = j + dv;
          return vertex(k);
        };
        const uint32_t a = key(0, 0), b = key(1, 0), c = key(1, 1), d = key(0, 1);
        mesh.triangles.push_back({a, b, c});
        mesh.triangles.push_back({a, c, d});
      }
  return mesh;
}

FibreSet ellipsoidChords(const btVector3& centre, const btVector3& radii, const btVector3& axis,
                         int count, DiskPattern pattern, double inset, int samples, int* columns) {
  const btVector3 direction = axis.normalized();
  btVector3 e1, e2;
  btPlaneSpace1(direction, e1, e2);
  // Extent of the ellipsoid along a unit direction d: 1 / |d / radii|.
  auto extent = [&radii](const btVector3& d) { return 1.0 / double((d / radii).length()); };
  const double across1 = extent(e1), across2 = extent(e2);
  const int n = std::max(2, samples);
  FibreSet fibres;
  std::vector<btVector3> polyline(n);
  for (const auto& [u, v] : diskPoints(count, pattern, columns)) {
    // Offsets reach 85 % of the inset cross-section so that rim fibres keep some length.
    const btVector3 offset =
        e1 * btScalar(0.85 * inset * u * across1) + e2 * btScalar(0.85 * inset * v * across2);
    // Solve |(offset + s·direction) / radii| = inset for the chord's two ends.
    const btVector3 o = offset / radii, d = direction / radii;
    const double a = d.dot(d), b = 2 * o.dot(d), c = o.dot(o) - inset * inset;
    const double half = std::sqrt(std::max(0.0, b * b - 4 * a * c)) / (2 * a);
    const double middle = -b / (2 * a);
    for (int k = 0; k < n; ++k) {
      const double s = middle - half + 2 * half * k / (n - 1);
      polyline[k] = centre + offset + direction * btScalar(s);
    }
    fibres.addFibre(polyline);
  }
  return fibres;
}

}  // namespace fibremss
