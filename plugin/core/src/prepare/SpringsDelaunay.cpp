#include "SpringsDelaunay.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "PreparationInternal.h"
#include "PreparationKdTree.h"
#include "fibremss/Error.h"

extern "C" {
#include <libqhull_r/qhull_ra.h>
}

namespace fibremss::detail {

namespace {

constexpr uint32_t kNone = UINT32_MAX;

/// Particles from which on their spread is checked (fewer tetrahedralize in well under a second).
constexpr size_t kSpreadCheckedFrom = 2000;
/// How much closer than an even spread the particles' nearest neighbours may lie: particles
/// packed along few lines (straight or curved fibres sampled far more densely along than across)
/// have a Delaunay tetrahedralization quadratic in their number (10⁶ tetrahedra from 4000
/// particles), which qhull needs minutes for.
constexpr double kMaxPacking = 16;

/// Refuses particles packed along lines (kMaxPacking): the mean distance to the nearest
/// neighbour against the spacing N particles spread evenly through their bounding box would have.
void requireSpreadParticles(const MuscleInput& muscle, std::span<const btVector3> positions) {
  if (positions.size() < kSpreadCheckedFrom) return;
  btVector3 lower = positions.front(), upper = positions.front();
  for (const btVector3& p : positions) lower.setMin(p), upper.setMax(p);
  const btVector3 size = upper - lower;
  const double even = std::cbrt(double(size.x()) * size.y() * size.z() / double(positions.size()));
  const KdTree tree(positions);
  double sum = 0;
  for (const btVector3& p : positions) {
    uint32_t nearest[2];
    btScalar distance2[2];
    if (tree.nearest(p, 2, nearest, distance2) == 2) sum += std::sqrt(double(distance2[1]));
  }
  const double mean = sum / double(positions.size());
  if (mean * kMaxPacking < even)
    throw InputError(muscleSource(muscle), "springs.layout",
                     "the " + std::to_string(positions.size()) +
                         " particles lie packed along few lines (nearest neighbours " +
                         std::to_string(even / std::max(mean, 1e-300)) +
                         "x closer than an even spread): their tetrahedralization would be "
                         "quadratic in their number; expected more fibres or a lower resolution");
}

/// The lower Delaunay facets' particles, four per facet, kNone where a facet has fewer (a
/// vertex at infinity from Qz).
std::vector<std::array<uint32_t, 4>> delaunayFacets(const MuscleInput& muscle,
                                                    std::span<const btVector3> positions) {
  if (positions.size() < 5)
    throw InputError(
        muscleSource(muscle), "springs.layout",
        "delaunay needs at least 5 particles, got " + std::to_string(positions.size()));
  requireSpreadParticles(muscle, positions);
  std::vector<coordT> coordinates;
  coordinates.reserve(3 * positions.size());
  for (const btVector3& p : positions) coordinates.insert(coordinates.end(), {p.x(), p.y(), p.z()});

  // qhull reports problems on a FILE*; collect them in memory for the error message.
  char* messageBuffer = nullptr;
  size_t messageSize = 0;
  FILE* messages = open_memstream(&messageBuffer, &messageSize);
  qhT state;
  qhT* qh = &state;
  qh_zero(qh, messages);
  // d: Delaunay; Qt: triangulated output; Qbb: scale the paraboloid; Qz: a point at infinity
  // for cospherical input (lattices are full of it).
  char options[] = "qhull d Qt Qbb Qz";
  const int exitCode = qh_new_qhull(qh, 3, static_cast<int>(positions.size()), coordinates.data(),
                                    False, options, nullptr, messages);
  std::vector<std::array<uint32_t, 4>> tetrahedra;
  if (exitCode == 0) {
    facetT* facet;
    vertexT *vertex, **vertexp;
    FORALLfacets {
      if (facet->upperdelaunay) continue;
      std::array<uint32_t, 4> ids{kNone, kNone, kNone, kNone};
      size_t count = 0;
      FOREACHvertex_(facet->vertices) {
        const int id = qh_pointid(qh, vertex->point);
        if (id >= 0 && size_t(id) < positions.size() && count < 4)
          ids[count++] = static_cast<uint32_t>(id);
      }
      tetrahedra.push_back(ids);
    }
  }
  qh_freeqhull(qh, !qh_ALL);
  int currentLong = 0, totalLong = 0;
  qh_memfreeshort(qh, &currentLong, &totalLong);
  if (messages) fclose(messages);
  const std::string message = messageBuffer ? std::string(messageBuffer, messageSize) : "";
  free(messageBuffer);
  if (exitCode != 0)
    throw InputError(muscleSource(muscle), "springs.layout",
                     "qhull cannot tetrahedralize the particles (coplanar or degenerate?): " +
                         message.substr(0, 400));
  return tetrahedra;
}

}  // namespace

std::vector<std::array<uint32_t, 4>> delaunayTetrahedra(const MuscleInput& muscle,
                                                        std::span<const btVector3> positions) {
  std::vector<std::array<uint32_t, 4>> tetrahedra = delaunayFacets(muscle, positions);
  std::erase_if(tetrahedra, [](const std::array<uint32_t, 4>& t) { return t[3] == kNone; });
  return tetrahedra;
}

std::vector<std::pair<uint32_t, uint32_t>> delaunayEdges(const MuscleInput& muscle,
                                                         std::span<const btVector3> positions) {
  std::vector<std::pair<uint32_t, uint32_t>> edges;
  for (const std::array<uint32_t, 4>& t : delaunayFacets(muscle, positions))
    for (size_t i = 0; i < 4; ++i)
      for (size_t j = i + 1; j < 4 && t[j] != kNone; ++j)
        edges.emplace_back(std::min(t[i], t[j]), std::max(t[i], t[j]));
  return edges;
}

}  // namespace fibremss::detail
