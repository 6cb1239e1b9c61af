// Consistent, outward orientation for loaded surfaces (segmented meshes often have a few
// triangles turned over, which would flip inside and outside in distance queries).
#include <algorithm>

#include "MeshIOInternal.h"

namespace fibremss::meshio {
namespace {

/// A neighbour across an edge shared by exactly two triangles.
struct Link {
  uint32_t other;  ///< the neighbouring triangle
  bool agree;      ///< the two run the shared edge in opposite directions (consistent)
};

/// Six times the signed volume of the tetrahedron (origin, triangle).
double sixVolume(const TriangleMesh& mesh, const std::array<uint32_t, 3>& t) {
  const btVector3& a = mesh.vertices[t[0]];
  const btVector3& b = mesh.vertices[t[1]];
  const btVector3& c = mesh.vertices[t[2]];
  return double(a.x()) * (double(b.y()) * c.z() - double(b.z()) * c.y()) +
         double(a.y()) * (double(b.z()) * c.x() - double(b.x()) * c.z()) +
         double(a.z()) * (double(b.x()) * c.y() - double(b.y()) * c.x());
}

}  // namespace

size_t orientConsistently(TriangleMesh& mesh, size_t& nonOrientableParts) {
  const size_t triangleCount = mesh.triangles.size();
  const std::vector<EdgeUse> edges = sortedEdgeUses(mesh);

  // Links between the two triangles of every manifold edge (CSR); triangles with an edge used
  // once or more than twice lie on a border, so their part is not closed.
  std::vector<uint32_t> linkStart(triangleCount + 1, 0);
  std::vector<bool> onBorder(triangleCount, false);
  const auto forEachGroup = [&](auto&& visit) {
    for (size_t begin = 0; begin < edges.size();) {
      size_t end = begin + 1;
      while (end < edges.size() && edges[end].key == edges[begin].key) ++end;
      visit(begin, end);
      begin = end;
    }
  };
  forEachGroup([&](size_t begin, size_t end) {
    if (end - begin == 2) {
      ++linkStart[edges[begin].triangle + 1];
      ++linkStart[edges[begin + 1].triangle + 1];
    } else {
      for (size_t k = begin; k < end; ++k) onBorder[edges[k].triangle] = true;
    }
  });
  for (size_t t = 0; t < triangleCount; ++t) linkStart[t + 1] += linkStart[t];
  std::vector<Link> links(linkStart.back());
  std::vector<uint32_t> filled(linkStart.begin(), linkStart.end() - 1);
  forEachGroup([&](size_t begin, size_t end) {
    if (end - begin != 2) return;
    const EdgeUse& a = edges[begin];
    const EdgeUse& b = edges[begin + 1];
    const bool agree = a.forward != b.forward;
    links[filled[a.triangle]++] = {b.triangle, agree};
    links[filled[b.triangle]++] = {a.triangle, agree};
  });

  // Breadth-first over each part: turn[t] says whether t must be turned over to agree with
  // the part's first triangle.
  std::vector<int8_t> turn(triangleCount, -1);
  std::vector<uint32_t> part;
  size_t turned = 0;
  nonOrientableParts = 0;
  for (uint32_t seed = 0; seed < triangleCount; ++seed) {
    if (turn[seed] != -1) continue;
    part.assign(1, seed);
    turn[seed] = 0;
    bool orientable = true, closed = true;
    for (size_t next = 0; next < part.size(); ++next) {
      const uint32_t t = part[next];
      closed = closed && !onBorder[t];
      for (uint32_t k = linkStart[t]; k < linkStart[t + 1]; ++k) {
        const Link& link = links[k];
        const int8_t wanted = static_cast<int8_t>(turn[t] ^ (link.agree ? 0 : 1));
        if (turn[link.other] == -1) {
          turn[link.other] = wanted;
          part.push_back(link.other);
        } else if (turn[link.other] != wanted) {
          orientable = false;
        }
      }
    }
    if (!orientable) {
      ++nonOrientableParts;
      continue;
    }
    const size_t toTurn = static_cast<size_t>(
        std::count_if(part.begin(), part.end(), [&](uint32_t t) { return turn[t] == 1; }));
    bool invert = 2 * toTurn > part.size();  // keep what most triangles already have
    if (closed) {
      double volume = 0;
      for (const uint32_t t : part) {
        volume += (turn[t] == 1 ? -1 : 1) * sixVolume(mesh, mesh.triangles[t]);
      }
      invert = volume < 0;  // a closed part faces outward
    }
    for (const uint32_t t : part) {
      if ((turn[t] == 1) != invert) {
        std::swap(mesh.triangles[t][1], mesh.triangles[t][2]);
        ++turned;
      }
    }
  }
  return turned;
}

}  // namespace fibremss::meshio
