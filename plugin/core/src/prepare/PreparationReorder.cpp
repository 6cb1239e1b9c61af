#include "PreparationReorder.h"

#include <algorithm>
#include <numeric>
#include <stdexcept>
#include <utility>

#include "kernels/SpringForces.h"
#include "kernels/VolumeForces.h"

namespace fibremss::detail {
namespace {

// A new field of MuscleSettings may hold particle indices or per-particle values: remap it in
// reorderParticles, then update this size (libstdc++, x86-64).
static_assert(sizeof(MuscleSettings) == (sizeof(btScalar) == 4 ? 816 : 832),
              "MuscleSettings changed: remap its new fields in reorderParticles");

/// Spreads the low 10 bits of v to every third bit (bit i to bit 3i).
uint32_t spreadBits(uint32_t v) {
  v &= 0x3ff;
  v = (v | (v << 16)) & 0x030000ff;
  v = (v | (v << 8)) & 0x0300f00f;
  v = (v | (v << 4)) & 0x030c30c3;
  v = (v | (v << 2)) & 0x09249249;
  return v;
}

/// values[order[k]] for every k.
template <typename T>
void permute(std::vector<T>& values, std::span<const uint32_t> order) {
  if (values.empty()) return;
  std::vector<T> permuted(order.size());
  for (size_t k = 0; k < order.size(); ++k) permuted[k] = values[order[k]];
  values = std::move(permuted);
}

}  // namespace

std::vector<uint32_t> mortonOrder(std::span<const btVector3> points) {
  std::vector<uint32_t> order(points.size());
  std::iota(order.begin(), order.end(), 0u);
  if (points.empty()) return order;
  btVector3 lower = points[0], upper = points[0];
  for (const btVector3& p : points) {
    lower.setMin(p);
    upper.setMax(p);
  }
  // One cube for all axes, so that a cell is as long as it is wide.
  const btVector3 size = upper - lower;
  const btScalar extent = std::max({size.x(), size.y(), size.z()});
  const btScalar scale = extent > 0 ? btScalar(1023) / extent : 0;
  std::vector<uint32_t> codes(points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    const btVector3 cell = (points[i] - lower) * scale;
    codes[i] = spreadBits(static_cast<uint32_t>(cell.x())) |
               spreadBits(static_cast<uint32_t>(cell.y())) << 1 |
               spreadBits(static_cast<uint32_t>(cell.z())) << 2;
  }
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t x, uint32_t y) { return codes[x] < codes[y]; });
  return order;
}

void reorderParticles(MuscleSettings& muscle, std::span<const uint32_t> order) {
  const size_t n = muscle.particleCount();
  if (order.size() != n)
    throw std::invalid_argument("reorderParticles: order is not a permutation");
  std::vector<uint32_t> rank(n, UINT32_MAX);
  for (size_t k = 0; k < n; ++k) {
    if (order[k] >= n || rank[order[k]] != UINT32_MAX)
      throw std::invalid_argument("reorderParticles: order is not a permutation");
    rank[order[k]] = static_cast<uint32_t>(k);
  }

  permute(muscle.restPositions, order);
  permute(muscle.radii, order);
  permute(muscle.flags, order);
  permute(muscle.fixedBone, order);
  permute(muscle.nearestBone, order);
  permute(muscle.blendBoneA, order);
  permute(muscle.blendBoneB, order);
  permute(muscle.blendWeight, order);

  const auto renumber = [&rank](std::vector<uint32_t>& indices) {
    for (uint32_t& i : indices) i = rank[i];
  };
  renumber(muscle.boundaryParticles);
  std::sort(muscle.boundaryParticles.begin(), muscle.boundaryParticles.end());
  renumber(muscle.fixedParticles);
  std::sort(muscle.fixedParticles.begin(), muscle.fixedParticles.end());
  renumber(muscle.fibreParticles);
  renumber(muscle.skinParticles);
  // Each keeps its sequence, hence its orientation (tetInverseVolume and tetRestGradient hold,
  // and the faces still face out).
  renumber(muscle.tetParticles);
  renumber(muscle.fanParticles);
  muscle.fanBytes = fanBytes(muscle.fanParticles);
  renumber(muscle.enclosedFaces);

  for (Spring& spring : muscle.springs) {
    spring.a = rank[spring.a];
    spring.b = rank[spring.b];
    if (spring.a > spring.b) std::swap(spring.a, spring.b);
  }
  std::sort(muscle.springs.begin(), muscle.springs.end(),
            [](const Spring& x, const Spring& y) { return x.a != y.a ? x.a < y.a : x.b < y.b; });
  layoutSprings(muscle);
}

}  // namespace fibremss::detail
