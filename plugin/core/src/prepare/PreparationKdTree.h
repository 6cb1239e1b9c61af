#pragma once
// A static 3-d kd-tree (nanoflann) over a point array that outlives it; const queries are
// thread-safe. Internal to preparation.
#include <LinearMath/btVector3.h>

#include <nanoflann.hpp>
#include <span>
#include <utility>
#include <vector>

namespace fibremss::detail {

class KdTree {
 public:
  explicit KdTree(std::span<const btVector3> points)
      : source_{points}, index_(3, source_, nanoflann::KDTreeSingleIndexAdaptorParams(12)) {
    index_.buildIndex();
  }
  KdTree(const KdTree&) = delete;
  KdTree& operator=(const KdTree&) = delete;

  size_t size() const { return source_.points.size(); }

  /// The k nearest points, nearest first; returns how many were found (<= k).
  size_t nearest(const btVector3& query, size_t k, uint32_t* indices, btScalar* distances2) const {
    if (source_.points.empty() || k == 0) return 0;
    return index_.knnSearch(query.m_floats, k, indices, distances2);
  }

  /// All points within `radius` (inclusive), as (index, squared distance), unsorted.
  void within(const btVector3& query, btScalar radius,
              std::vector<std::pair<uint32_t, btScalar>>& found) const {
    found.clear();
    if (source_.points.empty() || !(radius >= 0)) return;
    // nanoflann's radius test is strict; a hair more keeps points exactly on the sphere.
    const btScalar radius2 = radius * radius * (1 + 4 * SIMD_EPSILON);
    index_.radiusSearch(query.m_floats, radius2, found, nanoflann::SearchParams(32, 0, false));
  }

 private:
  struct Source {
    std::span<const btVector3> points;
    size_t kdtree_get_point_count() const { return points.size(); }
    btScalar kdtree_get_pt(uint32_t i, size_t axis) const { return points[i][int(axis)]; }
    template <class Box>
    bool kdtree_get_bbox(Box&) const {
      return false;
    }
  };
  using Index = nanoflann::KDTreeSingleIndexAdaptor<
      nanoflann::L2_Simple_Adaptor<btScalar, Source, btScalar, uint32_t>, Source, 3, uint32_t>;
  Source source_;
  Index index_;
};

}  // namespace fibremss::detail
