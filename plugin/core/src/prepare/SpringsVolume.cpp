// Local volume terms (issue 18): the Delaunay tetrahedra of a muscle's particles that lie inside
// its surface and are not slivers, with their rest volumes, for VolumeForces.h.
#include <algorithm>
#include <cmath>
#include <numeric>

#include "PreparationInternal.h"
#include "SpringsDelaunay.h"
#include "fibremss/Error.h"

namespace fibremss::detail {
namespace {

/// Shape quality 6√2·V / l³ of a tetrahedron (l the root mean square of its six edges): 1 for
/// the regular one, 0 for a flat one. Returns it with 6V (signed) in `sixVolume`.
double tetrahedronQuality(std::span<const btVector3> x, const std::array<uint32_t, 4>& t,
                          double& sixVolume) {
  const btVector3 a = x[t[1]] - x[t[0]], b = x[t[2]] - x[t[0]], c = x[t[3]] - x[t[0]];
  sixVolume = double(a.dot(b.cross(c)));
  const double edges2 = double(a.length2() + b.length2() + c.length2() + (b - a).length2() +
                               (c - a).length2() + (c - b).length2());
  const double edge = std::sqrt(edges2 / 6);
  return edge > 0 ? std::sqrt(2.0) * std::abs(sixVolume) / (edge * edge * edge) : 0;
}

/// Σ_i |∂(6V)/∂x_i|² of tetrahedron t at x: the squared lengths of the three cross products of
/// its edges from vertex 0 and of their sum (vertex 0's gradient, negated).
btScalar squaredVolumeGradient(std::span<const btVector3> x, const std::array<uint32_t, 4>& t) {
  const btVector3 a = x[t[1]] - x[t[0]], b = x[t[2]] - x[t[0]], c = x[t[3]] - x[t[0]];
  const btVector3 ga = b.cross(c), gb = c.cross(a), gc = a.cross(b);
  return ga.length2() + gb.length2() + gc.length2() + (ga + gb + gc).length2();
}

}  // namespace

void buildVolumeTetrahedra(const MuscleInput& input, MuscleSettings& muscle) {
  muscle.tetParticles.clear();
  muscle.tetInverseVolume.clear();
  muscle.tetRestGradient.clear();
  if (!(muscle.volumeModulus > 0) || muscle.particleCount() < 5) return;
  const std::span<const btVector3> x = muscle.restPositions;
  std::vector<std::array<uint32_t, 4>> kept;
  const MeshDistance surface(muscle.restSurface);
  std::vector<std::array<uint32_t, 4>> all;
  try {
    all = delaunayTetrahedra(input, x);
  } catch (const InputError&) {
    return;  // particles on a line or a plane enclose no volume to keep
  }
  for (std::array<uint32_t, 4> t : all) {
    if (std::all_of(t.begin(), t.end(), [&](uint32_t i) { return muscle.isFixed(i); })) continue;
    std::sort(t.begin(), t.end());
    double sixVolume = 0;
    // Slivers (flat tetrahedra of nearly coplanar particles) would be stiff along their
    // normal out of all proportion to their volume: the explicit dt would have to shrink.
    if (tetrahedronQuality(x, t, sixVolume) < kMinTetrahedronQuality) continue;
    if (sixVolume < 0) std::swap(t[2], t[3]);
    // Delaunay fills the convex hull: tetrahedra over a concave surface lie outside the muscle.
    const btVector3 centroid = (x[t[0]] + x[t[1]] + x[t[2]] + x[t[3]]) * btScalar(0.25);
    if (!surface.inside(centroid)) continue;
    kept.push_back(t);
  }
  std::sort(kept.begin(), kept.end());
  muscle.tetParticles.reserve(4 * kept.size());
  muscle.tetInverseVolume.reserve(kept.size());
  muscle.tetRestGradient.reserve(kept.size());
  for (const std::array<uint32_t, 4>& t : kept) {
    double sixVolume = 0;
    tetrahedronQuality(x, t, sixVolume);
    muscle.tetParticles.insert(muscle.tetParticles.end(), t.begin(), t.end());
    muscle.tetInverseVolume.push_back(static_cast<btScalar>(1 / sixVolume));
    // A poorly shaped tetrahedron is stiff along its gradient out of proportion to its volume
    // (K·G0/(36·V0)): capped, it keeps its rest volume with a softer term.
    const double cap = kMaxRestGradient * std::pow(sixVolume, 4.0 / 3);
    muscle.tetRestGradient.push_back(
        static_cast<btScalar>(std::min(double(squaredVolumeGradient(x, t)), cap)));
  }
}

std::vector<btVector3> fibreDirections(const MuscleSettings& muscle) {
  std::vector<btVector3> directions(muscle.particleCount(), btVector3(0, 0, 0));
  const std::span<const btVector3> x = muscle.restPositions;
  for (size_t f = 0; f < muscle.fibreCount(); ++f) {
    const uint32_t first = muscle.fibreOffsets[f], last = muscle.fibreOffsets[f + 1] - 1;
    for (uint32_t k = first; k <= last && last > first; ++k) {
      const btVector3 along = x[muscle.fibreParticles[std::min(k + 1, last)]] -
                              x[muscle.fibreParticles[k > first ? k - 1 : first]];
      if (along.length2() > 0) directions[muscle.fibreParticles[k]] = along.normalized();
    }
  }
  return directions;
}

}  // namespace fibremss::detail
