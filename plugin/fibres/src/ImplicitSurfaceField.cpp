// The implicit surface's field (ImplicitSurface.h): the rest distance grid, the particles'
// cells, the deformation of each particle's springs and the field itself.
#include <algorithm>
#include <array>
#include <cmath>

#include "ImplicitSurfaceInternal.h"

namespace fibremss {
namespace {

constexpr int32_t kBlock = 4;  ///< rest distance block side [points]
constexpr size_t kBlockValues = size_t(kBlock) * kBlock * kBlock;  ///< values per block
/// Particle cells per kernel radius [1]: the cells searched around a point then hold 2.5³ h³ on
/// average, against 3³ h³ with cells of h.
constexpr btScalar kCellsPerKernel = 2;
/// A vertex is taken for one of the thickened rest surface when the thickened distance at its
/// rest point lies within this many grid spacings of zero [1].
constexpr btScalar kOnThickened = btScalar(0.5);
/// Per set of odd axes (bit a: axis a): the share 1 / 2^(odd axes) of each coarse point around.
constexpr std::array<btScalar, 8> kCornerShare{1, 0.5f, 0.5f, 0.25f, 0.5f, 0.25f, 0.25f, 0.125f};

/// A step at rest mapped to now through the inverse of the map's derivative: false where the
/// derivative is singular.
bool mappedToNow(const btMatrix3x3& derivative, const btVector3& restStep, btVector3& step) {
  if (!(std::abs(derivative.determinant()) > btScalar(1e-6))) return false;
  step = derivative.inverse() * restStep;
  return true;
}

/// d·eᵀ.
btMatrix3x3 outer(const btVector3& d, const btVector3& e) {
  return btMatrix3x3(d.x() * e.x(), d.x() * e.y(), d.x() * e.z(), d.y() * e.x(), d.y() * e.y(),
                     d.y() * e.z(), d.z() * e.x(), d.z() * e.y(), d.z() * e.z());
}

/// Per particle, over its springs (those with a = b broken): Σ outer(x_b − x_a, X_b − X_a)
/// into `current`.
void currentMoments(std::span<const Spring> springs, std::span<const btVector3> positions,
                    std::span<const btVector3> restPositions, std::vector<btMatrix3x3>& current) {
  current.assign(positions.size(), btMatrix3x3(0, 0, 0, 0, 0, 0, 0, 0, 0));
  for (const Spring& spring : springs) {
    const btMatrix3x3 m = outer(positions[spring.b] - positions[spring.a],
                                restPositions[spring.b] - restPositions[spring.a]);
    current[spring.a] += m;
    current[spring.b] += m;
  }
}

/// Per particle, over its springs (those with a = b broken): Σ outer(X_b − X_a, X_b − X_a)
/// into `rest`.
void restMomentsOf(std::span<const Spring> springs, std::span<const btVector3> restPositions,
                   std::vector<btMatrix3x3>& rest) {
  rest.assign(restPositions.size(), btMatrix3x3(0, 0, 0, 0, 0, 0, 0, 0, 0));
  for (const Spring& spring : springs) {
    const btVector3 restEdge = restPositions[spring.b] - restPositions[spring.a];
    const btMatrix3x3 r = outer(restEdge, restEdge);
    rest[spring.a] += r;
    rest[spring.b] += r;
  }
}

/// Whether `springs` join the same particles as `whole`, spring for spring (none broken).
bool sameSprings(std::span<const Spring> springs, std::span<const Spring> whole) {
  return std::equal(springs.begin(), springs.end(), whole.begin(), whole.end(),
                    [](const Spring& s, const Spring& w) { return s.a == w.a && s.b == w.b; });
}

/// The median rest length of the muscle's springs [m] (1 mm without springs).
btScalar medianSpringLength(const MuscleSettings& muscle) {
  std::vector<btScalar> lengths;
  for (const Spring& spring : muscle.springs) lengths.push_back(spring.restLength);
  if (lengths.empty()) return btScalar(1e-3);
  std::nth_element(lengths.begin(), lengths.begin() + lengths.size() / 2, lengths.end());
  return lengths[lengths.size() / 2];
}

/// The rest surface's and particles' bounds.
void restBounds(const MuscleSettings& muscle, btVector3& lower, btVector3& upper) {
  pointBounds(muscle.restPositions, lower, upper);
  btVector3 surfaceLower, surfaceUpper;
  pointBounds(muscle.restSurface.vertices, surfaceLower, surfaceUpper);
  lower.setMin(surfaceLower);
  upper.setMax(surfaceUpper);
}

btScalar lengthUnit(const MuscleSettings& muscle, const ImplicitSurfaceSettings& settings) {
  return medianSpringLength(muscle) * (settings.voxel > 0 ? 1 : settings.voxelFactor);
}

/// The distance from x to the nearest of the rest particles, the boundary particles searched
/// first; once one lies within `reach`, that one's distance (the nearest's is no larger) [m].
btScalar nearestRestParticle(const MuscleSettings& muscle, const btVector3& x, btScalar reach) {
  btScalar nearest2 = SIMD_INFINITY;
  const btScalar reach2 = reach * reach;
  for (uint32_t p : muscle.boundaryParticles) {
    nearest2 = std::min(nearest2, (muscle.restPositions[p] - x).length2());
    if (nearest2 <= reach2) return btSqrt(nearest2);
  }
  for (const btVector3& p : muscle.restPositions) nearest2 = std::min(nearest2, (p - x).length2());
  return btSqrt(nearest2);
}

/// The rest surface's largest distance to its nearest rest particle, over its vertices and its
/// triangles' centroids [m].
btScalar restCoverReach(const MuscleSettings& muscle) {
  const TriangleMesh& surface = muscle.restSurface;
  btScalar largest = 0;
  auto take = [&](const btVector3& x) {
    largest = std::max(largest, nearestRestParticle(muscle, x, largest));
  };
  for (const btVector3& v : surface.vertices) take(v);
  for (const std::array<uint32_t, 3>& t : surface.triangles)
    take((surface.vertices[t[0]] + surface.vertices[t[1]] + surface.vertices[t[2]]) / 3);
  return largest;
}

/// h: kernelFactor median spring lengths, or more where the rest surface reaches farther from
/// the particles (coverMargin).
btScalar kernelRadiusOf(const MuscleSettings& muscle, const ImplicitSurfaceSettings& settings) {
  const btScalar h = medianSpringLength(muscle) * settings.kernelFactor;
  if (settings.coverMargin <= 0 || muscle.restPositions.empty()) return h;
  return std::max(h, settings.coverMargin * restCoverReach(muscle));
}

/// The thickening beside the muscle's fixed particles (ImplicitSurfaceSettings::tipThickening).
Thickening thickeningOf(const MuscleSettings& muscle, const ImplicitSurfaceSettings& settings,
                        btScalar voxel) {
  Thickening thickening;
  if (settings.tipThickening <= 0) return thickening;
  thickening.thickness = settings.tipThickening * voxel;
  thickening.reach = settings.tipReach * voxel;
  std::vector<btVector3> tips;
  for (uint32_t p : muscle.fixedParticles) tips.push_back(muscle.restPositions[p]);
  thickening.setTips(std::move(tips));
  return thickening;
}

GridFrame restFrame(const MuscleSettings& muscle, const ImplicitSurfaceSettings& settings,
                    btScalar h) {
  btVector3 lower, upper;
  restBounds(muscle, lower, upper);
  const btScalar voxel = settings.voxel > 0 ? settings.voxel : lengthUnit(muscle, settings);
  return GridFrame::covering(lower, upper, voxel * settings.restVoxelRatio, h + 2 * voxel);
}

}  // namespace

GridFrame GridFrame::covering(const btVector3& lower, const btVector3& upper, btScalar spacing,
                              btScalar pad) {
  GridFrame frame;
  frame.spacing = spacing;
  frame.origin = lower - btVector3(pad, pad, pad);
  const btVector3 extent = upper - lower + btVector3(2 * pad, 2 * pad, 2 * pad);
  for (int a = 0; a < 3; ++a) frame.dims[a] = int32_t(std::ceil(extent[a] / spacing)) + 2;
  return frame;
}

RayParity::RayParity(const TriangleMesh& surface) : surface_(surface) {
  btVector3 upper;
  pointBounds(surface.vertices, lower_, upper);
  const auto count = btScalar(std::max<size_t>(surface.triangles.size(), 1));
  cell_ = btMax((upper.y() - lower_.y()) * (upper.z() - lower_.z()) / count * 4, btScalar(1e-12));
  cell_ = btSqrt(cell_);
  for (int a = 0; a < 2; ++a) dims_[a] = int32_t((upper[a + 1] - lower_[a + 1]) / cell_) + 1;
  // Two passes over the triangles' bucket ranges: count, then fill.
  start_.assign(size_t(dims_[0]) * dims_[1] + 1, 0);
  auto forBuckets = [&](const std::array<uint32_t, 3>& t, auto&& fn) {
    btVector3 lo = surface.vertices[t[0]], hi = lo;
    for (uint32_t v : t) lo.setMin(surface.vertices[v]), hi.setMax(surface.vertices[v]);
    for (auto k = int32_t((lo.z() - lower_.z()) / cell_);
         k <= int32_t((hi.z() - lower_.z()) / cell_); ++k)
      for (auto j = int32_t((lo.y() - lower_.y()) / cell_);
           j <= int32_t((hi.y() - lower_.y()) / cell_); ++j)
        fn(size_t(j) + size_t(dims_[0]) * size_t(k));
  };
  for (const auto& t : surface.triangles) forBuckets(t, [&](size_t b) { ++start_[b + 1]; });
  for (size_t b = 0; b + 1 < start_.size(); ++b) start_[b + 1] += start_[b];
  triangles_.resize(start_.back());
  std::vector<uint32_t> fill(start_.begin(), start_.end() - 1);
  for (uint32_t t = 0; t < surface.triangles.size(); ++t)
    forBuckets(surface.triangles[t], [&](size_t b) { triangles_[fill[b]++] = t; });
}

void RayParity::crossings(const btVector3& p, std::vector<btScalar>& xs) const {
  xs.clear();
  const auto j = int32_t((p.y() - lower_.y()) / cell_), k = int32_t((p.z() - lower_.z()) / cell_);
  if (p.y() < lower_.y() || p.z() < lower_.z() || j >= dims_[0] || k >= dims_[1]) return;
  const size_t b = size_t(j) + size_t(dims_[0]) * size_t(k);
  for (uint32_t e = start_[b]; e < start_[b + 1]; ++e) {
    const auto& t = surface_.triangles[triangles_[e]];
    const btVector3 &a = surface_.vertices[t[0]], &u = surface_.vertices[t[1]],
                    &v = surface_.vertices[t[2]];
    // Barycentric coordinates of p in the triangle projected on yz, half-open at the edges.
    const btScalar d = (u.y() - a.y()) * (v.z() - a.z()) - (v.y() - a.y()) * (u.z() - a.z());
    if (d == 0) continue;
    const btScalar s1 = ((p.y() - a.y()) * (v.z() - a.z()) - (v.y() - a.y()) * (p.z() - a.z())) / d;
    const btScalar s2 = ((u.y() - a.y()) * (p.z() - a.z()) - (p.y() - a.y()) * (u.z() - a.z())) / d;
    if (s1 < 0 || s2 < 0 || s1 + s2 >= 1) continue;
    xs.push_back(a.x() + s1 * (u.x() - a.x()) + s2 * (v.x() - a.x()));
  }
}

btScalar Thickening::nearest(const btVector3& x) const {
  btScalar nearest2 = SIMD_INFINITY;
  for (uint32_t t : tips.near(x)) nearest2 = std::min(nearest2, (tips.points[t] - x).length2());
  return btSqrt(nearest2);
}

btScalar Thickening::at(btScalar nearest) const {
  if (!(nearest < 2 * reach)) return 0;
  const btScalar s = btMax(nearest / reach - 1, btScalar(0));  // 0 to 1 as it fades
  return thickness * (1 - s * s * (3 - 2 * s));
}

RestDistanceGrid::RestDistanceGrid(const TriangleMesh& surface, const GridFrame& frame,
                                   Thickening thickening)
    : distance_(surface), parity_(surface), frame_(frame), thickening_(std::move(thickening)) {
  for (int a = 0; a < 3; ++a) blocks_[a] = (frame.dims[a] + kBlock - 1) / kBlock;
  blockSlot_.assign(size_t(blocks_[0]) * blocks_[1] * blocks_[2], -1);
}

void RestDistanceGrid::fillBlock(int32_t bi, int32_t bj, int32_t bk, int32_t slot) {
  std::array<btVector3, kBlockValues> points;  // x fastest: a row of kBlock after another
  for (int32_t k = 0; k < kBlock; ++k)
    for (int32_t j = 0; j < kBlock; ++j)
      for (int32_t i = 0; i < kBlock; ++i)
        points[size_t(i + kBlock * (j + kBlock * k))] =
            frame_.point(bi * kBlock + i, bj * kBlock + j, bk * kBlock + k);
  const btScalar half = frame_.spacing * btScalar(kBlock - 1) / 2;
  std::array<btScalar, kBlockValues> distances;
  distance_.distances(
      frame_.point(bi * kBlock, bj * kBlock, bk * kBlock) + btVector3(half, half, half), points,
      distances);
  values_.resize(values_.size() + kBlockValues);
  float* out = values_.data() + size_t(slot) * kBlockValues;
  bool thickened = false;  // a point of the block thickened: its nearest points are kept
  for (size_t row = 0; row < kBlockValues; row += kBlock) {
    parity_.crossings(points[row], crossings_);
    for (size_t n = row; n < row + kBlock; ++n) {
      const btScalar thickness = thickeningAt(points[n]);
      thickened = thickened || thickness > 0;
      const btScalar d =
          RayParity::inside(points[n].x(), crossings_) ? distances[n] : -distances[n];
      out[n] = float(d + thickness);
    }
  }
  slotNearest_.push_back(-1);
  if (thickened) fillNearest(bi, bj, bk, slot);
}

void RestDistanceGrid::fillNearest(int32_t bi, int32_t bj, int32_t bk, int32_t slot) {
  slotNearest_[size_t(slot)] = int32_t(nearest_.size());
  for (int32_t k = 0; k < kBlock; ++k)
    for (int32_t j = 0; j < kBlock; ++j)
      for (int32_t i = 0; i < kBlock; ++i)
        nearest_.push_back(
            distance_.surfaceDistance()
                .closest(frame_.point(bi * kBlock + i, bj * kBlock + j, bk * kBlock + k))
                .point);
}

void RestDistanceGrid::thickenAlso(std::span<const btVector3> tips) {
  std::vector<btVector3> all = thickening_.tips.points;
  all.insert(all.end(), tips.begin(), tips.end());
  thickening_.setTips(std::move(all));
  std::fill(blockSlot_.begin(), blockSlot_.end(), -1);
  values_.clear();
  slotNearest_.clear();
  nearest_.clear();
}

void RestDistanceGrid::keepNearest(const btVector3& x, btScalar reach) {
  std::array<int32_t, 3> lo, hi;
  for (int a = 0; a < 3; ++a) {
    const btScalar u = (x[a] - frame_.origin[a]) / frame_.spacing;
    lo[size_t(a)] = std::max(int32_t(std::floor(u - reach / frame_.spacing)) / kBlock, 0);
    hi[size_t(a)] = std::min((int32_t(std::floor(u + reach / frame_.spacing)) + 1) / kBlock,
                             blocks_[size_t(a)] - 1);
  }
  for (int32_t bk = lo[2]; bk <= hi[2]; ++bk)
    for (int32_t bj = lo[1]; bj <= hi[1]; ++bj)
      for (int32_t bi = lo[0]; bi <= hi[0]; ++bi) {
        const int32_t slot = slotOf(bi, bj, bk);
        if (slotNearest_[size_t(slot)] < 0) fillNearest(bi, bj, bk, slot);
      }
}

int32_t RestDistanceGrid::filledSlot(int32_t bi, int32_t bj, int32_t bk) {
  const auto slot = int32_t(values_.size() / kBlockValues);
  fillBlock(bi, bj, bk, slot);
  return slot;
}

bool RestDistanceGrid::cellOf(const btVector3& x, RestCell& cell) {
  const btVector3 u = (x - frame_.origin) / frame_.spacing;
  // Per axis: the cell's lower and upper points' blocks and places within them.
  std::array<std::array<int32_t, 2>, 3> blockOf, placeIn;
  unsigned crossing = 0;  // bit a: the cell's upper points along axis a lie in the next block
  for (int a = 0; a < 3; ++a) {
    if (!(u[a] >= 0 && u[a] < btScalar(frame_.dims[a] - 1))) return false;
    const auto base = uint32_t(u[a]);  // unsigned: its division by the block side a shift
    const auto side = uint32_t(kBlock);
    cell.t[size_t(a)] = u[a] - btScalar(base);
    blockOf[a] = {int32_t(base / side), int32_t((base + 1) / side)};
    placeIn[a] = {int32_t(base % side), int32_t((base + 1) % side)};
    crossing |= unsigned(blockOf[a][0] != blockOf[a][1]) << a;
  }
  if (crossing == 0) {  // the cell within one block: its corners' places one step apart
    const int32_t slot = slotOf(blockOf[0][0], blockOf[1][0], blockOf[2][0]);
    const int32_t place = placeIn[0][0] + kBlock * (placeIn[1][0] + kBlock * placeIn[2][0]);
    for (unsigned c = 0; c < 8; ++c) {
      cell.slot[c] = slot;
      cell.place[c] =
          place + int32_t(c & 1) + kBlock * (int32_t(c >> 1 & 1) + kBlock * int32_t(c >> 2));
    }
    return true;
  }
  for (unsigned c = 0; c < 8; ++c) {
    const unsigned dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    cell.slot[c] = (c & crossing) != c ? cell.slot[c & crossing]
                                       : slotOf(blockOf[0][dx], blockOf[1][dy], blockOf[2][dz]);
    cell.place[c] = placeIn[0][dx] + kBlock * (placeIn[1][dy] + kBlock * placeIn[2][dz]);
  }
  return true;
}

btScalar RestDistanceGrid::at(const btVector3& x, btScalar outsideValue, bool& thickened) {
  RestCell cell;
  thickened = false;
  if (!cellOf(x, cell)) return -outsideValue;
  std::array<btScalar, 8> v;
  for (size_t c = 0; c < 8; ++c) {
    v[c] = values_[kBlockValues * size_t(cell.slot[c]) + size_t(cell.place[c])];
    thickened = thickened || slotNearest_[size_t(cell.slot[c])] >= 0;
  }
  // Along x, then y, then z.
  auto lerp = [](btScalar a, btScalar b, btScalar s) { return a + (b - a) * s; };
  const btScalar lower = lerp(lerp(v[0], v[1], cell.t[0]), lerp(v[2], v[3], cell.t[0]), cell.t[1]);
  const btScalar upper = lerp(lerp(v[4], v[5], cell.t[0]), lerp(v[6], v[7], cell.t[0]), cell.t[1]);
  return lerp(lower, upper, cell.t[2]);
}

bool RestDistanceGrid::closestAt(const btVector3& x, btVector3& closest, btScalar& value) {
  RestCell cell;
  if (!cellOf(x, cell)) return false;
  closest.setZero();
  value = 0;
  for (unsigned c = 0; c < 8; ++c) {
    const int32_t first = slotNearest_[size_t(cell.slot[c])];
    if (first < 0) return false;
    btScalar w = 1;
    for (size_t a = 0; a < 3; ++a) w *= (c >> a & 1) != 0 ? cell.t[a] : 1 - cell.t[a];
    closest += nearest_[size_t(first + cell.place[c])] * w;
    value += values_[kBlockValues * size_t(cell.slot[c]) + size_t(cell.place[c])] * w;
  }
  return true;
}

void ParticleCells::build(std::span<const btVector3> positions, btScalar cellSize) {
  btVector3 lower, upper;
  pointBounds(positions, lower, upper);
  frame = GridFrame::covering(lower, upper, cellSize, 0);
  const size_t count = size_t(frame.dims[0]) * frame.dims[1] * frame.dims[2];
  start.assign(count + 1, 0);
  order.resize(positions.size());
  auto cellOf = [&](const btVector3& p) {
    const btVector3 u = (p - frame.origin) / cellSize;
    return frame.index(int32_t(u.x()), int32_t(u.y()), int32_t(u.z()));
  };
  for (const btVector3& p : positions) ++start[cellOf(p) + 1];
  for (size_t c = 0; c < count; ++c) start[c + 1] += start[c];
  fill.assign(start.begin(), start.end() - 1);
  for (uint32_t i = 0; i < positions.size(); ++i) order[fill[cellOf(positions[i])]++] = i;
  sorted.resize(order.size());
  for (size_t e = 0; e < order.size(); ++e) sorted[e] = positions[order[e]];
}

ImplicitSurface::Impl::Impl(std::shared_ptr<const MuscleSettings> muscleIn,
                            const ImplicitSurfaceSettings& settingsIn)
    : muscle(std::move(muscleIn)),
      settings(settingsIn),
      voxel(settings.voxel > 0 ? settings.voxel : lengthUnit(*muscle, settings)),
      h(kernelRadiusOf(*muscle, settings)),
      rest(muscle->restSurface, restFrame(*muscle, settings, h),
           thickeningOf(*muscle, settings, voxel)) {
  const MeshDistance& distance = rest.surfaceDistance();
  outward.assign(muscle->particleCount(), btVector3(0, 0, 0));
  for (uint32_t i : muscle->boundaryParticles) {
    const MeshDistance::Closest closest = distance.closest(muscle->restPositions[i]);
    const btVector3 d = closest.point - muscle->restPositions[i];
    outward[i] = closest.inside ? d : -d;
  }
  restMomentsOf(muscle->springs, muscle->restPositions, wholeRestMoments);
  measureRestCover();
  if (settings.snapTolerance > 0) markRestErrors();
}

void ImplicitSurface::Impl::measureRestCover() {
  prepareFrames(muscle->restPositions, muscle->springs);
  btScalar smallest = SIMD_INFINITY;
  for (const btVector3& v : muscle->restSurface.vertices)
    smallest = std::min(smallest, coverage(v));
  kappa = std::isfinite(smallest) && smallest > 0 ? smallest / 2 : btScalar(1e-3);
}

void ImplicitSurface::Impl::prepareFrames(std::span<const btVector3> current,
                                          std::span<const Spring> springs) {
  positions = current;
  currentMoments(springs, current, muscle->restPositions, moments);
  const bool whole = sameSprings(springs, muscle->springs);
  spreadWeight = whole ? 0 : settings.spreadWeight;
  if (!whole) restMomentsOf(springs, muscle->restPositions, restMoments);
  const std::vector<btMatrix3x3>& rests = whole ? wholeRestMoments : restMoments;
  toRest.resize(current.size());
  for (size_t i = 0; i < current.size(); ++i) {
    // F⁻¹ = R·M⁻¹ with M = Σ dx·dXᵀ, R = Σ dX·dXᵀ (F = M·R⁻¹).
    const btMatrix3x3& m = moments[i];
    const btScalar scale = (m[0][0] + m[1][1] + m[2][2]) / 3;
    const bool spans = m.determinant() > btScalar(1e-3) * scale * scale * scale;
    toRest[i] = spans ? rests[i] * m.inverse() : btMatrix3x3::getIdentity();
  }
  cells.build(current, h / kCellsPerKernel);
  entries.resize(current.size());
  for (size_t e = 0; e < cells.order.size(); ++e) {
    const btVector3& p = cells.sorted[e];
    const btVector3& restPosition = muscle->restPositions[cells.order[e]];
    const btMatrix3x3& inverse = toRest[cells.order[e]];
    for (size_t a = 0; a < 3; ++a) {
      entries.array(EntryLanes::kX + a)[e] = p[int(a)];
      entries.array(EntryLanes::kRestX + a)[e] = restPosition[int(a)];
      for (size_t b = 0; b < 3; ++b)
        entries.array(EntryLanes::kToRest + 3 * a + b)[e] = inverse[int(a)][int(b)];
    }
  }
}

/// Σ w_j at x (the particles' cover), from `current` binned in `cells`.
btScalar ImplicitSurface::Impl::coverage(const btVector3& x) const {
  btScalar sum = 0;
  forNeighbours(x, [&](uint32_t, const btVector3&, btScalar w) { sum += w; });
  return sum;
}

// Also compiled for AVX, taken where the CPU has it: its three-operand instructions copy fewer
// registers, the operations the same (so the same results).
#if defined(__x86_64__) && defined(__GNUC__)
__attribute__((target_clones("avx", "default")))
#endif
RestMap
ImplicitSurface::Impl::restMap(const btVector3& x) const {
  // Four entries at a time, the lanes past a row's end weighed 0.
  const LaneMask lane{0, 1, 2, 3};
  const float inverseH2 = float(1 / (h * h));
  const std::array<float, 3> point{float(x.x()), float(x.y()), float(x.z())};
  Lanes weight{}, offsetX{}, offsetY{}, offsetZ{}, spread{};  // Σ w, Σ w·(X_j − x), Σ w·|X_j − x|²
  forNeighbourRows(x, [&](uint32_t begin, uint32_t end) FIBREMSS_INLINED {
    for (uint32_t e = begin; e < end; e += 4) {
      auto at = [&](size_t a) { return entries.load(a, e); };
      const Lanes dx = point[0] - at(EntryLanes::kX), dy = point[1] - at(EntryLanes::kY),
                  dz = point[2] - at(EntryLanes::kZ);
      const Lanes q = 1 - (dx * dx + dy * dy + dz * dz) * inverseH2;
      const LaneMask take = (q > 0) & (lane < int32_t(end - e));
      const Lanes w = Lanes(LaneMask(q * q * q) & take);
      auto mapped = [&](size_t a) {  // X_j − x along axis a: P_j + F_j⁻¹ (x − p_j) − x
        const size_t row = EntryLanes::kToRest + 3 * a;
        return at(EntryLanes::kRestX + a) + (at(row) * dx + at(row + 1) * dy + at(row + 2) * dz) -
               point[a];
      };
      const Lanes mx = mapped(0), my = mapped(1), mz = mapped(2);
      weight += w;
      offsetX += w * mx;
      offsetY += w * my;
      offsetZ += w * mz;
      spread += w * (mx * mx + my * my + mz * mz);
    }
  });
  auto sum = [](const Lanes& v) { return (v[0] + v[1]) + (v[2] + v[3]); };
  RestMap map;
  const btScalar total = sum(weight);
  if (total == 0) return map;
  map.offset = btVector3(sum(offsetX), sum(offsetY), sum(offsetZ)) / total;
  map.spread = btSqrt(btMax(sum(spread) / total - map.offset.length2(), btScalar(0)));
  map.weight = total;
  return map;
}

void ImplicitSurface::Impl::beginMaps() {
  coarse.origin = grid.origin;
  coarse.spacing = 2 * grid.spacing;
  for (int a = 0; a < 3; ++a) coarse.dims[a] = grid.dims[a] / 2 + 2;
  const size_t count = size_t(coarse.dims[0]) * coarse.dims[1] * coarse.dims[2];
  if (maps.size() < count) maps.resize(count);
  if (++mapStamp == 0) {  // wrapped: clear once
    for (RestMap& map : maps) map.stamp = 0;
    mapStamp = 1;
  }
}

void ImplicitSurface::Impl::fillCoarseMap(int32_t i, int32_t j, int32_t k, RestMap& map) const {
  map = restMap(coarse.point(i, j, k));
  map.stamp = mapStamp;
}

btScalar ImplicitSurface::Impl::field(int32_t i, int32_t j, int32_t k, bool& thickened) {
  // Along each axis where the index is odd the point lies halfway between two coarse points,
  // else on one: 2^(odd axes) corners, each of an equal share.
  const unsigned odd = unsigned(i & 1) | unsigned(j & 1) << 1 | unsigned(k & 1) << 2;
  const btScalar share = kCornerShare[odd];
  btVector3 offset(0, 0, 0);
  btScalar spread = 0, weight = 0;
  bool covered = true;  // every coarse point around has particles within h
  for (unsigned c = 0; c < 8; ++c) {
    if ((c & odd) != c) continue;
    const RestMap& map = coarseMap((i >> 1) + int32_t(c & 1), (j >> 1) + int32_t(c >> 1 & 1),
                                   (k >> 1) + int32_t(c >> 2 & 1));
    covered = covered && map.weight > 0;
    offset += map.offset;
    spread += map.spread;
    weight += map.weight;
  }
  offset *= share;
  spread *= share;
  weight *= share;
  const btVector3 x = grid.point(i, j, k);
  if (!covered) {  // the interpolation would mix in their empty maps: the map here instead
    const RestMap map = restMap(x);
    offset = map.offset;
    spread = map.spread;
    weight = map.weight;
  }
  btScalar value = -h;
  thickened = false;
  if (weight > 0) {
    const btScalar distance = rest.at(x + offset, h, thickened) - spreadWeight * spread;
    value = std::min(distance, h * (weight / kappa - 1));
  }
  for (const SurfaceDent& dent : dents) {
    const btScalar q = 1 - (x - dent.centre).length2() / (dent.radius * dent.radius);
    // A dented vertex is not thinned: the dent takes the thickening off, wholly at its centre.
    if (q > 0) value -= dent.depth * q * q * q + q * rest.thickeningAt(x + offset);
  }
  return value;
}

bool ImplicitSurface::Impl::mapAt(const btVector3& x, btVector3& offset, btMatrix3x3& derivative) {
  const btVector3 u = (x - coarse.origin) / coarse.spacing;
  std::array<int32_t, 3> base;
  std::array<btScalar, 3> t;
  for (size_t a = 0; a < 3; ++a) {
    base[a] = std::clamp(int32_t(u[int(a)]), 0, coarse.dims[a] - 2);
    t[a] = u[int(a)] - btScalar(base[a]);
  }
  std::array<const RestMap*, 8> around;
  for (unsigned c = 0; c < 8; ++c) {
    around[c] = &coarseMap(base[0] + int32_t(c & 1), base[1] + int32_t(c >> 1 & 1),
                           base[2] + int32_t(c >> 2 & 1));
    if (around[c]->weight == 0) {  // the interpolation would mix in an empty map: x's own
      const RestMap own = restMap(x);
      offset = own.offset;
      derivative = btMatrix3x3::getIdentity();
      return own.weight > 0;
    }
  }
  // Trilinear along x, then y, then z, each stage's derivatives along the axes before it.
  std::array<btVector3, 4> alongX, slopeX;
  for (size_t q = 0; q < 4; ++q) {
    slopeX[q] = around[2 * q + 1]->offset - around[2 * q]->offset;
    alongX[q] = around[2 * q]->offset + slopeX[q] * t[0];
  }
  const std::array<btVector3, 2> alongY{alongX[0] + (alongX[1] - alongX[0]) * t[1],
                                        alongX[2] + (alongX[3] - alongX[2]) * t[1]},
      slopeYX{slopeX[0] + (slopeX[1] - slopeX[0]) * t[1],
              slopeX[2] + (slopeX[3] - slopeX[2]) * t[1]},
      slopeY{alongX[1] - alongX[0], alongX[3] - alongX[2]};
  offset = alongY[0] + (alongY[1] - alongY[0]) * t[2];
  const btVector3 dx = (slopeYX[0] + (slopeYX[1] - slopeYX[0]) * t[2]) / coarse.spacing,
                  dy = (slopeY[0] + (slopeY[1] - slopeY[0]) * t[2]) / coarse.spacing,
                  dz = (alongY[1] - alongY[0]) / coarse.spacing;
  derivative = btMatrix3x3(1 + dx.x(), dy.x(), dz.x(), dx.y(), 1 + dy.y(), dz.y(), dx.z(), dy.z(),
                           1 + dz.z());
  return true;
}

bool ImplicitSurface::Impl::thinningStep(const btVector3& x, btVector3& step, btVector3& onRest) {
  for (const SurfaceDent& dent : dents)  // the dent, not the rest surface, places it
    if ((x - dent.centre).length2() < dent.radius * dent.radius) return false;
  btVector3 offset;
  btMatrix3x3 derivative;
  if (!mapAt(x, offset, derivative)) return false;
  btScalar value;
  // Only a vertex of the thickened rest surface: not one a dent, the cover or the spread placed.
  if (!rest.closestAt(x + offset, onRest, value) || !(std::abs(value) < kOnThickened * voxel))
    return false;
  const btVector3 restStep = onRest - (x + offset);
  const btScalar largest = btScalar(1.5) * settings.tipThickening * voxel;
  return restStep.length2() <= largest * largest && mappedToNow(derivative, restStep, step);
}

bool ImplicitSurface::Impl::mappedStep(const btVector3& x, const btVector3& target,
                                       btVector3& step) {
  btVector3 offset;
  btMatrix3x3 derivative;
  return mapAt(x, offset, derivative) && mappedToNow(derivative, target - (x + offset), step);
}

void PointCells::build(std::vector<btVector3> pointsIn, btScalar reach) {
  points = std::move(pointsIn);
  start.clear();
  listed.clear();
  if (points.empty() || !(reach > 0)) return;  // none listed
  btVector3 lower, upper;
  pointBounds(points, lower, upper);
  frame = GridFrame::covering(lower, upper, reach, reach);
  start.assign(size_t(frame.dims[0]) * frame.dims[1] * frame.dims[2] + 1, 0);
  // Two passes over each point's cells within reach: count, then fill.
  auto forCells = [&](const btVector3& p, auto&& fn) {
    const btVector3 lo = (p - frame.origin) / reach - btVector3(1, 1, 1),
                    hi = (p - frame.origin) / reach + btVector3(1, 1, 1);
    for (auto k = int32_t(lo.z()); k <= int32_t(hi.z()); ++k)
      for (auto j = int32_t(lo.y()); j <= int32_t(hi.y()); ++j)
        for (auto i = int32_t(lo.x()); i <= int32_t(hi.x()); ++i) fn(frame.index(i, j, k));
  };
  for (const btVector3& p : points) forCells(p, [&](uint32_t c) { ++start[c + 1]; });
  for (size_t c = 0; c + 1 < start.size(); ++c) start[c + 1] += start[c];
  listed.resize(start.back());
  std::vector<uint32_t> fill(start.begin(), start.end() - 1);
  for (uint32_t a = 0; a < points.size(); ++a)
    forCells(points[a], [&](uint32_t c) { listed[fill[c]++] = a; });
}

std::span<const uint32_t> PointCells::near(const btVector3& x) const {
  if (start.empty()) return {};
  const btVector3 u = (x - frame.origin) / frame.spacing;
  for (int a = 0; a < 3; ++a)
    if (!(u[a] >= 0 && u[a] < btScalar(frame.dims[a]))) return {};
  const uint32_t c = frame.index(int32_t(u.x()), int32_t(u.y()), int32_t(u.z()));
  return {listed.data() + start[c], start[c + 1] - start[c]};
}

}  // namespace fibremss
