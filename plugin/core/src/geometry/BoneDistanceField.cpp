#include "BoneDistanceField.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "fibremss/Error.h"

namespace fibremss {
namespace {

/// Fine cells along each edge of a coarse block whose corners are always exact.
constexpr int kBlock = 4;

/// Blocks of kBlock cells covering `extent`.
int blocksFor(btScalar extent, btScalar cell) {
  return std::max(1, static_cast<int>(std::ceil(extent / (cell * kBlock))));
}

}  // namespace

BoneDistanceField::BoneDistanceField(const MeshDistance& mesh, btScalar cell, btScalar margin) {
  if (!(cell > 0) || !(margin >= 0))
    throw InputError("BoneDistanceField", "",
                     "the cell (" + std::to_string(cell) + ") must be > 0 and the margin (" +
                         std::to_string(margin) + ") >= 0");
  if (mesh.mesh().empty()) throw InputError("BoneDistanceField", "", "empty bone mesh");
  btVector3 lower, upper;
  pointBounds(mesh.mesh().vertices, lower, upper);
  lower -= btVector3(margin, margin, margin);
  upper += btVector3(margin, margin, margin);
  const btVector3 extent = upper - lower;
  const int bx = blocksFor(extent.x(), cell), by = blocksFor(extent.y(), cell),
            bz = blocksFor(extent.z(), cell);
  nx_ = bx * kBlock + 1;
  ny_ = by * kBlock + 1;
  nz_ = bz * kBlock + 1;
  cell_ = cell;
  inverseCell_ = 1 / cell;
  lower_ = lower;
  upper_ = lower + btVector3(btScalar(nx_ - 1), btScalar(ny_ - 1), btScalar(nz_ - 1)) * cell;
  values_.assign(static_cast<size_t>(nx_) * ny_ * nz_, 0.0f);
  std::vector<bool> exact(values_.size(), false);

  // Exact value at a node; `reach` bounds the search when |φ| is known to be below it.
  auto compute = [&](int x, int y, int z, btScalar reach) {
    const size_t i = index(x, y, z);
    if (exact[i]) return;
    const btVector3 p = lower_ + btVector3(btScalar(x), btScalar(y), btScalar(z)) * cell_;
    const MeshDistance::Closest hit = mesh.closest(p, reach);
    const btScalar d = std::isfinite(hit.distance) ? (hit.inside ? -hit.distance : hit.distance)
                                                   : mesh.signedDistance(p);
    values_[i] = static_cast<float>(d);
    exact[i] = true;
    ++exactNodes_;
  };
  const btScalar infinite = std::numeric_limits<btScalar>::infinity();
  for (int z = 0; z < nz_; z += kBlock)
    for (int y = 0; y < ny_; y += kBlock)
      for (int x = 0; x < nx_; x += kBlock) compute(x, y, z, infinite);

  // φ is 1-Lipschitz: a block whose corners are all farther than its diagonal from the surface
  // holds no surface, and its nodes stay farther than half a diagonal from it.
  const btScalar diagonal = cell * kBlock * btSqrt(3);
  for (int cz = 0; cz < bz; ++cz)
    for (int cy = 0; cy < by; ++cy)
      for (int cx = 0; cx < bx; ++cx) {
        const int x0 = cx * kBlock, y0 = cy * kBlock, z0 = cz * kBlock;
        float corner[8];
        btScalar nearest = infinite;
        for (int k = 0; k < 8; ++k) {
          corner[k] = values_[index(x0 + (k & 1) * kBlock, y0 + ((k >> 1) & 1) * kBlock,
                                    z0 + ((k >> 2) & 1) * kBlock)];
          nearest = std::min(nearest, btScalar(std::abs(corner[k])));
        }
        const bool nearSurface = nearest < 2 * diagonal;
        for (int z = z0; z <= z0 + kBlock; ++z)
          for (int y = y0; y <= y0 + kBlock; ++y)
            for (int x = x0; x <= x0 + kBlock; ++x) {
              if (nearSurface) {
                compute(x, y, z, 1.01f * (nearest + diagonal));
                continue;
              }
              const size_t i = index(x, y, z);
              if (exact[i]) continue;
              const float fx = float(x - x0) / kBlock, fy = float(y - y0) / kBlock,
                          fz = float(z - z0) / kBlock;
              float value = 0;
              for (int k = 0; k < 8; ++k)
                value += corner[k] * ((k & 1) ? fx : 1 - fx) * ((k >> 1) & 1 ? fy : 1 - fy) *
                         ((k >> 2) & 1 ? fz : 1 - fz);
              values_[i] = value;
            }
      }
}

BoneDistanceField::Sample BoneDistanceField::sample(const btVector3& p) const {
  const btVector3 clamped(std::clamp(p.x(), lower_.x(), upper_.x()),
                          std::clamp(p.y(), lower_.y(), upper_.y()),
                          std::clamp(p.z(), lower_.z(), upper_.z()));
  const btVector3 grid = (clamped - lower_) * inverseCell_;
  const int x = std::min(static_cast<int>(grid.x()), nx_ - 2);
  const int y = std::min(static_cast<int>(grid.y()), ny_ - 2);
  const int z = std::min(static_cast<int>(grid.z()), nz_ - 2);
  const btScalar fx = grid.x() - btScalar(x), fy = grid.y() - btScalar(y),
                 fz = grid.z() - btScalar(z);
  const size_t i = index(x, y, z);
  const size_t dy = static_cast<size_t>(nx_), dz = static_cast<size_t>(nx_) * ny_;
  const btScalar c000 = values_[i], c100 = values_[i + 1], c010 = values_[i + dy],
                 c110 = values_[i + dy + 1], c001 = values_[i + dz], c101 = values_[i + dz + 1],
                 c011 = values_[i + dz + dy], c111 = values_[i + dz + dy + 1];
  // Interpolate along x, then y, then z; the partial derivatives come from the same lerps.
  const btScalar c00 = c000 + (c100 - c000) * fx, c10 = c010 + (c110 - c010) * fx,
                 c01 = c001 + (c101 - c001) * fx, c11 = c011 + (c111 - c011) * fx;
  const btScalar c0 = c00 + (c10 - c00) * fy, c1 = c01 + (c11 - c01) * fy;
  const btScalar ddx0 = (c100 - c000) + ((c110 - c010) - (c100 - c000)) * fy;
  const btScalar ddx1 = (c101 - c001) + ((c111 - c011) - (c101 - c001)) * fy;
  Sample result;
  result.distance = c0 + (c1 - c0) * fz;
  const btVector3 gradient(ddx0 + (ddx1 - ddx0) * fz,
                           (c10 - c00) + ((c11 - c01) - (c10 - c00)) * fz, c1 - c0);
  const btVector3 outside = p - clamped;
  const btScalar away = outside.length();
  if (away > 0) {
    result.distance += away;
    result.gradient = outside / away;
  } else if (gradient.length2() > SIMD_EPSILON) {
    result.gradient = gradient.normalized();
  }
  return result;
}

}  // namespace fibremss
