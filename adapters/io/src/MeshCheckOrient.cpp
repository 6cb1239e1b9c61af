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

/// Links between the two triangles of every manifold edge (CSR), and the triangles on a border
/// (an edge used once or more than twice: their part is not closed).
struct TriangleLinks {
  std::vector<uint32_t> start;  ///< triangle t's links are links[start[t] .. start[t + 1])
  std::vector<Link> links;      ///< per manifold edge, one each way
  std::vector<bool> onBorder;   ///< per triangle
};

TriangleLinks triangleLinks(const TriangleMesh& mesh) {
  const size_t triangleCount = mesh.triangles.size();
  const std::vector<EdgeUse> edges = sortedEdgeUses(mesh);
  TriangleLinks result;
  result.start.assign(triangleCount + 1, 0);
  result.onBorder.assign(triangleCount, false);
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
      ++result.start[edges[begin].triangle + 1];
      ++result.start[edges[begin + 1].triangle + 1];
    } else {
      for (size_t k = begin; k < end; ++k) result.onBorder[edges[k].triangle] = true;
    }
  });
  for (size_t t = 0; t < triangleCount; ++t) result.start[t + 1] += result.start[t];
  result.links.resize(result.start.back());
  std::vector<uint32_t> filled(result.start.begin(), result.start.end() - 1);
  forEachGroup([&](size_t begin, size_t end) {
    if (end - begin != 2) return;
    const EdgeUse& a = edges[begin];
    const EdgeUse& b = edges[begin + 1];
    const bool agree = a.forward != b.forward;
    result.links[filled[a.triangle]++] = {b.triangle, agree};
    result.links[filled[b.triangle]++] = {a.triangle, agree};
  });
  return result;
}

/// Breadth-first over the part of `seed` into `part`: turn[t] says whether t must be turned
/// over to agree with the part's first triangle. Returns whether the part is orientable;
/// `closed` whether no triangle of it lies on a border.
bool walkPart(const TriangleLinks& links, uint32_t seed, std::vector<int8_t>& turn,
              std::vector<uint32_t>& part, bool& closed) {
  part.assign(1, seed);
  turn[seed] = 0;
  bool orientable = true;
  closed = true;
  for (size_t next = 0; next < part.size(); ++next) {
    const uint32_t t = part[next];
    closed = closed && !links.onBorder[t];
    for (uint32_t k = links.start[t]; k < links.start[t + 1]; ++k) {
      const Link& link = links.links[k];
      const int8_t wanted = static_cast<int8_t>(turn[t] ^ (link.agree ? 0 : 1));
      if (turn[link.other] == -1) {
        turn[link.other] = wanted;
        part.push_back(link.other);
      } else if (turn[link.other] != wanted) {
        orientable = false;
      }
    }
  }
  return orientable;
}

/// Turns over the triangles of an orientable part that disagree with the orientation it keeps
/// (outward when closed, else what most of its triangles have); returns how many.
size_t orientPart(TriangleMesh& mesh, const std::vector<uint32_t>& part,
                  const std::vector<int8_t>& turn, bool closed) {
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
  size_t turned = 0;
  for (const uint32_t t : part) {
    if ((turn[t] == 1) != invert) {
      std::swap(mesh.triangles[t][1], mesh.triangles[t][2]);
      ++turned;
    }
  }
  return turned;
}

}  // namespace

size_t orientConsistently(TriangleMesh& mesh, size_t& nonOrientableParts) {
  const size_t triangleCount = mesh.triangles.size();
  const TriangleLinks links = triangleLinks(mesh);
  std::vector<int8_t> turn(triangleCount, -1);
  std::vector<uint32_t> part;
  size_t turned = 0;
  nonOrientableParts = 0;
  for (uint32_t seed = 0; seed < triangleCount; ++seed) {
    if (turn[seed] != -1) continue;
    bool closed = true;
    if (!walkPart(links, seed, turn, part, closed)) {
      ++nonOrientableParts;
      continue;
    }
    turned += orientPart(mesh, part, turn, closed);
  }
  return turned;
}

}  // namespace fibremss::meshio
