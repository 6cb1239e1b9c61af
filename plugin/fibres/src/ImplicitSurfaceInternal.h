#pragma once
// ImplicitSurface's state (ImplicitSurface.h): the field's parts and the sparse grid it is
// extracted on.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include "ClusterDistance.h"
#include "fibremss/ImplicitSurface.h"

namespace fibremss {

/// A regular grid of points: point (i, j, k) at origin + (i, j, k)·spacing.
struct GridFrame {
  btVector3 origin{0, 0, 0};             ///< point (0, 0, 0) [m]
  btScalar spacing = 1;                  ///< [m]
  std::array<int32_t, 3> dims{0, 0, 0};  ///< points per axis

  /// A frame covering [lower, upper] with `pad` [m] on every side.
  static GridFrame covering(const btVector3& lower, const btVector3& upper, btScalar spacing,
                            btScalar pad);
  uint32_t index(int32_t i, int32_t j, int32_t k) const {
    return uint32_t(i + dims[0] * (j + dims[1] * k));
  }
  btVector3 point(int32_t i, int32_t j, int32_t k) const {
    return origin + btVector3(btScalar(i), btScalar(j), btScalar(k)) * spacing;
  }
};

/// Whether points lie inside a closed triangle surface, by the parity of the surface's crossings
/// of a ray along +x: the inside's boundary is the surface even where it folds through itself
/// (where the sign of the nearest triangle's pseudo-normal jumps away from the surface).
class RayParity {
 public:
  explicit RayParity(const TriangleMesh& surface);
  /// The x of the surface's crossings of the ray along +x through p's y and z, into `xs` (in
  /// the surface's order): the ray of every point with those y and z.
  void crossings(const btVector3& p, std::vector<btScalar>& xs) const;
  /// Whether the point at x on a ray lies inside: an odd count of the ray's crossings beyond x.
  static bool inside(btScalar x, std::span<const btScalar> xs) {
    return std::count_if(xs.begin(), xs.end(), [x](btScalar c) { return c > x; }) % 2 != 0;
  }

 private:
  const TriangleMesh& surface_;
  btVector3 lower_{0, 0, 0};           ///< the surface's lower corner [m]
  btScalar cell_ = 1;                  ///< bucket side in y and z [m]
  std::array<int32_t, 2> dims_{0, 0};  ///< buckets along y and z
  std::vector<uint32_t> start_;        ///< per bucket + 1: first entry in triangles_
  std::vector<uint32_t> triangles_;    ///< triangles whose yz bounds meet each bucket
};

/// Points, each listed in every cell of `frame` within `reach` of it, so that the list of a
/// point's cell holds every point within reach of it (and some farther).
struct PointCells {
  std::vector<btVector3> points;  ///< [m]
  GridFrame frame;                ///< cells of side `reach`: frame points their lower corners
  std::vector<uint32_t> start;    ///< per cell + 1: first entry in `listed`
  std::vector<uint32_t> listed;   ///< indices in `points`, cell after cell

  void build(std::vector<btVector3> points, btScalar reach);
  /// The points listed in x's cell, every point within reach of x among them.
  std::span<const uint32_t> near(const btVector3& x) const;
};

/// Where the rest surface is thickened: by `thickness` within `reach` of a tip point (the
/// attachments' fixed particles at rest, beside which the tendons end in points thinner than a
/// grid cell), fading out (smoothly) over the next `reach`.
struct Thickening {
  PointCells tips;         ///< [m], listed within 2·reach (beyond, no thickening)
  btScalar thickness = 0;  ///< [m]
  btScalar reach = 0;      ///< [m]

  void setTips(std::vector<btVector3> points) { tips.build(std::move(points), 2 * reach); }
  /// The distance from rest point x to the nearest tip, where one lies within 2·reach; else
  /// that or more (infinite where none is listed) [m].
  btScalar nearest(const btVector3& x) const;
  btScalar at(btScalar nearest) const;  ///< the thickening at `nearest` from a tip [m]
};

/// A point's cell of the rest distance grid: its corners' blocks' slots and their places in
/// them (corner c at offset (c & 1, c >> 1 & 1, c >> 2 & 1)), and the point's place in the cell
/// along each axis [0, 1).
struct RestCell {
  std::array<int32_t, 8> slot{};   ///< per corner: its block's slot
  std::array<int32_t, 8> place{};  ///< per corner: its place in its block
  std::array<btScalar, 3> t{};     ///< [1]
};

/// The rest surface's signed distance (positive inside) on a grid, each block of 4³ points
/// computed the first time a lookup reaches it: its distances searched among the triangles that
/// can be nearest to any of its points (ClusterDistance), its signs from one ray per row; plus
/// the thickening where there is one.
class RestDistanceGrid {
 public:
  RestDistanceGrid(const TriangleMesh& surface, const GridFrame& frame, Thickening thickening);
  /// D + thickening, trilinear in the grid; outside the grid −outsideValue. `thickened`: a
  /// block of the point's cell holds a thickened point.
  btScalar at(const btVector3& x, btScalar outsideValue, bool& thickened);
  /// `tips` thickened about too: every block computed again as it is reached.
  void thickenAlso(std::span<const btVector3> tips);
  /// The thickening at rest point x [m].
  btScalar thickeningAt(const btVector3& x) const {
    return thickening_.tips.points.empty() ? 0 : thickening_.at(thickening_.nearest(x));
  }
  /// The blocks within `reach` of x keep their points' nearest rest surface points (closestAt).
  void keepNearest(const btVector3& x, btScalar reach);
  /// The rest surface's point nearest to x, trilinear between the grid points' nearest, and
  /// D + thickening there: false outside the grid or where a corner's block keeps none.
  bool closestAt(const btVector3& x, btVector3& closest, btScalar& value);
  /// Closest points on the rest surface, one point at a time.
  const MeshDistance& surfaceDistance() const { return distance_.surfaceDistance(); }

 private:
  /// The slot of block (bi, bj, bk)'s values (4³ from its lower corner, x fastest), filled
  /// the first time; a fill may move every block's values.
  int32_t slotOf(int32_t bi, int32_t bj, int32_t bk) {
    int32_t& slot = blockSlot_[size_t(bi) + size_t(blocks_[0]) * (bj + size_t(blocks_[1]) * bk)];
    if (slot < 0) slot = filledSlot(bi, bj, bk);
    return slot;
  }
  /// Block (bi, bj, bk)'s values filled into a new slot, that slot.
  int32_t filledSlot(int32_t bi, int32_t bj, int32_t bk);
  void fillBlock(int32_t bi, int32_t bj, int32_t bk, int32_t slot);
  /// Block (bi, bj, bk)'s points' nearest rest surface points into nearest_, its slot's entry.
  void fillNearest(int32_t bi, int32_t bj, int32_t bk, int32_t slot);
  /// x's cell, every corner's block filled: false outside the grid.
  bool cellOf(const btVector3& x, RestCell& cell);

  ClusterDistance distance_;
  RayParity parity_;
  GridFrame frame_;
  Thickening thickening_;
  std::vector<btScalar> crossings_;         ///< scratch: a row's ray's crossings [m]
  std::array<int32_t, 3> blocks_{0, 0, 0};  ///< blocks per axis
  std::vector<int32_t> blockSlot_;          ///< per block: its values' slot, −1 not yet
  std::vector<float> values_;               ///< 64 per computed block: D + thickening [m]
  /// Per slot: the first of its points' nearest rest surface points in nearest_, −1 where the
  /// block lies beyond the thickening's reach.
  std::vector<int32_t> slotNearest_;
  std::vector<btVector3> nearest_;  ///< 64 per block the thickening reaches [m]
};

/// Per anchor, in one extraction: the moved vertex whose nearest rest surface point (where
/// thinningStep moves it) lies nearest the anchor.
struct AnchorPick {
  int32_t vertex = -1;        ///< −1: none within reach
  btScalar distance2 = 0;     ///< that point's squared distance to the anchor [m²]
  btVector3 before{0, 0, 0};  ///< the vertex where the march made it [m]
};

/// The particles binned into cells (counting sort).
struct ParticleCells {
  GridFrame frame;                ///< cells: frame points are their lower corners
  std::vector<uint32_t> start;    ///< per cell + 1: first entry in `order`
  std::vector<uint32_t> order;    ///< particle indices, cell after cell
  std::vector<uint32_t> fill;     ///< scratch: per cell, its next entry in `order`
  std::vector<btVector3> sorted;  ///< per entry of `order`: its particle's position [m]

  void build(std::span<const btVector3> positions, btScalar cellSize);
};

/// Per grid point of the extraction: its field value and the vertices on its 7 edges that go
/// to a point above it (+x, +y, +x+y, +z, +x+z, +y+z, +x+y+z; indexed by the offset's bits − 1),
/// and whether the cell it is the lower corner of was queued.
struct GridEntry {
  float value = 0;                      ///< field [m]
  bool known = false;                   ///< value computed
  bool queued = false;                  ///< its cell queued
  bool thickened = false;               ///< its rest point's cell thickened
  std::array<int32_t, 7> edgeVertex{};  ///< vertex index per edge, −1 none
};

/// Where the particles map a point back to rest: the w-weighted mean of X_j − x, their spread
/// σ and W = Σ w_j (ImplicitSurface.h). Valid in the extraction `stamp` names.
struct RestMap {
  uint32_t stamp = 0;         ///< extraction that wrote it
  btVector3 offset{0, 0, 0};  ///< X̄ − x [m]
  btScalar spread = 0;        ///< σ [m]
  btScalar weight = 0;        ///< W [1]
};

/// Inlined into its caller, whose target (an instruction set it is compiled for) it then takes.
#if defined(__GNUC__)
#define FIBREMSS_INLINED __attribute__((always_inline))
#else
#define FIBREMSS_INLINED
#endif

/// Four floats, one per lane (the compiler's vector extension: SIMD where the target has it).
using Lanes = float __attribute__((vector_size(16)));
using LaneMask = int32_t __attribute__((vector_size(16)));

/// Per entry of ParticleCells::order: its particle's current position p, rest position P and
/// F⁻¹ (row after row), one array of floats per coordinate, read four entries at a time.
class EntryLanes {
 public:
  enum Array : size_t { kX, kY, kZ, kRestX, kRestY, kRestZ, kToRest, kArrays = kToRest + 9 };
  /// Room for `count` entries per array, and 3 more (the lanes read past a row's last entry).
  void resize(size_t count) {
    stride_ = count + 3;
    if (values_.size() != kArrays * stride_) values_.assign(kArrays * stride_, 0);
  }
  float* array(size_t a) { return values_.data() + a * stride_; }
  /// Entries e to e + 3 of array a.
  Lanes load(size_t a, size_t e) const {
    Lanes v;
    std::memcpy(&v, values_.data() + a * stride_ + e, sizeof v);
    return v;
  }

 private:
  size_t stride_ = 0;          ///< floats per array
  std::vector<float> values_;  ///< kArrays arrays of stride_ floats
};

/// The ray along which a seed is searched beside a boundary particle: steps of `step` from
/// `start` along `direction`, the rest surface expected at step `expected`.
struct SeedRay {
  btVector3 start{0, 0, 0};      ///< the particle [m]
  btVector3 direction{1, 0, 0};  ///< outward, unit [1]
  btScalar step = 0;             ///< [m]
  int steps = 0;                 ///< steps along the ray
  int expected = 0;              ///< the step nearest the expected surface
};

/// The extraction grid's entries in blocks of 4³ points, a block taken from a pool the first
/// time an extraction reaches it (a cell's corners then mostly in one block); emptied by
/// advancing the stamp (no clearing).
class GridTable {
 public:
  void begin(const GridFrame& grid);  ///< a new extraction over `grid`: every block stale
  /// The entry of grid point (i, j, k), fresh if its block was stale.
  GridEntry& at(int32_t i, int32_t j, int32_t k) {
    const size_t b = blockOf(i, j, k);
    if (blockStamp_[b] != stamp_) take(b);
    return entries_[blockSlot_[b] + pointOf(i, j, k)];
  }
  /// The entries of the cell's corners, corner c at (i, j, k) + (c & 1, c >> 1 & 1, c >> 2 & 1),
  /// fresh where their blocks were stale: valid until the table takes another block.
  std::array<GridEntry*, 8> corners(int32_t i, int32_t j, int32_t k);

 private:
  size_t blockOf(int32_t i, int32_t j, int32_t k) const {
    return size_t(i >> 2) + size_t(blocks_[0]) * size_t((j >> 2) + blocks_[1] * (k >> 2));
  }
  /// The point's entry within its block.
  static size_t pointOf(int32_t i, int32_t j, int32_t k) {
    return size_t(i & 3) + 4 * size_t((j & 3) + 4 * (k & 3));
  }
  void take(size_t block);                  ///< gives the block a slot of fresh entries
  std::array<int32_t, 3> blocks_{0, 0, 0};  ///< blocks per axis
  std::vector<uint32_t> blockStamp_;        ///< per block: the extraction that took it
  std::vector<uint32_t> blockSlot_;         ///< per block: its first entry in entries_
  std::vector<GridEntry> entries_;          ///< 64 per slot taken, x fastest
  uint32_t stamp_ = 0;                      ///< this extraction's stamp
  size_t taken_ = 0;                        ///< entries taken this extraction
};

struct ImplicitSurface::Impl {
  Impl(std::shared_ptr<const MuscleSettings> muscle, const ImplicitSurfaceSettings& settings);

  // The field (ImplicitSurfaceField.cpp).
  void prepareFrames(std::span<const btVector3> positions, std::span<const Spring> springs);
  /// The particles' map back to rest at x (weight 0 where no particle is within h).
  RestMap restMap(const btVector3& x) const;
  /// A new extraction's coarse grid over `grid`, every map stale.
  void beginMaps();
  /// The map at point (i, j, k) of the coarse grid (every second extraction grid point), cached.
  const RestMap& coarseMap(int32_t i, int32_t j, int32_t k) {
    RestMap& map = maps[coarse.index(i, j, k)];
    if (map.stamp != mapStamp) fillCoarseMap(i, j, k, map);
    return map;
  }
  /// `map`, coarse point (i, j, k)'s, computed for this extraction.
  void fillCoarseMap(int32_t i, int32_t j, int32_t k, RestMap& map) const;
  /// The field at extraction grid point (i, j, k): the map interpolated (trilinear) between the
  /// coarse points around it, which is exact at rest (where X̄ − x = 0 everywhere), then D.
  btScalar field(int32_t i, int32_t j, int32_t k, bool& thickened);
  /// The map back to rest at x interpolated (trilinear) between the coarse points around it
  /// and its derivative ∂X̄/∂x; at x itself, the derivative I, where one has no particle within
  /// h: false where x has none.
  bool mapAt(const btVector3& x, btVector3& offset, btMatrix3x3& derivative);
  /// The step that takes vertex x, made where the thickened rest surface crosses a cell's
  /// edge, onto the rest surface mapped to now: from its rest point to that point's nearest rest
  /// surface point, mapped through (∂X̄/∂x)⁻¹, into `step`, and that nearest point into `onRest`;
  /// false (none) where the step would be longer than the thickening (a vertex the field's cover
  /// or spread placed) or under a dent.
  bool thinningStep(const btVector3& x, btVector3& step, btVector3& onRest);
  /// The step that takes x's rest point to `target` at rest, mapped to now as in thinningStep;
  /// false where x has no map or its derivative is singular.
  bool mappedStep(const btVector3& x, const btVector3& target, btVector3& step);
  /// The vertices on the edges of a corner whose rest point's cell keeps nearest points (beside
  /// the tips and where the rest extraction erred) moved onto the rest surface (thinningStep),
  /// then each anchor's nearest of them onto the anchor (pinToAnchors).
  void thin();
  /// Each anchor's picked vertex moved onto it (mapped to now), a vertex to one anchor at most.
  void pinToAnchors();
  btScalar coverage(const btVector3& x) const;
  void measureRestCover();
  /// fn(begin, end) for each row of particle cells within h of x along every axis: the
  /// entries [begin, end) of cells.order (the cells of a row along x hold consecutive entries).
  template <class Fn>
  FIBREMSS_INLINED void forNeighbourRows(const btVector3& x, Fn&& fn) const {
    const btVector3 u = (x - cells.frame.origin) / cells.frame.spacing;
    const btScalar reach = h / cells.frame.spacing;
    std::array<int32_t, 3> lo, hi;
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::max(int32_t(std::floor(u[a] - reach)), 0);
      hi[a] = std::min(int32_t(std::floor(u[a] + reach)), cells.frame.dims[a] - 1);
      if (lo[a] > hi[a]) return;
    }
    for (int32_t k = lo[2]; k <= hi[2]; ++k)
      for (int32_t j = lo[1]; j <= hi[1]; ++j)
        fn(cells.start[cells.frame.index(lo[0], j, k)],
           cells.start[cells.frame.index(hi[0], j, k) + 1]);
  }
  /// fn(entry, x − p, w) for every particle binned in `cells` within h of x, by its entry in
  /// cells.order.
  template <class Fn>
  void forNeighbours(const btVector3& x, Fn&& fn) const {
    const btScalar inverseH2 = 1 / (h * h);
    forNeighbourRows(x, [&](uint32_t begin, uint32_t end) {
      for (uint32_t e = begin; e < end; ++e) {
        const btVector3 d = x - cells.sorted[e];
        const btScalar q = 1 - d.length2() * inverseH2;
        if (q > 0) fn(e, d, q * q * q);
      }
    });
  }

  // The extraction (ImplicitSurface.cpp).
  /// The surface of the particles at `current` into `mesh` (ImplicitSurface::extract).
  void extract(std::span<const btVector3> current, std::span<const Spring> springs);
  /// Once, at rest: around the extracted vertices farther than snapTolerance from the rest
  /// surface, the rest distance grid keeps its points' nearest rest surface points, so that the
  /// vertices made there are moved onto the rest surface as at the tips (thin).
  void markRestErrors();
  /// The surface extracted at rest (its vertices moved as they stand), and the rest surface's
  /// vertices farther than snapTolerance from it.
  std::vector<btVector3> missedRestVertices();
  /// Once, at rest, at the end of markRestErrors: the rest surface's vertices that the surface
  /// extracted at rest (its vertices moved) misses by more than snapTolerance become anchors,
  /// the blocks around them keeping their nearest points.
  void findAnchors();
  /// Once, at rest, before markRestErrors: the rest surface's vertices farther than
  /// snapTolerance from the surface extracted at rest (tendons' ends beyond the fixed
  /// particles' reach) thickened about too.
  void thickenMissedTips();
  /// The cell's corners' entries (corner c at offset (c & 1, c >> 1 & 1, c >> 2 & 1)), their
  /// field values computed where not yet known and copied into `values`.
  std::array<GridEntry*, 8> cellCorners(const std::array<int32_t, 3>& cell,
                                        std::array<float, 8>& values);
  /// Queues `cell` once, when it lies inside the grid.
  void enqueue(const std::array<int32_t, 3>& cell);
  bool inGrid(const std::array<int32_t, 3>& cell) const {
    for (int a = 0; a < 3; ++a)
      if (cell[a] < 0 || cell[a] + 1 >= grid.dims[a]) return false;
    return true;
  }
  /// The ray a seed beside boundary particle p is searched along.
  SeedRay seedRay(uint32_t p) const;
  /// The ray's n-th cell searched (its steps from the expected one alternately in and out), into
  /// `cell`; false when that step is off the ray or the cell outside the grid.
  bool probeCell(const SeedRay& ray, int n, std::array<int32_t, 3>& cell) const;
  /// Seeds the surface beside boundary particle p: the first cell holding both signs on the ray
  /// along its outward direction, searched from where its rest depth puts the surface. False
  /// when none, or when any cell on the ray was queued already (a surface found there).
  bool seedFrom(uint32_t p);
  /// Every boundary particle's seed, each marched before the next (its cells then queued).
  void seedAndMarch();
  /// Polygonises the queued cells from `marched` on, queueing the cells the surface goes on to.
  void march();
  /// Drops the mesh's pieces (vertices joined by triangles) that enclose less than
  /// kSmallestPieceCells grid cells, the largest piece always kept: beads of a part thinner than
  /// a cell (a tendon's pointed end), which the grid's points meet only here and there.
  void dropSpecks();
  /// The cell's triangles, its corners inside (value > 0) the bits of `inside`.
  void polygonise(const std::array<int32_t, 3>& cell, const std::array<GridEntry*, 8>& corners,
                  const std::array<float, 8>& values, unsigned inside);
  /// A new vertex where the field crosses zero on the cell's edge from corner u to corner v.
  uint32_t newVertex(const std::array<int32_t, 3>& cell, int u, int v,
                     const std::array<float, 8>& values);

  std::shared_ptr<const MuscleSettings> muscle;
  ImplicitSurfaceSettings settings;
  btScalar voxel = 0;     ///< extraction grid spacing [m]
  btScalar h = 0;         ///< kernel radius [m]
  btScalar kappa = 0;     ///< κ: half the smallest W on the rest surface [1]
  RestDistanceGrid rest;  ///< D, thickened at the tips
  /// Per boundary particle: from it to the nearest rest surface point, made to point outward [m].
  std::vector<btVector3> outward;
  std::vector<SurfaceDent> dents;

  // Per extraction.
  std::span<const btVector3> positions;  ///< the particles
  /// λ: settings.spreadWeight where a spring is broken, else 0 (particles that cannot part
  /// open no surface: their spread is the error of their affine maps where they deform) [1].
  btScalar spreadWeight = 0;
  std::vector<btMatrix3x3> toRest;       ///< per particle F⁻¹ (identity when degenerate)
  EntryLanes entries;                    ///< per entry of cells.order: p, P and F⁻¹
  std::vector<btMatrix3x3> moments;      ///< scratch: Σ dx·dXᵀ over the unbroken springs [m²]
  std::vector<btMatrix3x3> restMoments;  ///< scratch: Σ dX·dXᵀ over the unbroken springs [m²]
  /// Per particle Σ dX·dXᵀ over all the muscle's springs (none broken) [m²].
  std::vector<btMatrix3x3> wholeRestMoments;
  ParticleCells cells;
  GridFrame grid;  ///< extraction grid
  GridTable table;
  GridFrame coarse;                           ///< every second point of the extraction grid
  std::vector<RestMap> maps;                  ///< per coarse point, valid when stamped mapStamp
  uint32_t mapStamp = 0;                      ///< this extraction's stamp of `maps`
  std::vector<std::array<int32_t, 3>> queue;  ///< cells to polygonise
  size_t marched = 0;                         ///< queue entries polygonised
  /// Per vertex: its union-find parent, vertices joined by triangles (the mesh's pieces).
  std::vector<uint32_t> pieceOf;
  std::vector<uint32_t> thickVertices;  ///< vertices on an edge from a thickened corner
  /// Rest points the surface is pinned to: the rest surface's vertices the surface extracted at
  /// rest misses (pits, which no vertex moved to its nearest rest surface point reaches), listed
  /// within a grid spacing.
  PointCells anchors;
  std::vector<AnchorPick> picks;    ///< per anchor: its vertex in this extraction
  std::vector<uint8_t> pinned;      ///< scratch per vertex: moved onto an anchor
  std::vector<double> pieceVolume;  ///< scratch per root vertex: its piece's volume [m³]
  std::vector<int32_t> vertexKept;  ///< scratch per vertex: its new index, −1 dropped
  TriangleMesh mesh;
};

}  // namespace fibremss
