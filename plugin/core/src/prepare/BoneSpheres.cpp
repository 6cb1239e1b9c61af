// Bone spheres by the two-ring heuristic (method.md §6, 000 §4.3): for an unmarked root
// vertex take the longest edge Lmax through it and its area-weighted normal n; the sphere has
// centre root − n·Lmax and radius Lmax·√2; then the root's two-ring is marked and the next
// unmarked vertex becomes a root. Guards: zero-area triangles are ignored, Lmax is capped at
// kMaxEdgeFactor mean edge lengths (slivers otherwise make huge spheres), and a centre that
// the inward offset carries out through a thin part is pulled back into the middle of it.
#include <algorithm>
#include <cmath>

#include "PreparationInternal.h"
#include "fibremss/Error.h"

namespace fibremss::detail {
namespace {

/// The longest edge used for a sphere is at most this many mean edge lengths.
constexpr btScalar kMaxEdgeFactor = 3;
/// A triangle is degenerate when twice its area is below this fraction of its longest edge².
constexpr btScalar kDegenerateArea = 1e-8f;

/// One-ring neighbours of every vertex (compressed rows) and area-weighted normals.
struct Adjacency {
  std::vector<uint32_t> offsets;     // vertexCount + 1
  std::vector<uint32_t> neighbours;  // unique per vertex
  std::vector<btVector3> normals;    // Σ of (b − a)×(c − a) over the vertex's triangles
  size_t degenerate = 0;
  double meanEdge = 0;

  std::span<const uint32_t> ring(uint32_t v) const {
    return {neighbours.data() + offsets[v], neighbours.data() + offsets[v + 1]};
  }
};

Adjacency buildAdjacency(const TriangleMesh& mesh) {
  Adjacency adjacency;
  const size_t n = mesh.vertices.size();
  std::vector<std::vector<uint32_t>> rings(n);
  adjacency.normals.assign(n, btVector3(0, 0, 0));
  double edgeSum = 0;
  size_t edgeCount = 0;
  for (const auto& t : mesh.triangles) {
    const btVector3 &a = mesh.vertices[t[0]], &b = mesh.vertices[t[1]], &c = mesh.vertices[t[2]];
    const btVector3 cross = (b - a).cross(c - a);
    const btScalar longest2 = std::max({(b - a).length2(), (c - b).length2(), (a - c).length2()});
    if (!(cross.length() > kDegenerateArea * longest2)) {
      ++adjacency.degenerate;
      continue;
    }
    for (int k = 0; k < 3; ++k) {
      adjacency.normals[t[k]] += cross;  // |cross| = 2·area: area weighting for free
      rings[t[k]].push_back(t[(k + 1) % 3]);
      rings[t[k]].push_back(t[(k + 2) % 3]);
      edgeSum += (mesh.vertices[t[(k + 1) % 3]] - mesh.vertices[t[k]]).length();
      ++edgeCount;
    }
  }
  adjacency.meanEdge = edgeCount ? edgeSum / edgeCount : 0;
  adjacency.offsets.assign(1, 0);
  for (auto& ring : rings) {
    std::sort(ring.begin(), ring.end());
    ring.erase(std::unique(ring.begin(), ring.end()), ring.end());
    adjacency.neighbours.insert(adjacency.neighbours.end(), ring.begin(), ring.end());
    adjacency.offsets.push_back(static_cast<uint32_t>(adjacency.neighbours.size()));
  }
  return adjacency;
}

/// The sphere of the vertex at `position` whose centre, `longest` [m] along `inward`, went through
/// a thin part of the bone: where the inward ray leaves the bone (the vertex side is inside just
/// below the surface) found by bisection, the centre half way there [m] and a radius that keeps
/// the sphere's reach beyond the vertex's surface [m]. False when no such sphere lies inside the
/// bone (within `tolerance` [m]), or the normal does not point out of the bone there.
bool pullBack(const MeshDistance& distance, const btVector3& position, const btVector3& inward,
              btScalar longest, btScalar tolerance, btVector3& centre, btScalar& radius) {
  btScalar inside = btScalar(0.01), outside = 1;
  if (distance.signedDistance(position + inward * (inside * longest)) > tolerance) return false;
  for (int iteration = 0; iteration < 24; ++iteration) {
    const btScalar middle = (inside + outside) / 2;
    (distance.signedDistance(position + inward * (middle * longest)) <= tolerance ? inside
                                                                                  : outside) =
        middle;
  }
  const btScalar depth = inside * longest / 2;
  centre = position + inward * depth;
  radius = depth + (SIMDSQRT12 * 2 - 1) * longest;
  return !(distance.signedDistance(centre) > tolerance);
}

}  // namespace

BoneSphereReport makeBoneSpheres(const BoneInput& bone, const MeshDistance& distance,
                                 std::mt19937& random, BoneSettings& out) {
  const BoneSphereParameters& parameters = bone.spheres;
  if (!(parameters.thinning >= 0 && parameters.thinning < 1))
    throw InputError("bone '" + bone.name + "'", "spheres.thinning",
                     "must be in [0, 1), got " + std::to_string(parameters.thinning));
  BoneSphereReport report;
  const TriangleMesh& mesh = bone.mesh;
  const Adjacency adjacency = buildAdjacency(mesh);
  report.degenerateTriangles = adjacency.degenerate;
  const btScalar edgeCap = static_cast<btScalar>(kMaxEdgeFactor * adjacency.meanEdge);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<uint8_t> marked(mesh.vertices.size(), 0);
  auto markTwoRing = [&](uint32_t root) {
    marked[root] = 1;
    for (uint32_t first : adjacency.ring(root)) {
      marked[first] = 1;
      for (uint32_t second : adjacency.ring(first)) marked[second] = 1;
    }
  };
  out.sphereCentres.clear();
  out.sphereRadii.clear();
  for (uint32_t root = 0; root < mesh.vertices.size(); ++root) {
    if (marked[root] || adjacency.ring(root).empty()) continue;
    markTwoRing(root);
    if (parameters.thinning > 0 && unit(random) < parameters.thinning) {
      ++report.thinned;
      continue;
    }
    const btVector3& position = mesh.vertices[root];
    const btScalar normalLength = adjacency.normals[root].length();
    if (!(normalLength > 0)) {  // opposite faces cancel: no inward direction
      ++report.dropped;
      continue;
    }
    const btVector3 inward = -adjacency.normals[root] / normalLength;
    btScalar longest = 0;
    for (uint32_t neighbour : adjacency.ring(root))
      longest = std::max(longest, (mesh.vertices[neighbour] - position).length());
    if (longest > edgeCap) {
      longest = edgeCap;
      ++report.capped;
    }
    btVector3 centre = position + inward * longest;
    btScalar radius = longest * SIMDSQRT12 * 2;  // Lmax·√2
    // The centre must be inside or on the bone; 1e-4·Lmax absorbs rounding on flat parts.
    const btScalar tolerance = longest * btScalar(1e-4);
    if (distance.signedDistance(centre) > tolerance) {
      if (!pullBack(distance, position, inward, longest, tolerance, centre, radius)) {
        ++report.dropped;
        continue;
      }
      ++report.pulledBack;
    }
    if (parameters.maxRadius > 0 && radius > parameters.maxRadius) {
      ++report.dropped;
      continue;
    }
    out.sphereCentres.push_back(centre);
    out.sphereRadii.push_back(radius);
  }
  return report;
}

}  // namespace fibremss::detail
