#pragma once
// Signed distance field of a bone mesh in the bone frame (method.md §6, stronger alternatives;
// 002 Table 4.31): exact signed distances at the nodes of a regular grid, trilinear in between.
// Built once per bone; queries are const, allocation-free and thread-safe.
#include <LinearMath/btVector3.h>

#include <cstddef>
#include <vector>

#include "fibremss/Geometry.h"

namespace fibremss {

class BoneDistanceField {
 public:
  /// Signed distance (negative inside) and the field's direction of increase at a point.
  struct Sample {
    btScalar distance = 0;        ///< signed distance [m]
    btVector3 gradient{0, 0, 0};  ///< unit direction away from the surface, or zero
  };

  /// Samples `mesh` on a grid of `cell`-sized cells covering its bounds grown by `margin`. Nodes
  /// of coarse blocks that the surface cannot reach (1-Lipschitz bound) take the trilinear value
  /// of the block's exact corners; every other node is exact. Allocates.
  BoneDistanceField(const MeshDistance& mesh, btScalar cell, btScalar margin);

  /// The field at p (bone frame). Outside the grid: the value at the nearest grid point plus the
  /// distance to it (an upper bound of the true distance; no contact is that far out).
  Sample sample(const btVector3& p) const;

  const btVector3& lower() const { return lower_; }    ///< grid corner, bone frame [m]
  const btVector3& upper() const { return upper_; }    ///< opposite grid corner [m]
  btScalar cell() const { return cell_; }              ///< grid spacing [m]
  size_t nodeCount() const { return values_.size(); }  ///< grid nodes
  size_t exactNodes() const { return exactNodes_; }    ///< nodes given the mesh's exact distance

 private:
  /// Index of node (x, y, z) in values_.
  size_t index(int x, int y, int z) const {
    return (static_cast<size_t>(z) * ny_ + static_cast<size_t>(y)) * nx_ + static_cast<size_t>(x);
  }

  btVector3 lower_{0, 0, 0};      ///< node (0, 0, 0)
  btVector3 upper_{0, 0, 0};      ///< node (nx − 1, ny − 1, nz − 1)
  btScalar cell_ = 0;             ///< spacing
  btScalar inverseCell_ = 0;      ///< 1 / spacing
  int nx_ = 0, ny_ = 0, nz_ = 0;  ///< nodes per axis
  std::vector<float> values_;     ///< signed distances, x fastest
  size_t exactNodes_ = 0;         ///< nodes computed exactly (the rest interpolated)
};

}  // namespace fibremss
