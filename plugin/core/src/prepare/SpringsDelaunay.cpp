#include "SpringsDelaunay.h"

#include <cstdio>
#include <string>

#include "PreparationInternal.h"
#include "fibremss/Error.h"

extern "C" {
#include <libqhull_r/qhull_ra.h>
}

namespace fibremss::detail {

std::vector<std::pair<uint32_t, uint32_t>> delaunayEdges(const MuscleInput& muscle,
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
  std::vector<std::pair<uint32_t, uint32_t>> edges;
  if (exitCode == 0) {
    facetT* facet;
    vertexT *vertex, **vertexp;
    std::vector<uint32_t> ids;
    FORALLfacets {
      if (facet->upperdelaunay) continue;
      ids.clear();
      FOREACHvertex_(facet->vertices) {
        const int id = qh_pointid(qh, vertex->point);
        if (id >= 0 && size_t(id) < positions.size()) ids.push_back(static_cast<uint32_t>(id));
      }
      for (size_t i = 0; i < ids.size(); ++i)
        for (size_t j = i + 1; j < ids.size(); ++j)
          edges.emplace_back(std::min(ids[i], ids[j]), std::max(ids[i], ids[j]));
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
  return edges;
}

}  // namespace fibremss::detail
