// The implicit surface's extraction (ImplicitSurface.h): seeds beside the boundary particles,
// then marching tetrahedra (each cell cut into the six tetrahedra around its diagonal from the
// lower corner, the same in every cell, so neighbouring cells cut a shared face alike) from
// cell to cell across every face the surface crosses.
#include "fibremss/ImplicitSurface.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>

#include "ImplicitSurfaceInternal.h"
#include "fibremss/Error.h"
#include "fibremss/UnionFind.h"

namespace fibremss {
namespace {

/// The six tetrahedra of a cell: corners as bit sets (x 1, y 2, z 4), each a chain 0 ⊂ a ⊂ b ⊂ 7.
constexpr std::array<std::array<int, 4>, 6> kTetrahedra{
    {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}}};

/// The surface's triangles in one tetrahedron for one set of inside corners: each triangle's
/// vertices as the cell corner pairs (u, v) of the edges they lie on, u ⊂ v (the edge goes up
/// from u).
struct TetrahedronCut {
  int count = 0;  ///< triangles (0 to 2)
  std::array<std::array<std::array<int, 2>, 3>, 2> edges{};
};

/// The cut of tetrahedron `tet` with the corners in bit set `inside` (bit k: tet[k]) inside,
/// counter-clockwise seen from outside. Within a tetrahedron the linear field's zero set is a
/// plane, so the orientation does not depend on where the vertices lie along their edges: it is
/// found here with them at the edges' midpoints.
TetrahedronCut cutOf(const std::array<int, 4>& tet, unsigned inside) {
  std::array<int, 4> in{}, out{};
  int ins = 0, outs = 0;
  for (unsigned k = 0; k < 4; ++k)
    (inside >> k & 1 ? in[size_t(ins++)] : out[size_t(outs++)]) = tet[k];
  TetrahedronCut cut;
  if (ins == 0 || outs == 0) return cut;
  if (ins == 1 || outs == 1) {
    const int lone = ins == 1 ? in[0] : out[0];
    const std::array<int, 4>& others = ins == 1 ? out : in;
    cut.count = 1;
    for (size_t k = 0; k < 3; ++k) cut.edges[0][k] = {lone, others[k]};
  } else {
    const std::array<int, 2> a{in[0], out[0]}, b{in[0], out[1]}, c{in[1], out[1]}, d{in[1], out[0]};
    cut.count = 2;
    cut.edges = {{{a, b, c}, {a, c, d}}};
  }
  auto corner = [](int c) {
    return btVector3(btScalar(c & 1), btScalar(c >> 1 & 1), btScalar(c >> 2 & 1));
  };
  btVector3 inward(0, 0, 0);
  for (size_t k = 0; k < 4; ++k) inward += inside >> k & 1 ? corner(tet[k]) : -corner(tet[k]);
  for (int n = 0; n < cut.count; ++n) {
    auto& e = cut.edges[size_t(n)];
    auto mid = [&](size_t k) { return (corner(e[k][0]) + corner(e[k][1])) / 2; };
    if ((mid(1) - mid(0)).cross(mid(2) - mid(0)).dot(inward) > 0) std::swap(e[1], e[2]);
    for (std::array<int, 2>& edge : e)
      if ((edge[0] & edge[1]) != edge[0]) std::swap(edge[0], edge[1]);
  }
  return cut;
}

/// The surface's triangles in one cell for one set of inside corners (bit c: corner c), the
/// six tetrahedra's cuts in order: the distinct edges their vertices lie on, in the order the
/// triangles first use them, and each triangle's edges among those.
struct CellCut {
  int count = 0;      ///< triangles (0 to 12)
  int edgeCount = 0;  ///< distinct edges (at most the cell's 19: 12 sides, 6 face diagonals, 1)
  std::array<std::array<uint8_t, 2>, 19> edges{};      ///< corner pairs (u, v), u ⊂ v
  std::array<std::array<uint8_t, 3>, 12> triangles{};  ///< per triangle: its vertices' edges
  /// Per edge: the first edge of the triangles joined to it through shared edges, −1 for that
  /// first edge itself.
  std::array<int8_t, 19> joined{};

  /// Adds a triangle whose vertices lie on the edges `triangle` (corner pairs).
  void add(const std::array<std::array<int, 2>, 3>& triangle) {
    for (size_t k = 0; k < 3; ++k) {
      const std::array<uint8_t, 2> edge{uint8_t(triangle[k][0]), uint8_t(triangle[k][1])};
      int e = 0;
      while (e < edgeCount && edges[size_t(e)] != edge) ++e;
      if (e == edgeCount) edges[size_t(edgeCount++)] = edge;
      triangles[size_t(count)][k] = uint8_t(e);
    }
    ++count;
  }
  /// Sets `joined` once every triangle is added.
  void join() {
    std::vector<uint32_t> parent(static_cast<size_t>(edgeCount));
    std::iota(parent.begin(), parent.end(), 0u);
    for (int n = 0; n < count; ++n)
      for (size_t k = 1; k < 3; ++k)  // the root stays the first edge
        unionFindJoin(parent, triangles[size_t(n)][0], triangles[size_t(n)][k]);
    for (uint32_t e = 0; e < uint32_t(edgeCount); ++e) {
      const uint32_t first = unionFindRoot(parent, e);
      joined[e] = first == e ? int8_t(-1) : int8_t(first);
    }
  }
};

/// kCellCuts[inside]: the cell's triangles with the corners in bit set `inside` inside.
const std::array<CellCut, 256> kCellCuts = [] {
  std::array<CellCut, 256> cuts;
  for (unsigned inside = 0; inside < 256; ++inside)
    for (size_t t = 0; t < kTetrahedra.size(); ++t) {
      unsigned tetInside = 0;
      for (unsigned k = 0; k < 4; ++k) tetInside |= (inside >> kTetrahedra[t][k] & 1) << k;
      const TetrahedronCut cut = cutOf(kTetrahedra[t], tetInside);
      for (int n = 0; n < cut.count; ++n) cuts[inside].add(cut.edges[size_t(n)]);
    }
  for (CellCut& cut : cuts) cut.join();
  return cuts;
}();

/// A piece of a surface enclosing fewer grid cells than this is dropped (Impl::dropSpecks).
constexpr double kSmallestPieceCells = 2;

/// The corners among `values` inside (value > 0), bit c for corner c.
unsigned insideCorners(const std::array<float, 8>& values) {
  unsigned inside = 0;
  for (unsigned c = 0; c < 8; ++c) inside |= unsigned(values[c] > 0) << c;
  return inside;
}

/// Whether the corners in `mask` hold both signs.
bool mixed(unsigned inside, unsigned mask = 255) {
  return (inside & mask) != 0 && (inside & mask) != mask;
}

/// The corners of the cell's face on side `side` of `axis`, as a bit set.
constexpr unsigned faceCorners(int axis, int side) {
  unsigned mask = 0;
  for (int c = 0; c < 8; ++c)
    if ((c >> axis & 1) == side) mask |= 1u << c;
  return mask;
}

}  // namespace

void GridTable::begin(const GridFrame& grid) {
  for (int a = 0; a < 3; ++a) blocks_[a] = (grid.dims[a] + 3) / 4;
  const size_t count = size_t(blocks_[0]) * size_t(blocks_[1]) * size_t(blocks_[2]);
  if (blockStamp_.size() < count) {
    blockStamp_.resize(count, 0);
    blockSlot_.resize(count, 0);
  }
  if (++stamp_ == 0) {  // wrapped: clear once
    std::fill(blockStamp_.begin(), blockStamp_.end(), 0u);
    stamp_ = 1;
  }
  taken_ = 0;
}

void GridTable::take(size_t block) {
  constexpr size_t kPoints = 64;
  if (entries_.size() < taken_ + kPoints) entries_.resize(std::max(2 * entries_.size(), kPoints));
  GridEntry fresh;
  fresh.edgeVertex.fill(-1);
  std::fill_n(entries_.begin() + std::ptrdiff_t(taken_), kPoints, fresh);
  blockStamp_[block] = stamp_;
  blockSlot_[block] = uint32_t(taken_);
  taken_ += kPoints;
}

std::array<GridEntry*, 8> GridTable::corners(int32_t i, int32_t j, int32_t k) {
  std::array<GridEntry*, 8> entries;
  if ((i & 3) != 3 && (j & 3) != 3 && (k & 3) != 3) {  // the cell within one block
    GridEntry* first = &at(i, j, k);
    for (int c = 0; c < 8; ++c) entries[size_t(c)] = first + pointOf(c & 1, c >> 1 & 1, c >> 2 & 1);
    return entries;
  }
  // Every block taken before any pointer is made: a take may move the entries.
  std::array<size_t, 8> blocks;
  for (int c = 0; c < 8; ++c) {
    blocks[size_t(c)] = blockOf(i + (c & 1), j + (c >> 1 & 1), k + (c >> 2 & 1));
    if (blockStamp_[blocks[size_t(c)]] != stamp_) take(blocks[size_t(c)]);
  }
  for (int c = 0; c < 8; ++c)
    entries[size_t(c)] = &entries_[blockSlot_[blocks[size_t(c)]] +
                                   pointOf(i + (c & 1), j + (c >> 1 & 1), k + (c >> 2 & 1))];
  return entries;
}

std::array<GridEntry*, 8> ImplicitSurface::Impl::cellCorners(const std::array<int32_t, 3>& cell,
                                                             std::array<float, 8>& values) {
  const std::array<GridEntry*, 8> corners = table.corners(cell[0], cell[1], cell[2]);
  for (int c = 0; c < 8; ++c) {
    GridEntry& e = *corners[size_t(c)];
    if (!e.known) {
      e.value = float(
          field(cell[0] + (c & 1), cell[1] + (c >> 1 & 1), cell[2] + (c >> 2 & 1), e.thickened));
      e.known = true;
    }
    values[size_t(c)] = e.value;
  }
  return corners;
}

void ImplicitSurface::Impl::enqueue(const std::array<int32_t, 3>& cell) {
  if (!inGrid(cell)) return;
  GridEntry& e = table.at(cell[0], cell[1], cell[2]);
  if (e.queued) return;
  e.queued = true;
  queue.push_back(cell);
}

SeedRay ImplicitSurface::Impl::seedRay(uint32_t p) const {
  SeedRay ray;
  ray.start = positions[p];
  ray.direction = (toRest[p].transpose() * outward[p]).normalized();
  ray.step = voxel / 2;
  ray.steps = int(2 * h / ray.step) + 2;
  // The step where the rest surface is expected: the particle's rest depth, mapped to now.
  const btScalar depth =
      outward[p].length() / btMax((toRest[p] * ray.direction).length(), SIMD_EPSILON);
  ray.expected = std::min(int(depth / ray.step), ray.steps - 1);
  return ray;
}

bool ImplicitSurface::Impl::probeCell(const SeedRay& ray, int n,
                                      std::array<int32_t, 3>& cell) const {
  const int s = ray.expected + (n % 2 ? (n + 1) / 2 : -(n / 2));
  if (s < 0 || s >= ray.steps) return false;
  const btVector3 u = (ray.start + ray.direction * (ray.step * btScalar(s)) - grid.origin) / voxel;
  cell = {int32_t(u.x()), int32_t(u.y()), int32_t(u.z())};
  return inGrid(cell);
}

bool ImplicitSurface::Impl::seedFrom(uint32_t p) {
  const SeedRay ray = seedRay(p);
  std::array<int32_t, 3> cell;
  // A ray through a queued cell meets a surface already found: no field values needed.
  for (int n = 0; n < 2 * ray.steps; ++n)
    if (probeCell(ray, n, cell) && table.at(cell[0], cell[1], cell[2]).queued) return false;
  // From the expected step alternately in and out: the first cell holding both signs.
  std::array<float, 8> values;
  for (int n = 0; n < 2 * ray.steps; ++n) {
    if (!probeCell(ray, n, cell)) continue;
    cellCorners(cell, values);
    if (mixed(insideCorners(values))) {
      enqueue(cell);
      return true;
    }
  }
  return false;
}

void ImplicitSurface::Impl::seedAndMarch() {
  for (uint32_t p : muscle->boundaryParticles)
    if (outward[p].length2() > 0 && seedFrom(p)) march();
}

void ImplicitSurface::Impl::march() {
  for (; marched < queue.size(); ++marched) {
    const std::array<int32_t, 3> cell = queue[marched];
    std::array<float, 8> values;
    const std::array<GridEntry*, 8> corners = cellCorners(cell, values);
    const unsigned inside = insideCorners(values);
    if (!mixed(inside)) continue;
    polygonise(cell, corners, values, inside);
    // Across each face whose corners hold both signs the surface goes on in the next cell.
    for (int axis = 0; axis < 3; ++axis)
      for (int side = 0; side < 2; ++side) {
        if (!mixed(inside, faceCorners(axis, side))) continue;
        std::array<int32_t, 3> next = cell;
        next[axis] += side ? 1 : -1;
        enqueue(next);
      }
  }
}

void ImplicitSurface::Impl::dropSpecks() {
  const size_t count = mesh.vertices.size();  // pieceOf joined by polygonise
  uint32_t roots = 0;                         // pieces
  for (uint32_t v = 0; v < count; ++v) roots += pieceOf[v] == v;
  if (roots <= 1) return;
  // Each piece's enclosed volume (signed: a hollow's is negative), from the grid's origin.
  pieceVolume.assign(count, 0);
  for (const std::array<uint32_t, 3>& t : mesh.triangles) {
    const btVector3 a = mesh.vertices[t[0]] - grid.origin, b = mesh.vertices[t[1]] - grid.origin,
                    c = mesh.vertices[t[2]] - grid.origin;
    pieceVolume[unionFindRoot(pieceOf, t[0])] += double(a.dot(b.cross(c))) / 6;
  }
  uint32_t largest = 0;
  for (uint32_t v = 0; v < count; ++v)
    if (std::abs(pieceVolume[v]) > std::abs(pieceVolume[largest])) largest = v;
  const double smallest = kSmallestPieceCells * double(voxel) * double(voxel) * double(voxel);
  vertexKept.resize(count);
  int32_t kept = 0;
  for (uint32_t v = 0; v < count; ++v) {
    const uint32_t root = unionFindRoot(pieceOf, v);
    const bool keep = root == largest || std::abs(pieceVolume[root]) >= smallest;
    vertexKept[v] = keep ? kept : -1;
    if (keep) mesh.vertices[size_t(kept++)] = mesh.vertices[v];
  }
  mesh.vertices.resize(size_t(kept));
  size_t triangles = 0;
  for (const std::array<uint32_t, 3>& t : mesh.triangles)
    if (vertexKept[t[0]] >= 0)
      mesh.triangles[triangles++] = {uint32_t(vertexKept[t[0]]), uint32_t(vertexKept[t[1]]),
                                     uint32_t(vertexKept[t[2]])};
  mesh.triangles.resize(triangles);
}

void ImplicitSurface::Impl::thin() {
  const AnchorPick none{-1, voxel * voxel, btVector3(0, 0, 0)};  // reach: a grid spacing
  std::fill(picks.begin(), picks.end(), none);
  for (uint32_t v : thickVertices) {
    const btVector3 x = mesh.vertices[v];
    btVector3 step, onRest;
    if (!thinningStep(x, step, onRest)) continue;
    mesh.vertices[v] = x + step;
    for (uint32_t a : anchors.near(onRest)) {
      const btScalar distance2 = (anchors.points[a] - onRest).length2();
      if (distance2 < picks[a].distance2) picks[a] = {int32_t(v), distance2, x};
    }
  }
  pinToAnchors();
}

void ImplicitSurface::Impl::pinToAnchors() {
  if (picks.empty()) return;
  pinned.assign(mesh.vertices.size(), 0);
  for (size_t a = 0; a < picks.size(); ++a) {
    const AnchorPick& pick = picks[a];
    if (pick.vertex < 0 || pinned[size_t(pick.vertex)]) continue;  // one anchor per vertex
    btVector3 step;
    if (!mappedStep(pick.before, anchors.points[a], step)) continue;
    mesh.vertices[size_t(pick.vertex)] = pick.before + step;
    pinned[size_t(pick.vertex)] = 1;
  }
}

inline uint32_t ImplicitSurface::Impl::newVertex(const std::array<int32_t, 3>& cell, int u, int v,
                                                 const std::array<float, 8>& values) {
  auto corner = [&](int c) {
    return grid.point(cell[0] + (c & 1), cell[1] + (c >> 1 & 1), cell[2] + (c >> 2 & 1));
  };
  const btScalar t = btScalar(values[u] / (values[u] - values[v]));
  const auto vertex = uint32_t(mesh.vertices.size());
  mesh.vertices.push_back(corner(u) + (corner(v) - corner(u)) * t);
  pieceOf.push_back(vertex);
  return vertex;
}

void ImplicitSurface::Impl::polygonise(const std::array<int32_t, 3>& cell,
                                       const std::array<GridEntry*, 8>& corners,
                                       const std::array<float, 8>& values, unsigned inside) {
  const CellCut& cut = kCellCuts[inside];
  std::array<uint32_t, 19> vertices;                 // per distinct edge of the cut
  const auto made = uint32_t(mesh.vertices.size());  // vertices from here on are this cell's
  for (int e = 0; e < cut.edgeCount; ++e) {
    const auto [u, v] = cut.edges[size_t(e)];
    // Made once, kept in the entry of corner u (the edge goes up from it).
    int32_t& vertex = corners[u]->edgeVertex[size_t((u ^ v) - 1)];
    if (vertex < 0) {
      vertex = int32_t(newVertex(cell, u, v, values));
      if (corners[u]->thickened || corners[v]->thickened) thickVertices.push_back(uint32_t(vertex));
    }
    vertices[size_t(e)] = uint32_t(vertex);
  }
  // Each vertex joins the piece of its triangles' first vertex: one made here is still a root.
  for (int e = 0; e < cut.edgeCount; ++e) {
    if (cut.joined[size_t(e)] < 0) continue;
    const uint32_t root = unionFindRoot(pieceOf, vertices[size_t(cut.joined[size_t(e)])]),
                   vertex = vertices[size_t(e)];
    pieceOf[vertex >= made ? vertex : unionFindRoot(pieceOf, vertex)] = root;
  }
  for (int n = 0; n < cut.count; ++n) {
    const std::array<uint8_t, 3>& t = cut.triangles[size_t(n)];
    mesh.triangles.push_back({vertices[t[0]], vertices[t[1]], vertices[t[2]]});
  }
}

ImplicitSurface::ImplicitSurface(std::shared_ptr<const MuscleSettings> muscle,
                                 const ImplicitSurfaceSettings& settings)
    : impl_(std::make_unique<Impl>(std::move(muscle), settings)) {}
ImplicitSurface::~ImplicitSurface() = default;
ImplicitSurface::ImplicitSurface(ImplicitSurface&&) noexcept = default;
ImplicitSurface& ImplicitSurface::operator=(ImplicitSurface&&) noexcept = default;

void ImplicitSurface::Impl::extract(std::span<const btVector3> current,
                                    std::span<const Spring> springs) {
  prepareFrames(current, springs.empty() ? std::span<const Spring>(muscle->springs) : springs);
  btVector3 lower, upper;
  pointBounds(current, lower, upper);
  grid = GridFrame::covering(lower, upper, voxel, h + 2 * voxel);
  beginMaps();
  table.begin(grid);
  queue.clear();
  marched = 0;
  mesh.vertices.clear();
  mesh.triangles.clear();
  pieceOf.clear();
  thickVertices.clear();
  seedAndMarch();
  thin();
  dropSpecks();
}

std::vector<btVector3> ImplicitSurface::Impl::missedRestVertices() {
  extract(muscle->restPositions, {});
  const MeshDistance distance(mesh);
  const btScalar tolerance = settings.snapTolerance * voxel;
  std::vector<btVector3> missed;
  for (const btVector3& v : muscle->restSurface.vertices)
    if (distance.closest(v).distance > tolerance) missed.push_back(v);
  return missed;
}

void ImplicitSurface::Impl::thickenMissedTips() {
  const std::vector<btVector3> missed = missedRestVertices();
  if (!missed.empty()) rest.thickenAlso(missed);
}

void ImplicitSurface::Impl::findAnchors() {
  std::vector<btVector3> missed = missedRestVertices();
  for (const btVector3& v : missed) rest.keepNearest(v, voxel);
  anchors.build(std::move(missed), voxel);
  picks.resize(anchors.points.size());
}

void ImplicitSurface::Impl::markRestErrors() {
  if (settings.tipThickening > 0) thickenMissedTips();
  extract(muscle->restPositions, {});
  const MeshDistance& distance = rest.surfaceDistance();
  const btScalar tolerance = settings.snapTolerance * voxel;
  for (const btVector3& v : mesh.vertices)
    if (distance.closest(v).distance > tolerance) rest.keepNearest(v, voxel);
  if (settings.tipThickening > 0) findAnchors();
  mesh.vertices.clear();  // no surface until the first extract()
  mesh.triangles.clear();
}

void ImplicitSurface::extract(std::span<const btVector3> positions,
                              std::span<const Spring> springs) {
  impl_->extract(positions, springs);
}

const TriangleMesh& ImplicitSurface::mesh() const {
  return impl_->mesh;
}
std::vector<uint32_t> ImplicitSurface::nearestParticles() const {
  const Impl& s = *impl_;
  std::vector<uint32_t> nearest(s.mesh.vertices.size(), 0);
  for (size_t v = 0; v < nearest.size(); ++v) {
    btScalar best = 0;
    s.forNeighbours(s.mesh.vertices[v], [&](uint32_t e, const btVector3&, btScalar w) {
      if (w > best) best = w, nearest[v] = s.cells.order[e];
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

std::vector<size_t> extractionOrder(std::span<ImplicitSurface* const> surfaces,
                                    std::span<const std::span<const btVector3>> positions) {
  const auto size = [&](size_t a) {
    return std::pair(surfaces[a]->mesh().triangles.size(), positions[a].size());
  };
  std::vector<size_t> order(surfaces.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return size(a) > size(b); });
  return order;
}

void extractSurfaces(std::span<ImplicitSurface* const> surfaces,
                     std::span<const std::span<const btVector3>> positions,
                     std::span<const std::span<const Spring>> springs, TaskPool& pool) {
  if (positions.size() != surfaces.size() || springs.size() != surfaces.size())
    throw InputError("extractSurfaces", "",
                     std::to_string(surfaces.size()) + " surfaces, " +
                         std::to_string(positions.size()) + " positions, " +
                         std::to_string(springs.size()) +
                         " springs; expected one each per surface");
  // One task per surface, never two on one: a surface's grids and scratch are its task's alone.
  for (size_t a = 0; a < surfaces.size(); ++a)
    for (size_t b = 0; b < a; ++b)
      if (surfaces[a] == surfaces[b])
        throw InputError(
            "extractSurfaces", "surfaces[" + std::to_string(a) + "]",
            "the same surface as surfaces[" + std::to_string(b) + "]; expected distinct surfaces");
  const std::vector<size_t> order = extractionOrder(surfaces, positions);
  pool.run(
      order.size(),
      [&](size_t n, unsigned) {
        surfaces[order[n]]->extract(positions[order[n]], springs[order[n]]);
      },
      "implicit surfaces");
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
  MeshTopology topology;
  for (size_t i = 0, j; i < edges.size(); i = j) {
    for (j = i; j < edges.size() && edges[j].first == edges[i].first; ++j)
      unionFindJoin(parent, edges[j].second, edges[i].second);
    if (j - i != 2) ++topology.openEdges;
  }
  for (uint32_t t = 0; t < parent.size(); ++t) topology.components += unionFindRoot(parent, t) == t;
  return topology;
}

}  // namespace fibremss
