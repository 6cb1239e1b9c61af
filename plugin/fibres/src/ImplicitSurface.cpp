// The implicit surface's extraction (ImplicitSurface.h): seeds beside the boundary particles,
// then marching tetrahedra (each cell cut into the six tetrahedra around its diagonal from the
// lower corner, the same in every cell, so neighbouring cells cut a shared face alike) from
// cell to cell across every face the surface crosses.
#include "fibremss/ImplicitSurface.h"

#include <algorithm>
#include <atomic>
#include <numeric>
#include <thread>

#include "ImplicitSurfaceInternal.h"

namespace fibremss {
namespace {

/// The six tetrahedra of a cell: corners as bit sets (x 1, y 2, z 4), each a chain 0 ⊂ a ⊂ b ⊂ 7.
constexpr std::array<std::array<int, 4>, 6> kTetrahedra{
    {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}}};

/// Whether the values hold both signs (inside: > 0).
bool mixed(std::span<const float> values) {
  bool inside = false, outside = false;
  for (float v : values) (v > 0 ? inside : outside) = true;
  return inside && outside;
}

uint32_t hashKey(uint32_t key) {
  return key * 2654435761u;
}

}  // namespace

void GridTable::begin() {
  if (entries_.empty()) entries_.resize(1 << 12);
  if (++stamp_ == 0) {  // wrapped: clear once
    for (GridEntry& e : entries_) e.stamp = 0;
    stamp_ = 1;
  }
  used_ = 0;
}

GridEntry& GridTable::at(uint32_t key) {
  if (2 * (used_ + 1) > entries_.size()) grow();
  const size_t mask = entries_.size() - 1;
  for (size_t s = hashKey(key) & mask;; s = (s + 1) & mask) {
    GridEntry& e = entries_[s];
    if (e.stamp == stamp_ && e.key == key) return e;
    if (e.stamp != stamp_) {
      e = GridEntry{};
      e.key = key;
      e.stamp = stamp_;
      e.edgeVertex.fill(-1);
      ++used_;
      return e;
    }
  }
}

void GridTable::grow() {
  std::vector<GridEntry> old(entries_.size() * 2);
  old.swap(entries_);
  const size_t mask = entries_.size() - 1;
  for (const GridEntry& e : old) {
    if (e.stamp != stamp_) continue;
    size_t s = hashKey(e.key) & mask;
    while (entries_[s].stamp == stamp_) s = (s + 1) & mask;
    entries_[s] = e;
  }
}

float ImplicitSurface::Impl::valueAt(int32_t i, int32_t j, int32_t k) {
  GridEntry& e = table.at(grid.index(i, j, k));
  if (!e.known) {
    e.value = float(field(grid.point(i, j, k)));
    e.known = true;
  }
  return e.value;
}

std::array<float, 8> ImplicitSurface::Impl::cornerValues(const std::array<int32_t, 3>& cell) {
  std::array<float, 8> values;
  for (int c = 0; c < 8; ++c)
    values[c] = valueAt(cell[0] + (c & 1), cell[1] + (c >> 1 & 1), cell[2] + (c >> 2 & 1));
  return values;
}

void ImplicitSurface::Impl::enqueue(const std::array<int32_t, 3>& cell) {
  if (!inGrid(cell)) return;
  GridEntry& e = table.at(grid.index(cell[0], cell[1], cell[2]));
  if (e.queued) return;
  e.queued = true;
  queue.push_back(cell);
}

void ImplicitSurface::Impl::seed() {
  const btScalar step = voxel / 2;
  const int steps = int(2 * h / step) + 2;
  for (uint32_t p : muscle->boundaryParticles) {
    if (outward[p].length2() == 0) continue;
    const btVector3 direction = (toRest[p].transpose() * outward[p]).normalized();
    std::array<int32_t, 3> last{-1, -1, -1};
    for (int s = 0; s < steps; ++s) {
      const btVector3 u = (positions[p] + direction * (step * btScalar(s)) - grid.origin) / voxel;
      const std::array<int32_t, 3> cell{int32_t(u.x()), int32_t(u.y()), int32_t(u.z())};
      if (cell == last) continue;
      last = cell;
      if (!inGrid(cell)) break;
      if (mixed(cornerValues(cell))) {
        enqueue(cell);
        break;
      }
    }
  }
}

void ImplicitSurface::Impl::march() {
  for (size_t q = 0; q < queue.size(); ++q) {
    const std::array<int32_t, 3> cell = queue[q];
    const std::array<float, 8> values = cornerValues(cell);
    if (!mixed(values)) continue;
    polygonise(cell, values);
    // Across each face whose corners hold both signs the surface goes on in the next cell.
    for (int axis = 0; axis < 3; ++axis)
      for (int side = 0; side < 2; ++side) {
        std::array<float, 4> face;
        int n = 0;
        for (int c = 0; c < 8; ++c)
          if ((c >> axis & 1) == side) face[n++] = values[c];
        if (!mixed(face)) continue;
        std::array<int32_t, 3> next = cell;
        next[axis] += side ? 1 : -1;
        enqueue(next);
      }
  }
}

int32_t ImplicitSurface::Impl::edgeVertex(const std::array<int32_t, 3>& cell, int u, int v,
                                          const std::array<float, 8>& values) {
  if ((u & v) != u) std::swap(u, v);  // u ⊂ v: the edge goes up from corner u
  GridEntry& e =
      table.at(grid.index(cell[0] + (u & 1), cell[1] + (u >> 1 & 1), cell[2] + (u >> 2 & 1)));
  int32_t& vertex = e.edgeVertex[size_t((u ^ v) - 1)];
  if (vertex < 0) {
    auto corner = [&](int c) {
      return grid.point(cell[0] + (c & 1), cell[1] + (c >> 1 & 1), cell[2] + (c >> 2 & 1));
    };
    const btScalar t = btScalar(values[u] / (values[u] - values[v]));
    vertex = int32_t(mesh.vertices.size());
    mesh.vertices.push_back(corner(u) + (corner(v) - corner(u)) * t);
  }
  return vertex;
}

void ImplicitSurface::Impl::polygonise(const std::array<int32_t, 3>& cell,
                                       const std::array<float, 8>& values) {
  for (const std::array<int, 4>& tet : kTetrahedra) {
    std::array<int, 4> in, out;
    int ins = 0, outs = 0;
    for (int c : tet) (values[c] > 0 ? in[ins++] : out[outs++]) = c;
    if (ins == 0 || outs == 0) continue;
    std::array<std::array<int32_t, 3>, 2> triangles;
    int count = 1;
    if (ins == 1 || outs == 1) {
      const int lone = ins == 1 ? in[0] : out[0];
      const std::array<int, 4>& others = ins == 1 ? out : in;
      for (int k = 0; k < 3; ++k) triangles[0][k] = edgeVertex(cell, lone, others[k], values);
    } else {
      const int32_t a = edgeVertex(cell, in[0], out[0], values),
                    b = edgeVertex(cell, in[0], out[1], values),
                    c = edgeVertex(cell, in[1], out[1], values),
                    d = edgeVertex(cell, in[1], out[0], values);
      triangles = {{{a, b, c}, {a, c, d}}};
      count = 2;
    }
    // Counter-clockwise seen from outside: the normal points from the inside corners out.
    btVector3 inward(0, 0, 0);
    for (int c = 0; c < 8; ++c) {
      const btVector3 offset(btScalar(c & 1), btScalar(c >> 1 & 1), btScalar(c >> 2 & 1));
      if (std::find(tet.begin(), tet.end(), c) != tet.end())
        inward += values[c] > 0 ? offset : -offset;
    }
    for (int t = 0; t < count; ++t) {
      std::array<int32_t, 3>& tri = triangles[size_t(t)];
      const auto& v = mesh.vertices;
      const btVector3 normal = (v[tri[1]] - v[tri[0]]).cross(v[tri[2]] - v[tri[0]]);
      if (normal.dot(inward) > 0) std::swap(tri[1], tri[2]);
      mesh.triangles.push_back({uint32_t(tri[0]), uint32_t(tri[1]), uint32_t(tri[2])});
    }
  }
}

ImplicitSurface::ImplicitSurface(std::shared_ptr<const MuscleSettings> muscle,
                                 const ImplicitSurfaceSettings& settings)
    : impl_(std::make_unique<Impl>(std::move(muscle), settings)) {}
ImplicitSurface::~ImplicitSurface() = default;
ImplicitSurface::ImplicitSurface(ImplicitSurface&&) noexcept = default;
ImplicitSurface& ImplicitSurface::operator=(ImplicitSurface&&) noexcept = default;

void ImplicitSurface::extract(std::span<const btVector3> positions,
                              std::span<const Spring> springs) {
  Impl& s = *impl_;
  s.prepareFrames(positions,
                  springs.empty() ? std::span<const Spring>(s.muscle->springs) : springs);
  btVector3 lower, upper;
  pointBounds(positions, lower, upper);
  s.grid = GridFrame::covering(lower, upper, s.voxel, s.h + 2 * s.voxel);
  s.table.begin();
  s.queue.clear();
  s.mesh.vertices.clear();
  s.mesh.triangles.clear();
  s.seed();
  s.march();
}

const TriangleMesh& ImplicitSurface::mesh() const {
  return impl_->mesh;
}
std::vector<uint32_t> ImplicitSurface::nearestParticles() const {
  const Impl& s = *impl_;
  std::vector<uint32_t> nearest(s.mesh.vertices.size(), 0);
  for (size_t v = 0; v < nearest.size(); ++v) {
    btScalar best = 0;
    s.forNeighbours(s.mesh.vertices[v], s.positions, [&](uint32_t p, const btVector3&, btScalar w) {
      if (w > best) best = w, nearest[v] = p;
    });
  }
  return nearest;
}

void ImplicitSurface::setDents(std::span<const SurfaceDent> dents) {
  impl_->dents.assign(dents.begin(), dents.end());
}
btScalar ImplicitSurface::voxel() const {
  return impl_->voxel;
}
btScalar ImplicitSurface::kernelRadius() const {
  return impl_->h;
}

void extractSurfaces(std::span<ImplicitSurface* const> surfaces,
                     std::span<const std::span<const btVector3>> positions,
                     std::span<const std::span<const Spring>> springs, unsigned threads) {
  // Largest first, so the threads finish close together.
  std::vector<size_t> order(surfaces.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return positions[a].size() > positions[b].size(); });
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t n; (n = next.fetch_add(1)) < order.size();)
      surfaces[order[n]]->extract(positions[order[n]], springs[order[n]]);
  };
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < std::min<size_t>(threads, order.size()); ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
}

MeshTopology meshTopology(const TriangleMesh& mesh) {
  std::vector<std::pair<uint64_t, uint32_t>> edges;  // (low << 32 | high, triangle)
  for (uint32_t t = 0; t < mesh.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      const uint64_t a = mesh.triangles[t][size_t(k)], b = mesh.triangles[t][size_t((k + 1) % 3)];
      edges.push_back({std::min(a, b) << 32 | std::max(a, b), t});
    }
  std::sort(edges.begin(), edges.end());
  std::vector<uint32_t> parent(mesh.triangles.size());
  std::iota(parent.begin(), parent.end(), 0u);
  auto root = [&](uint32_t t) {
    while (parent[t] != t) t = parent[t] = parent[parent[t]];
    return t;
  };
  MeshTopology topology;
  for (size_t i = 0, j; i < edges.size(); i = j) {
    for (j = i; j < edges.size() && edges[j].first == edges[i].first; ++j)
      parent[root(edges[j].second)] = root(edges[i].second);
    if (j - i != 2) ++topology.openEdges;
  }
  for (uint32_t t = 0; t < parent.size(); ++t) topology.components += root(t) == t;
  return topology;
}

}  // namespace fibremss
