// The interior tetrahedra of a muscle's particles (the Delaunay tetrahedra inside its surface) and
// what preparation makes of them: the springs' share of the network's stiffness by the volume
// around them, and the local volume terms (those that are not slivers, with their rest
// volumes, for VolumeForces.h).
#include <algorithm>
#include <cmath>
#include <numeric>

#include "PreparationInternal.h"
#include "PreparationKdTree.h"
#include "SpringsDelaunay.h"
#include "fibremss/Error.h"
#include "kernels/VolumeForces.h"

namespace fibremss::detail {
namespace {

/// Shape quality 6√2·V / l³ of a tetrahedron (l the root mean square of its six edges): 1 for
/// the regular one, 0 for a flat one. Returns it with 6V (signed) in `sixVolume`.
double tetrahedronQuality(std::span<const btVector3> x, const Tetrahedron& t, double& sixVolume) {
  const btVector3 a = x[t[1]] - x[t[0]], b = x[t[2]] - x[t[0]], c = x[t[3]] - x[t[0]];
  sixVolume = double(a.dot(b.cross(c)));
  const double edges2 = double(a.length2() + b.length2() + c.length2() + (b - a).length2() +
                               (c - a).length2() + (c - b).length2());
  const double edge = std::sqrt(edges2 / 6);
  return edge > 0 ? std::sqrt(2.0) * std::abs(sixVolume) / (edge * edge * edge) : 0;
}

/// Σ_i |∂(6V)/∂x_i|² of tetrahedron t at x: the squared lengths of the three cross products of
/// its edges from vertex 0 and of their sum (vertex 0's gradient, negated).
btScalar squaredVolumeGradient(std::span<const btVector3> x, const Tetrahedron& t) {
  const btVector3 a = x[t[1]] - x[t[0]], b = x[t[2]] - x[t[0]], c = x[t[3]] - x[t[0]];
  const btVector3 ga = b.cross(c), gb = c.cross(a), gc = a.cross(b);
  return ga.length2() + gb.length2() + gc.length2() + (ga + gb + gc).length2();
}

}  // namespace

std::vector<Tetrahedron> interiorTetrahedra(const MuscleInput& input,
                                            std::span<const btVector3> positions,
                                            const TriangleMesh& surface) {
  if (positions.size() < 5) return {};
  std::vector<Tetrahedron> all;
  try {
    all = delaunayTetrahedra(input, positions);
  } catch (const InputError&) {
    return {};  // particles on a line or a plane enclose no volume
  }
  const MeshDistance inside(surface);
  std::erase_if(all, [&](const Tetrahedron& t) {
    const btVector3 centroid =
        (positions[t[0]] + positions[t[1]] + positions[t[2]] + positions[t[3]]) * btScalar(0.25);
    return !inside.inside(centroid);
  });
  return all;
}

std::vector<Tetrahedron> coarseTetrahedra(const MuscleInput& input,
                                          std::span<const btVector3> positions,
                                          const KdTree& particles, const TriangleMesh& surface,
                                          double coarsening) {
  std::vector<uint8_t> dropped(positions.size(), 0);
  std::vector<uint32_t> kept;
  std::vector<btVector3> subset;
  std::vector<std::pair<uint32_t, btScalar>> near;
  for (uint32_t i = 0; i < positions.size(); ++i) {
    if (dropped[i]) continue;
    uint32_t nearest[2];
    btScalar distance2[2];
    if (particles.nearest(positions[i], 2, nearest, distance2) < 2) continue;
    kept.push_back(i);
    subset.push_back(positions[i]);
    particles.within(positions[i], static_cast<btScalar>(coarsening) * std::sqrt(distance2[1]),
                     near);
    for (const auto& [j, d2] : near) dropped[j] = 1;
  }
  std::vector<Tetrahedron> tetrahedra = interiorTetrahedra(input, subset, surface);
  for (Tetrahedron& t : tetrahedra)
    for (uint32_t& i : t) i = kept[i];
  return tetrahedra;
}

void renumberTetrahedra(std::vector<Tetrahedron>& tetrahedra, std::span<const uint32_t> order) {
  std::vector<uint32_t> renamed(order.size());
  for (uint32_t k = 0; k < order.size(); ++k) renamed[order[k]] = k;
  for (Tetrahedron& t : tetrahedra)
    for (uint32_t& i : t) i = renamed[i];
}

bool shareStiffnessByVolume(std::span<const btVector3> x, std::span<const Tetrahedron> interior,
                            std::vector<Spring>& springs) {
  std::vector<double> volume(x.size(), 0.0);  // each particle's quarter of its tetrahedra [m³]
  for (const Tetrahedron& t : interior) {
    double sixVolume = 0;
    tetrahedronQuality(x, t, sixVolume);
    for (uint32_t i : t) volume[i] += std::abs(sixVolume) / 24;
  }
  std::vector<double> lengths(x.size(), 0.0);  // Σ L0 of each particle's springs [m]
  for (const Spring& spring : springs) {
    lengths[spring.a] += spring.restLength;
    lengths[spring.b] += spring.restLength;
  }
  // A particle at the edge of the particles' hull whose tetrahedra all fall outside the surface
  // still has muscle around it (the layer out to the surface): at least a quarter of the median.
  std::vector<double> sorted = volume;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double floor = sorted[sorted.size() / 2] / 4;
  if (!(floor > 0)) return false;
  double before = 0, after = 0;  // Σ k·L0² of the length rule and of the shares
  std::vector<double> factor(springs.size());
  for (size_t e = 0; e < springs.size(); ++e) {
    const Spring& spring = springs[e];
    const double share = std::max(volume[spring.a], floor) / lengths[spring.a] +
                         std::max(volume[spring.b], floor) / lengths[spring.b];
    factor[e] = share;  // [m²]
    const double energy = double(spring.stiffness) * spring.restLength * spring.restLength;
    before += energy;
    after += energy * factor[e];
  }
  if (!(after > 0)) return false;
  for (size_t e = 0; e < springs.size(); ++e)
    springs[e].stiffness = static_cast<btScalar>(springs[e].stiffness * factor[e] * before / after);
  return true;
}

namespace {

/// Tetrahedron k has the edge (i, j), i < j.
struct EdgeIncidence {
  uint32_t i, j, k;
  auto operator<=>(const EdgeIncidence&) const = default;
};

/// The tetrahedra around one edge (i, j): incidences [first, first + count).
struct EdgeShell {
  uint32_t a, b;
  size_t first, count;
};

/// Every edge of the tetrahedra with the tetrahedra around it (`incidences` sorted), the edges
/// with more tetrahedra first, then by their particles.
std::vector<EdgeShell> edgeShells(std::span<const Tetrahedron> tetrahedra,
                                  std::vector<EdgeIncidence>& incidences) {
  for (uint32_t k = 0; k < tetrahedra.size(); ++k)
    for (int p = 0; p < 4; ++p)
      for (int q = p + 1; q < 4; ++q)
        incidences.push_back({std::min(tetrahedra[k][p], tetrahedra[k][q]),
                              std::max(tetrahedra[k][p], tetrahedra[k][q]), k});
  std::sort(incidences.begin(), incidences.end());
  std::vector<EdgeShell> shells;
  for (size_t s = 0; s < incidences.size();) {
    size_t e = s;
    while (e < incidences.size() && incidences[e].i == incidences[s].i &&
           incidences[e].j == incidences[s].j)
      ++e;
    shells.push_back({incidences[s].i, incidences[s].j, s, e - s});
    s = e;
  }
  std::stable_sort(shells.begin(), shells.end(),
                   [](const EdgeShell& l, const EdgeShell& r) { return l.count > r.count; });
  return shells;
}

/// The unused tetrahedra around `shell` in their order around it: each as the step p → q of the
/// ring (turned so that (a, b, p, q) has positive volume at x) and its index; empty when two
/// steps leave or reach the same particle (the tetrahedra do not fan around the edge).
std::vector<std::array<uint32_t, 3>> ringSteps(std::span<const btVector3> x,
                                               std::span<const Tetrahedron> tetrahedra,
                                               std::span<const EdgeIncidence> around,
                                               const EdgeShell& shell,
                                               const std::vector<uint8_t>& used) {
  std::vector<std::array<uint32_t, 3>> steps;  // p, q, tetrahedron
  for (const EdgeIncidence& incidence : around) {
    if (used[incidence.k]) continue;
    uint32_t other[2], n = 0;
    for (uint32_t v : tetrahedra[incidence.k])
      if (v != shell.a && v != shell.b) other[n++] = v;
    const btVector3 e = x[shell.b] - x[shell.a];
    if (e.dot((x[other[0]] - x[shell.a]).cross(x[other[1]] - x[shell.a])) < 0)
      std::swap(other[0], other[1]);
    steps.push_back({other[0], other[1], incidence.k});
  }
  for (size_t u = 0; u < steps.size(); ++u)
    for (size_t w = u + 1; w < steps.size(); ++w)
      if (steps[u][0] == steps[w][0] || steps[u][1] == steps[w][1]) return {};
  return steps;
}

/// The steps in runs around the edge: each run a chain p → q → … of consecutive steps; a closed
/// ring without one of them.
std::vector<std::vector<size_t>> ringRuns(const std::vector<std::array<uint32_t, 3>>& steps) {
  const auto find = [&](uint32_t particle, int end) -> size_t {
    for (size_t u = 0; u < steps.size(); ++u)
      if (steps[u][static_cast<size_t>(end)] == particle) return u;
    return steps.size();
  };
  std::vector<uint8_t> placed(steps.size(), 0);
  std::vector<std::vector<size_t>> runs;
  for (size_t start = 0; start < steps.size(); ++start) {
    if (placed[start]) continue;
    size_t first = start;  // back to the run's first step (or once around a ring)
    for (size_t previous = find(steps[first][0], 1);
         previous < steps.size() && previous != start && !placed[previous];
         previous = find(steps[first][0], 1))
      first = previous;
    std::vector<size_t> run{first};
    placed[first] = 1;
    for (size_t next = find(steps[first][1], 0); next < steps.size() && !placed[next];
         next = find(steps[run.back()][1], 0)) {
      run.push_back(next);
      placed[next] = 1;
    }
    // A closed ring loses its last step, so that no fan has a particle twice.
    if (run.size() > 1 && steps[run.back()][1] == steps[run.front()][0]) run.pop_back();
    runs.push_back(std::move(run));
  }
  return runs;
}

/// The tetrahedra as fans around their edges (MuscleSettings::fanParticles): greedily, runs of
/// at least `size` unused tetrahedra around an edge, edges with more tetrahedra first, for size
/// kMaxFanTetrahedra down to 2, cut into fans of at most kMaxFanTetrahedra; the rest one each.
/// A fan's particles are a, b, r_0 .. r_m (m tetrahedra (a, b, r_k, r_k+1), positive at x).
std::vector<std::vector<uint32_t>> fansOf(std::span<const btVector3> x,
                                          std::span<const Tetrahedron> tetrahedra) {
  std::vector<EdgeIncidence> incidences;
  const std::vector<EdgeShell> shells = edgeShells(tetrahedra, incidences);
  std::vector<uint8_t> used(tetrahedra.size(), 0);
  std::vector<std::vector<uint32_t>> fans;
  for (size_t size = kMaxFanTetrahedra; size >= 2; --size)
    for (const EdgeShell& shell : shells) {
      const auto steps = ringSteps(
          x, tetrahedra, std::span(incidences).subspan(shell.first, shell.count), shell, used);
      if (steps.size() < size) continue;
      for (const std::vector<size_t>& run : ringRuns(steps))
        for (size_t from = 0; from + size <= run.size(); from += kMaxFanTetrahedra) {
          const size_t to = std::min(run.size(), from + kMaxFanTetrahedra);
          std::vector<uint32_t> fan{shell.a, shell.b};
          for (size_t u = from; u < to; ++u) {
            fan.push_back(steps[run[u]][0]);
            used[steps[run[u]][2]] = 1;
          }
          fan.push_back(steps[run[to - 1]][1]);
          fans.push_back(std::move(fan));
        }
    }
  for (uint32_t k = 0; k < tetrahedra.size(); ++k)
    if (!used[k]) fans.push_back({tetrahedra[k].begin(), tetrahedra[k].end()});
  std::sort(fans.begin(), fans.end(), [](const auto& l, const auto& r) {
    return l.size() != r.size() ? l.size() < r.size() : l < r;
  });
  return fans;
}

/// Fills the muscle's fans from `fans` (fansOf) with their rest volumes and G0.
void buildFans(MuscleSettings& muscle, const std::vector<std::vector<uint32_t>>& fans) {
  muscle.fanParticles.clear();
  muscle.fanOffsets.assign(1, 0);
  muscle.fanInverseVolume.clear();
  muscle.fanRestGradient.clear();
  for (const std::vector<uint32_t>& fan : fans) {
    const FanGradients rest = fanGradients(muscle.restPositions.data(), fan);
    muscle.fanParticles.insert(muscle.fanParticles.end(), fan.begin(), fan.end());
    muscle.fanOffsets.push_back(static_cast<uint32_t>(muscle.fanParticles.size()));
    const double sixVolume = rest.sixVolume;
    muscle.fanInverseVolume.push_back(static_cast<btScalar>(1 / sixVolume));
    // A poorly shaped fan is stiff along its gradient out of proportion to its volume
    // (K·G0/(36·V0)): capped, it keeps its rest volume with a softer term.
    const double cap = kMaxRestGradient * std::pow(sixVolume, 4.0 / 3);
    muscle.fanRestGradient.push_back(static_cast<btScalar>(std::min(double(rest.squared), cap)));
  }
  muscle.fanBytes = fanBytes(muscle.fanParticles);
}

}  // namespace

void buildVolumeTetrahedra(MuscleSettings& muscle, std::span<const Tetrahedron> interior) {
  buildFans(muscle, {});
  muscle.tetParticles.clear();
  muscle.tetInverseVolume.clear();
  muscle.tetRestGradient.clear();
  if (!(muscle.volumeModulus > 0)) return;
  const std::span<const btVector3> x = muscle.restPositions;
  std::vector<Tetrahedron> kept;
  for (Tetrahedron t : interior) {
    if (std::all_of(t.begin(), t.end(), [&](uint32_t i) { return muscle.isFixed(i); })) continue;
    std::sort(t.begin(), t.end());
    double sixVolume = 0;
    // Slivers (flat tetrahedra of nearly coplanar particles) would be stiff along their
    // normal out of all proportion to their volume: the explicit dt would have to shrink.
    if (tetrahedronQuality(x, t, sixVolume) < kMinTetrahedronQuality) continue;
    if (sixVolume < 0) std::swap(t[2], t[3]);
    kept.push_back(t);
  }
  std::sort(kept.begin(), kept.end());
  muscle.tetParticles.reserve(4 * kept.size());
  muscle.tetInverseVolume.reserve(kept.size());
  muscle.tetRestGradient.reserve(kept.size());
  for (const Tetrahedron& t : kept) {
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
  buildFans(muscle, fansOf(x, kept));
}

namespace {

/// A face of a tetrahedron as its particles in ascending order and the orientation it had: +1
/// when it was an even permutation of them, −1 when odd.
struct OrientedFace {
  std::array<uint32_t, 3> particles;
  int sign;
};

OrientedFace orientedFace(uint32_t p, uint32_t q, uint32_t r) {
  const int inversions = int(p > q) + int(p > r) + int(q > r);
  std::array<uint32_t, 3> sorted{p, q, r};
  std::sort(sorted.begin(), sorted.end());
  return {sorted, inversions % 2 == 0 ? 1 : -1};
}

/// The faces of the tetrahedra's boundary, counter-clockwise from outside: each tetrahedron
/// turned to positive volume at x gives its four faces outward; a face two of them share comes
/// once each way and cancels.
std::vector<uint32_t> boundaryFaces(std::span<const btVector3> x,
                                    std::span<const Tetrahedron> tetrahedra) {
  std::vector<OrientedFace> faces;
  faces.reserve(4 * tetrahedra.size());
  for (Tetrahedron t : tetrahedra) {
    double sixVolume = 0;
    tetrahedronQuality(x, t, sixVolume);
    if (sixVolume < 0) std::swap(t[2], t[3]);
    faces.push_back(orientedFace(t[1], t[2], t[3]));
    faces.push_back(orientedFace(t[0], t[3], t[2]));
    faces.push_back(orientedFace(t[0], t[1], t[3]));
    faces.push_back(orientedFace(t[0], t[2], t[1]));
  }
  std::sort(faces.begin(), faces.end(),
            [](const OrientedFace& a, const OrientedFace& b) { return a.particles < b.particles; });
  std::vector<uint32_t> boundary;
  for (size_t k = 0; k < faces.size();) {
    int sign = 0;
    const std::array<uint32_t, 3>& f = faces[k].particles;
    for (; k < faces.size() && faces[k].particles == f; ++k) sign += faces[k].sign;
    for (int copy = 0; copy < std::abs(sign); ++copy) {
      const bool even = sign > 0;
      boundary.insert(boundary.end(), {f[0], even ? f[1] : f[2], even ? f[2] : f[1]});
    }
  }
  return boundary;
}

}  // namespace

void buildEnclosedVolume(MuscleSettings& muscle, std::span<const Tetrahedron> interior) {
  muscle.enclosedFaces.clear();
  muscle.enclosedRestVolume = 0;
  if (!(muscle.enclosedModulus > 0)) return;
  muscle.enclosedFaces = boundaryFaces(muscle.restPositions, interior);
  muscle.enclosedRestVolume = enclosedParticleVolume(muscle, muscle.restPositions);
  if (!(muscle.enclosedRestVolume > 0)) muscle.enclosedFaces.clear();
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
