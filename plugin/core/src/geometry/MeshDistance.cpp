// Closest points and signed distances against a triangle mesh: a compact bounding volume
// hierarchy over the triangles (median split, four triangles per leaf, nearest child first)
// and angle-weighted pseudo-normals (Bærentzen & Aanæs) for a sign that holds at edges and
// vertices too.
#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "fibremss/Geometry.h"
#include "fibremss/TrianglePoint.h"

namespace fibremss {
namespace {

using Feature = TriangleFeature;

constexpr uint32_t kLeafSize = 4;
constexpr int kMaxDepth = 64;

}  // namespace

struct MeshDistance::Impl {
  /// A tree node; inner nodes have count == 0, their left child follows them directly and
  /// `first` is the right child; leaves hold triangles [first, first + count) in leaf order.
  struct Node {
    btVector3 lower, upper;
    uint32_t first = 0;
    uint32_t count = 0;
  };
  struct Hit {
    btScalar distance2;
    btVector3 point;
    uint32_t slot;  // triangle position in leaf order
    Feature feature;
  };

  TriangleMesh mesh;                     // the mesh as given
  std::vector<Node> nodes;               // the tree, root first
  std::vector<uint32_t> order;           // leaf order -> triangle index
  std::vector<btVector3> corners;        // three corners per triangle, leaf order
  std::vector<btVector3> pseudoNormals;  // per triangle in leaf order: face, edge 0, 1, 2
  std::vector<btVector3> vertexNormals;  // angle-weighted, per vertex
  std::vector<btVector3> faceNormals;    // unit, per triangle (zero for a zero-area one)
  std::vector<uint32_t> ringStart;       // per vertex + 1: where its triangles start in `ring`
  std::vector<uint32_t> ring;            // the triangles around each vertex, vertex by vertex

  explicit Impl(const TriangleMesh& input) : mesh(input) {
    const size_t count = mesh.triangles.size();
    order.resize(count);
    for (uint32_t i = 0; i < count; ++i) order[i] = i;
    if (count == 0) return;
    std::vector<btVector3> centroids(count);
    for (size_t i = 0; i < count; ++i) {
      const auto& t = mesh.triangles[i];
      centroids[i] = (mesh.vertices[t[0]] + mesh.vertices[t[1]] + mesh.vertices[t[2]]) / 3;
    }
    nodes.reserve(2 * count / kLeafSize + 2);
    build(0, static_cast<uint32_t>(count), centroids, 0);
    corners.resize(3 * count);
    for (size_t slot = 0; slot < count; ++slot)
      for (int k = 0; k < 3; ++k)
        corners[3 * slot + k] = mesh.vertices[mesh.triangles[order[slot]][k]];
    computePseudoNormals();
    buildRings();
  }

  void buildRings() {
    ringStart.assign(mesh.vertices.size() + 1, 0);
    for (const auto& t : mesh.triangles)
      for (uint32_t v : t) ++ringStart[v + 1];
    for (size_t v = 0; v < mesh.vertices.size(); ++v) ringStart[v + 1] += ringStart[v];
    ring.resize(ringStart.back());
    std::vector<uint32_t> next(ringStart.begin(), ringStart.end() - 1);
    for (uint32_t i = 0; i < mesh.triangles.size(); ++i)
      for (uint32_t v : mesh.triangles[i]) ring[next[v]++] = i;
  }

  uint32_t build(uint32_t begin, uint32_t end, const std::vector<btVector3>& centroids, int depth) {
    const uint32_t index = static_cast<uint32_t>(nodes.size());
    nodes.emplace_back();
    btVector3 lower(BT_LARGE_FLOAT, BT_LARGE_FLOAT, BT_LARGE_FLOAT), upper = -lower;
    btVector3 centreLower = lower, centreUpper = upper;
    for (uint32_t i = begin; i < end; ++i) {
      for (uint32_t v : mesh.triangles[order[i]]) {
        lower.setMin(mesh.vertices[v]);
        upper.setMax(mesh.vertices[v]);
      }
      centreLower.setMin(centroids[order[i]]);
      centreUpper.setMax(centroids[order[i]]);
    }
    nodes[index].lower = lower;
    nodes[index].upper = upper;
    if (end - begin <= kLeafSize || depth >= kMaxDepth - 2) {
      nodes[index].first = begin;
      nodes[index].count = end - begin;
      return index;
    }
    const int axis = (centreUpper - centreLower).maxAxis();
    const uint32_t middle = begin + (end - begin) / 2;
    std::nth_element(
        order.begin() + begin, order.begin() + middle, order.begin() + end,
        [&](uint32_t x, uint32_t y) { return centroids[x][axis] < centroids[y][axis]; });
    build(begin, middle, centroids, depth + 1);
    const uint32_t right = build(middle, end, centroids, depth + 1);
    nodes[index].first = right;
    return index;
  }

  void computePseudoNormals() {
    const size_t count = mesh.triangles.size();
    faceNormals.assign(count, btVector3(0, 0, 0));
    vertexNormals.assign(mesh.vertices.size(), btVector3(0, 0, 0));
    std::unordered_map<uint64_t, btVector3> edgeSums;
    edgeSums.reserve(2 * count);
    auto edgeKey = [](uint32_t u, uint32_t v) {
      return (uint64_t(std::min(u, v)) << 32) | std::max(u, v);
    };
    for (size_t i = 0; i < count; ++i) {
      const auto& t = mesh.triangles[i];
      const btVector3 normal = (mesh.vertices[t[1]] - mesh.vertices[t[0]])
                                   .cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]);
      const btScalar length = normal.length();
      if (!(length > 0)) continue;  // zero-area: contributes to no pseudo-normal
      faceNormals[i] = normal / length;
      for (int k = 0; k < 3; ++k) {
        const btVector3& corner = mesh.vertices[t[k]];
        const btVector3 e1 = mesh.vertices[t[(k + 1) % 3]] - corner;
        const btVector3 e2 = mesh.vertices[t[(k + 2) % 3]] - corner;
        const btScalar cosine = e1.dot(e2) / std::sqrt(e1.length2() * e2.length2());
        if (std::isfinite(cosine))
          vertexNormals[t[k]] +=
              faceNormals[i] * std::acos(std::clamp(cosine, btScalar(-1), btScalar(1)));
        // try_emplace: btVector3's default constructor leaves it uninitialized.
        edgeSums.try_emplace(edgeKey(t[k], t[(k + 1) % 3]), 0, 0, 0).first->second +=
            faceNormals[i];
      }
    }
    pseudoNormals.resize(4 * count);
    for (size_t slot = 0; slot < count; ++slot) {
      const uint32_t triangle = order[slot];
      const auto& t = mesh.triangles[triangle];
      pseudoNormals[4 * slot] = faceNormals[triangle];
      for (int k = 0; k < 3; ++k) {
        const auto edge = edgeSums.find(edgeKey(t[k], t[(k + 1) % 3]));
        pseudoNormals[4 * slot + 1 + k] =
            edge == edgeSums.end() ? faceNormals[triangle] : edge->second;
      }
    }
  }

  /// A node on the search's stack and its box's squared distance to the query point [m²].
  struct Pending {
    uint32_t node;
    btScalar distance2;
  };

  /// Nearest triangle point with squared distance <= limit2 (slot UINT32_MAX when none). A node's
  /// box distance is found once, when it is pushed, and held against the best distance again when
  /// it is popped.
  Hit nearest(const btVector3& p, btScalar limit2) const {
    Hit best{limit2, btVector3(0, 0, 0), UINT32_MAX, Feature::Face};
    if (nodes.empty()) return best;
    Pending stack[kMaxDepth];
    int top = 0;
    stack[top++] = {0, boxDistance2(p, nodes[0].lower, nodes[0].upper)};
    while (top > 0) {
      const Pending pending = stack[--top];
      if (pending.distance2 > best.distance2) continue;
      const Node& node = nodes[pending.node];
      if (node.count > 0) {
        for (uint32_t slot = node.first; slot < node.first + node.count; ++slot) {
          const TrianglePoint candidate =
              closestOnTriangle(p, corners[3 * slot], corners[3 * slot + 1], corners[3 * slot + 2]);
          const btScalar d2 = (p - candidate.point).length2();
          if (d2 < best.distance2 || (best.slot == UINT32_MAX && d2 <= best.distance2))
            best = {d2, candidate.point, slot, candidate.feature};
        }
        continue;
      }
      const uint32_t left = pending.node + 1, right = node.first;
      const btScalar dl = boxDistance2(p, nodes[left].lower, nodes[left].upper);
      const btScalar dr = boxDistance2(p, nodes[right].lower, nodes[right].upper);
      // Push the farther child first so the nearer one is searched first and prunes more.
      if (dl <= dr) {
        if (dr <= best.distance2) stack[top++] = {right, dr};
        if (dl <= best.distance2) stack[top++] = {left, dl};
      } else {
        if (dl <= best.distance2) stack[top++] = {left, dl};
        if (dr <= best.distance2) stack[top++] = {right, dr};
      }
    }
    return best;
  }

  const btVector3& pseudoNormal(const Hit& hit) const {
    switch (hit.feature) {
      case Feature::Vertex0:
      case Feature::Vertex1:
      case Feature::Vertex2:
        return vertexNormals[mesh.triangles[order[hit.slot]][static_cast<int>(hit.feature)]];
      case Feature::Edge0:
      case Feature::Edge1:
      case Feature::Edge2:
        return pseudoNormals[4 * hit.slot + 1 + (static_cast<int>(hit.feature) - 3)];
      case Feature::Face:
        break;
    }
    return pseudoNormals[4 * hit.slot];
  }
};

MeshDistance::MeshDistance(const TriangleMesh& mesh) : impl_(std::make_unique<Impl>(mesh)) {}
MeshDistance::~MeshDistance() = default;
MeshDistance::MeshDistance(MeshDistance&&) noexcept = default;
MeshDistance& MeshDistance::operator=(MeshDistance&&) noexcept = default;

MeshDistance::Closest MeshDistance::closest(const btVector3& p, btScalar maxDistance) const {
  if (!(maxDistance >= 0)) return {};  // negative or NaN: nothing can be that close
  const btScalar limit2 = std::isfinite(maxDistance) ? maxDistance * maxDistance
                                                     : std::numeric_limits<btScalar>::infinity();
  const Impl::Hit hit = impl_->nearest(p, limit2);
  Closest result;
  if (hit.slot == UINT32_MAX) return result;
  result.distance = std::sqrt(hit.distance2);
  result.point = hit.point;
  result.triangle = impl_->order[hit.slot];
  result.inside = (p - hit.point).dot(impl_->pseudoNormal(hit)) < 0;
  result.feature = static_cast<uint8_t>(hit.feature);
  return result;
}

MeshDistance::Plane MeshDistance::frontFace(const btVector3& p, const Closest& c) const {
  const Impl& m = *impl_;
  Plane best{btVector3(0, 0, 0), -std::numeric_limits<btScalar>::infinity()};
  const auto consider = [&](uint32_t triangle) {
    const btVector3& normal = m.faceNormals[triangle];
    const btScalar distance = (p - c.point).dot(normal);
    if (!normal.isZero() && distance > best.distance) best = {normal, distance};
  };
  const auto& t = m.mesh.triangles[c.triangle];
  const auto feature = static_cast<Feature>(c.feature);
  if (feature == Feature::Face) {
    consider(c.triangle);
    return best;
  }
  // A corner: its ring; an edge: the triangles of its first corner's ring that hold both ends.
  const bool edge = feature >= Feature::Edge0;
  const int k = edge ? c.feature - 3 : c.feature;
  const uint32_t from = t[k], to = t[(k + 1) % 3];
  for (uint32_t r = m.ringStart[from]; r < m.ringStart[from + 1]; ++r) {
    const auto& other = m.mesh.triangles[m.ring[r]];
    if (!edge || std::find(other.begin(), other.end(), to) != other.end()) consider(m.ring[r]);
  }
  return best;
}

btScalar MeshDistance::signedDistance(const btVector3& p) const {
  const Impl::Hit hit = impl_->nearest(p, std::numeric_limits<btScalar>::infinity());
  if (hit.slot == UINT32_MAX) return std::numeric_limits<btScalar>::infinity();
  const btScalar distance = std::sqrt(hit.distance2);
  return (p - hit.point).dot(impl_->pseudoNormal(hit)) < 0 ? -distance : distance;
}

const TriangleMesh& MeshDistance::mesh() const {
  return impl_->mesh;
}

}  // namespace fibremss
