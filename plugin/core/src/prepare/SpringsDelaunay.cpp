#include "SpringsDelaunay.h"

#include <cstdio>
#include <string>

#include "PreparationInternal.h"
#include "fibremss/Error.h"

extern "C" {
#include <libqhull_r/qhull_ra.h>
}

namespace fibremss::detail {

namespace {

constexpr uint32_t kNone = UINT32_MAX;

/// The lower Delaunay facets' particles, four per facet, kNone where a facet has fewer (a
/// vertex at infinity from Qz).
std::vector<std::array<uint32_t, 4>> delaunayFacets(const MuscleInput& muscle,
                                                    std::span<const btVector3> positions) {
  if (positions.size() < 5)
    throw InputError(
        muscleSource(muscle), "springs.layout",
        "delaunay needs at least 5 particles, got " + std::to_string(positions.size()));
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
