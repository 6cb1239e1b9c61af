// Tendons: the stiffer ends of a muscle between its attachments and its belly. Measured on the
// real hip flexed to 90° (real-hip.json, one material, converged): the largest fibre stretch
// (2.7×) is always in the first free segments beyond a fixed particle, where the fibres
// converge into a thin end; the median is 1.24.
#include <span>

#include "PreparationInternal.h"

namespace fibremss::detail {
namespace {

/// Marks kTendon on the free particles of `fibre` (in fibre order) that lie within `length` of
/// arc beyond the last fixed particle of the run of fixed particles it starts with.
void markTendonFrom(MuscleSettings& muscle, std::span<const uint32_t> fibre, btScalar length) {
  size_t first = 0;
  while (first < fibre.size() && muscle.isFixed(fibre[first])) ++first;
  if (first == 0 || first == fibre.size()) return;
  btScalar arc = 0;
  for (size_t k = first; k < fibre.size() && !muscle.isFixed(fibre[k]); ++k) {
    arc += (muscle.restPositions[fibre[k]] - muscle.restPositions[fibre[k - 1]]).length();
    if (arc > length) return;
    muscle.flags[fibre[k]] |= kTendon;
  }
}

btScalar fibreLength(const MuscleSettings& muscle, std::span<const uint32_t> fibre) {
  btScalar length = 0;
  for (size_t k = 1; k < fibre.size(); ++k)
    length += (muscle.restPositions[fibre[k]] - muscle.restPositions[fibre[k - 1]]).length();
  return length;
}

}  // namespace

size_t stiffenTendons(MuscleSettings& muscle, btScalar fraction, btScalar stiffness) {
  if (!(fraction > 0)) return 0;
  std::vector<uint32_t> reversed;
  for (size_t f = 0; f < muscle.fibreCount(); ++f) {
    const std::span<const uint32_t> fibre(muscle.fibreParticles.data() + muscle.fibreOffsets[f],
                                          muscle.fibreOffsets[f + 1] - muscle.fibreOffsets[f]);
    const btScalar length = fraction * fibreLength(muscle, fibre);
    markTendonFrom(muscle, fibre, length);
    reversed.assign(fibre.rbegin(), fibre.rend());
    markTendonFrom(muscle, reversed, length);
  }
  size_t stiffened = 0;
  for (Spring& spring : muscle.springs) {
    const auto tendonOrFixed = [&](uint32_t p) { return muscle.flags[p] & (kTendon | kFixed); };
    if (!tendonOrFixed(spring.a) || !tendonOrFixed(spring.b)) continue;
    spring.stiffness *= stiffness;
    ++stiffened;
  }
  return stiffened;
}

}  // namespace fibremss::detail
