// Distances from a cluster of points to a triangle surface (ClusterDistance.h).
#include "ClusterDistance.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <utility>

#include "fibremss/TrianglePoint.h"

namespace fibremss {
namespace {

/// The searches' bounds are widened by this share of the surface's coordinates and extent: far
/// more than the rounding of a distance (a float's relative precision is 6e-8), far less than a
/// triangle.
constexpr btScalar kSlackShare = btScalar(1e-5);

/// Calls fn(leaf) for each of the tree's leaves that meet the query box.
template <class Fn>
struct LeafVisitor : btDbvt::ICollide {
  explicit LeafVisitor(Fn fn) : fn_(std::move(fn)) {}
  void Process(const btDbvtNode* leaf) override { fn_(leaf); }
  Fn fn_;
};

/// kGroup coordinates, one per lane (the compiler's vector extension: SIMD where the target has
/// it), and per lane a comparison's outcome (all bits set where true).
using Lanes = btScalar __attribute__((vector_size(16)));
using LaneMask = decltype(Lanes{} < Lanes{});

/// Entries c to c + kGroup − 1 of `values`.
Lanes load(const std::vector<btScalar>& values, size_t c) {
  Lanes v;
  std::memcpy(&v, values.data() + c, sizeof v);
  return v;
}

}  // namespace

ClusterDistance::ClusterDistance(const TriangleMesh& surface)
    : surface_(surface), distance_(surface), tree_(std::make_unique<btDbvt>()) {
  btVector3 lower, upper;
  pointBounds(surface.vertices, lower, upper);
  btVector3 magnitude = lower.absolute();
  magnitude.setMax(upper.absolute());
  slack_ = kSlackShare * (magnitude.length() + (upper - lower).length());
  for (uint32_t t = 0; t < surface.triangles.size(); ++t) {
    const auto& corners = surface.triangles[t];
    btVector3 lo = surface.vertices[corners[0]], hi = lo;
    for (uint32_t v : corners) lo.setMin(surface.vertices[v]), hi.setMax(surface.vertices[v]);
    tree_->insert(btDbvtVolume::FromMM(lo, hi), reinterpret_cast<void*>(uintptr_t(t)));
  }
  tree_->optimizeTopDown();
}

ClusterDistance::~ClusterDistance() = default;

void ClusterDistance::gather(const btVector3& centre, btScalar reach) {
  candidates_.clear();
  LeafVisitor visitor([&](const btDbvtNode* leaf) {
    const btVector3 &lower = leaf->volume.Mins(), &upper = leaf->volume.Maxs();
    const btScalar fromCentre = std::sqrt(boxDistance2(centre, lower, upper));
    if (fromCentre <= reach)
      candidates_.push_back(
          {fromCentre, uint32_t(reinterpret_cast<uintptr_t>(leaf->data)), lower, upper});
  });
  const btVector3 half(reach, reach, reach);
  tree_->collideTVNoStackAlloc(tree_->m_root, btDbvtVolume::FromMM(centre - half, centre + half),
                               stack_, visitor);
  std::sort(candidates_.begin(), candidates_.end(),
            [](const Candidate& a, const Candidate& b) { return a.fromCentre < b.fromCentre; });
  const size_t padded = (candidates_.size() + kGroup - 1) / kGroup * kGroup;
  for (size_t b = 0; b < kBounds; ++b) bounds_[b].resize(padded);
  for (size_t c = 0; c < padded; ++c) {
    const bool real = c < candidates_.size();
    const btVector3 far(BT_LARGE_FLOAT, BT_LARGE_FLOAT, BT_LARGE_FLOAT);
    const btVector3& lower = real ? candidates_[c].lower : far;
    const btVector3& upper = real ? candidates_[c].upper : far;
    for (int a = 0; a < 3; ++a) {
      bounds_[kLowerX + size_t(a)][c] = lower[a];
      bounds_[kUpperX + size_t(a)][c] = upper[a];
    }
  }
}

btScalar ClusterDistance::squaredDistance(const btVector3& p, size_t candidate) const {
  const auto& corners = surface_.triangles[candidates_[candidate].triangle];
  return (p - closestOnTriangle(p, surface_.vertices[corners[0]], surface_.vertices[corners[1]],
                                surface_.vertices[corners[2]])
                  .point)
      .length2();
}

btScalar ClusterDistance::nearest(const btVector3& p, btScalar offset, btScalar reach) const {
  btScalar best2 = std::numeric_limits<btScalar>::infinity(), reach2 = reach * reach;
  const Lanes px = Lanes{} + p.x(), py = Lanes{} + p.y(), pz = Lanes{} + p.z();
  auto gap = [&](size_t lower, size_t upper, const Lanes& q, size_t c) {
    const Lanes below = load(bounds_[lower], c) - q, above = q - load(bounds_[upper], c);
    const Lanes outside = below > above ? below : above;
    return outside > 0 ? outside : Lanes{};
  };
  for (size_t c = 0; c < bounds_[0].size(); c += kGroup) {
    // Every later candidate lies farther from p than its distance from the centre less p's.
    if (candidates_[c].fromCentre - offset > reach) break;
    const Lanes gx = gap(kLowerX, kUpperX, px, c), gy = gap(kLowerY, kUpperY, py, c),
                gz = gap(kLowerZ, kUpperZ, pz, c);
    const LaneMask near = gx * gx + gy * gy + gz * gz <= reach2;
    for (size_t l = 0; l < kGroup; ++l) {
      if (!near[l]) continue;
      const btScalar d2 = squaredDistance(p, c + l);
      if (d2 < best2) {
        best2 = d2;
        reach = std::sqrt(d2) + slack_;
        reach2 = reach * reach;
      }
    }
  }
  return std::sqrt(best2);
}

void ClusterDistance::distances(const btVector3& centre, std::span<const btVector3> points,
                                std::span<btScalar> distances) {
  const btScalar centreDistance = distance_.closest(centre).distance;
  btScalar spread = 0;  // the points' largest distance from the centre [m]
  for (const btVector3& p : points) spread = std::max(spread, (p - centre).length());
  // A point's nearest triangle lies within its distance, so within the centre's distance plus its
  // offset, of it: within the centre's distance plus twice the spread of the centre.
  gather(centre, centreDistance + 2 * spread + slack_);
  for (size_t n = 0; n < points.size(); ++n) {
    const btScalar offset = (points[n] - centre).length();
    distances[n] = nearest(points[n], offset - slack_, centreDistance + offset + slack_);
  }
}

}  // namespace fibremss
