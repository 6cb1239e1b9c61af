#pragma once
// Plain geometry shared by loaders, preparation, simulation output and metrics.
#include <LinearMath/btTransform.h>
#include <LinearMath/btVector3.h>

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <span>
#include <vector>

namespace fibremss {

/// Largest |coordinate| a point of a body may have [m] (1000 km; a scene in the wrong units
/// lands beyond it): btDbvt's tree build multiplies extents, which overflow float far beyond
/// any body and then write out of bounds.
constexpr btScalar kMaxCoordinate = btScalar(1e6);

/// Whether every coordinate of `p` is finite and within ±kMaxCoordinate (NaN is not).
inline bool withinWorld(const btVector3& p) {
  return btFabs(p.x()) <= kMaxCoordinate && btFabs(p.y()) <= kMaxCoordinate &&
         btFabs(p.z()) <= kMaxCoordinate;
}

/// A triangle surface; triangles are counter-clockwise seen from outside (outward normals).
struct TriangleMesh {
  std::vector<btVector3> vertices;                 ///< vertex positions
  std::vector<std::array<uint32_t, 3>> triangles;  ///< vertex indices, three per triangle

  bool empty() const { return triangles.empty(); }
};

/// Polylines in one array: fibre i spans points[offsets[i]] .. points[offsets[i+1]-1].
struct FibreSet {
  std::vector<btVector3> points;     ///< all fibre points, fibre after fibre
  std::vector<uint32_t> offsets{0};  ///< fibreCount()+1 entries, offsets.front() == 0

  size_t fibreCount() const { return offsets.size() - 1; }
  std::span<const btVector3> fibre(size_t i) const {
    return {points.data() + offsets[i], points.data() + offsets[i + 1]};
  }
  void addFibre(std::span<const btVector3> polyline) {
    points.insert(points.end(), polyline.begin(), polyline.end());
    offsets.push_back(static_cast<uint32_t>(points.size()));
  }
};

/// Signed volume enclosed by a closed mesh (positive when normals point outward).
btScalar meshVolume(const TriangleMesh& mesh);

/// Axis-aligned bounds of a point set.
void pointBounds(std::span<const btVector3> points, btVector3& lower, btVector3& upper);

/// Applies a rigid transform to every vertex.
TriangleMesh transformed(const TriangleMesh& mesh, const btTransform& transform);

/// Closest-point and signed-distance queries against one triangle mesh (a bone, a muscle
/// surface). Built once (a bounding volume tree over the triangles); queries are const and
/// thread-safe.
class MeshDistance {
 public:
  explicit MeshDistance(const TriangleMesh& mesh);
  ~MeshDistance();
  MeshDistance(MeshDistance&&) noexcept;
  MeshDistance& operator=(MeshDistance&&) noexcept;

  struct Closest {
    btScalar distance = std::numeric_limits<btScalar>::infinity();  ///< unsigned, >= 0
    btVector3 point{0, 0, 0};                                       ///< closest surface point
    uint32_t triangle = UINT32_MAX;  ///< triangle holding it, UINT32_MAX when none in range
    bool inside = false;  ///< p is inside the mesh (the sign signedDistance() would give)
    /// Where on `triangle` the point lies: its corner k (k = 0–2), its edge from corner k to the
    /// next (3 + k), or inside the face (6).
    uint8_t feature = 6;
  };
  /// Closest surface point within maxDistance (none found: distance stays infinite).
  Closest closest(const btVector3& p,
                  btScalar maxDistance = std::numeric_limits<btScalar>::infinity()) const;
  /// Distance to the surface, negative inside (sign from angle-weighted pseudo-normals).
  btScalar signedDistance(const btVector3& p) const;
  bool inside(const btVector3& p) const { return signedDistance(p) < 0; }

  struct Plane {
    btVector3 normal{0, 0, 0};  ///< the face's unit outward normal
    btScalar distance = 0;      ///< signed distance of the point from the face's plane [m]
  };
  /// Of the faces that meet at the closest point `c` of p (closest(p)'s answer: its face, an
  /// edge's two faces or a corner's ring), the one whose plane p lies farthest in front of: the
  /// face p lies beside when the mesh's edges are sharp (off a convex edge, the plane p is
  /// outside of; never nearer p than c is).
  Plane frontFace(const btVector3& p, const Closest& c) const;

  const TriangleMesh& mesh() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace fibremss
