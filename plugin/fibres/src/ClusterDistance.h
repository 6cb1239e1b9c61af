#pragma once
// Distances from the points of a small cluster (a block of the rest distance grid) to a triangle
// surface, the same bit for bit as MeshDistance::closest's: the triangles that can be nearest to
// any of the points are found once per cluster, then each point searches only those.
#include <BulletCollision/BroadphaseCollision/btDbvt.h>

#include <array>
#include <memory>
#include <span>
#include <vector>

#include "fibremss/Geometry.h"

namespace fibremss {

class ClusterDistance {
 public:
  explicit ClusterDistance(const TriangleMesh& surface);
  ~ClusterDistance();
  ClusterDistance(const ClusterDistance&) = delete;
  ClusterDistance& operator=(const ClusterDistance&) = delete;

  /// Per point of the cluster: its distance to the surface [m] into `distances` (as many). The
  /// points' distance from `centre` sets how many triangles are searched: the cluster's centre
  /// keeps them fewest.
  void distances(const btVector3& centre, std::span<const btVector3> points,
                 std::span<btScalar> distances);
  /// Closest points on the surface, one point at a time.
  const MeshDistance& surfaceDistance() const { return distance_; }

 private:
  /// A triangle that can be nearest to a point of the cluster: a lower bound of its distance
  /// from the centre (its bounds') and its bounds.
  struct Candidate {
    btScalar fromCentre = 0;  ///< [m]
    uint32_t triangle = 0;
    btVector3 lower{0, 0, 0}, upper{0, 0, 0};  ///< its bounds [m]
  };
  /// The candidates' bounds, one array per coordinate (lower x, y, z, upper x, y, z), padded to
  /// whole groups of kGroup with bounds no point comes near.
  enum Bound : size_t { kLowerX, kLowerY, kLowerZ, kUpperX, kUpperY, kUpperZ, kBounds };
  /// Candidates tested at once: as many as 16 bytes hold (one SSE register).
  static constexpr size_t kGroup = 16 / sizeof(btScalar);

  /// The triangles whose bounds lie within `reach` of `centre` into candidates_ and bounds_,
  /// nearest first.
  void gather(const btVector3& centre, btScalar reach);
  /// The point's distance to the nearest candidate, which lies within `reach` [m] of it;
  /// `offset` its distance from the centre [m].
  btScalar nearest(const btVector3& p, btScalar offset, btScalar reach) const;
  /// The squared distance from p to candidate `candidate`'s triangle [m²].
  btScalar squaredDistance(const btVector3& p, size_t candidate) const;

  const TriangleMesh& surface_;
  MeshDistance distance_;              ///< the centre's distance
  std::unique_ptr<btDbvt> tree_;       ///< over the triangles' bounds, a leaf's data its index
  btScalar slack_ = 0;                 ///< rounding allowance of the searches' bounds [m]
  std::vector<Candidate> candidates_;  ///< scratch
  std::array<std::vector<btScalar>, kBounds> bounds_;  ///< scratch: the candidates' [m]
  btAlignedObjectArray<const btDbvtNode*> stack_;      ///< scratch of the tree's query
};

}  // namespace fibremss
