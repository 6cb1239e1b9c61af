// repairSurface(): welds near-coincident vertices, drops triangles that repeat another, and
// closes small holes, for surfaces exported with cracks (OpenSim's coarse bone geometry).
#include <algorithm>
#include <cmath>
#include <map>
#include <tuple>

#include "MeshIOInternal.h"
#include "fibremss/MeshIO.h"

namespace fibremss::meshio {
namespace {

using Cell = std::tuple<long long, long long, long long>;

Cell cellOf(const btVector3& p, double size) {
  return {(long long)std::floor(p.x() / size), (long long)std::floor(p.y() / size),
          (long long)std::floor(p.z() / size)};
}

/// Each vertex within `distance` of an earlier kept vertex becomes that vertex and leaves the
/// vertex list; returns how many did.
size_t weld(TriangleMesh& mesh, double distance) {
  std::map<Cell, std::vector<uint32_t>> kept;
  std::vector<uint32_t> target(mesh.vertices.size());
  size_t welded = 0;
  for (uint32_t i = 0; i < mesh.vertices.size(); ++i) {
    const btVector3& p = mesh.vertices[i];
    const auto [cx, cy, cz] = cellOf(p, distance);
    target[i] = i;
    for (long long dx = -1; dx <= 1 && target[i] == i; ++dx)
      for (long long dy = -1; dy <= 1 && target[i] == i; ++dy)
        for (long long dz = -1; dz <= 1 && target[i] == i; ++dz) {
          const auto found = kept.find({cx + dx, cy + dy, cz + dz});
          if (found == kept.end()) continue;
          for (const uint32_t j : found->second)
            if (double(p.distance(mesh.vertices[j])) <= distance) {
              target[i] = j;
              break;
            }
        }
    if (target[i] == i)
      kept[{cx, cy, cz}].push_back(i);
    else
      ++welded;
  }
  std::vector<uint32_t> renumbered(mesh.vertices.size());
  std::vector<btVector3> vertices;
  for (uint32_t i = 0; i < mesh.vertices.size(); ++i) {
    if (target[i] != i) continue;
    renumbered[i] = uint32_t(vertices.size());
    vertices.push_back(mesh.vertices[i]);
  }
  for (auto& triangle : mesh.triangles)
    for (uint32_t& index : triangle) index = renumbered[target[index]];
  mesh.vertices = std::move(vertices);
  return welded;
}

/// Drops triangles with a repeated vertex and triangles over the same three vertices as an
/// earlier one; returns how many.
size_t dropRepeated(TriangleMesh& mesh) {
  std::vector<std::array<uint32_t, 3>> seen, kept;
  for (const auto& triangle : mesh.triangles) {
    std::array<uint32_t, 3> corners = triangle;
    std::sort(corners.begin(), corners.end());
    if (corners[0] == corners[1] || corners[1] == corners[2]) continue;
    const auto at = std::lower_bound(seen.begin(), seen.end(), corners);
    if (at != seen.end() && *at == corners) continue;
    seen.insert(at, corners);
    kept.push_back(triangle);
  }
  const size_t dropped = mesh.triangles.size() - kept.size();
  mesh.triangles = std::move(kept);
  return dropped;
}

/// Closes each loop of open edges of at most `maxEdges` edges by a fan of triangles turned
/// against the loop's own triangles; returns the loops closed.
size_t fillHoles(TriangleMesh& mesh, int maxEdges) {
  std::map<std::pair<uint32_t, uint32_t>, int> uses;  // undirected edge -> triangles
  for (const auto& t : mesh.triangles)
    for (size_t k = 0; k < 3; ++k) ++uses[std::minmax(t[k], t[(k + 1) % 3])];
  std::map<uint32_t, uint32_t> next;  // open edge a -> b as its triangle runs
  std::map<uint32_t, int> outgoing;
  for (const auto& t : mesh.triangles)
    for (size_t k = 0; k < 3; ++k)
      if (uses[std::minmax(t[k], t[(k + 1) % 3])] == 1) {
        next[t[k]] = t[(k + 1) % 3];
        ++outgoing[t[k]];
      }
  size_t filled = 0;
  std::map<uint32_t, bool> done;
  for (const auto& [start, unused] : next) {
    std::vector<uint32_t> loop{start};
    for (uint32_t at = next[start]; at != start && loop.size() <= size_t(maxEdges);
         at = next.count(at) ? next[at] : start)
      loop.push_back(at);
    const bool simple = std::all_of(loop.begin(), loop.end(), [&](uint32_t v) {
      return outgoing[v] == 1 && !done[v] && next.count(v);
    });
    if (!simple || loop.size() < 3 || loop.size() > size_t(maxEdges) || next[loop.back()] != start)
      continue;
    for (const uint32_t v : loop) done[v] = true;
    for (size_t i = 1; i + 1 < loop.size(); ++i)
      mesh.triangles.push_back({loop[0], loop[i + 1], loop[i]});
    ++filled;
  }
  return filled;
}

}  // namespace

void repairSurface(TriangleMesh& mesh, const SurfaceRepair& repair, MeshReport& report) {
  if (repair.weld > 0) report.weldedVertices = weld(mesh, repair.weld);
  if (repair.weld > 0 || repair.fillHoles > 0) report.droppedTriangles = dropRepeated(mesh);
  if (repair.fillHoles > 0) report.filledHoles = fillHoles(mesh, repair.fillHoles);
}

}  // namespace fibremss::meshio
