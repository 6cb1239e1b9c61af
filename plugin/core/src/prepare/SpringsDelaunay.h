#pragma once
// Delaunay tetrahedralization edges through qhull (reentrant C API). Internal to preparation.
#include <LinearMath/btVector3.h>

#include <array>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "fibremss/Preparation.h"

namespace fibremss::detail {

/// The Delaunay tetrahedra of `positions` (qhull, triangulated), four particle indices each, in
/// qhull's order (either orientation); throws InputError naming the muscle when qhull cannot
/// triangulate (e.g. all points coplanar).
std::vector<std::array<uint32_t, 4>> delaunayTetrahedra(const MuscleInput& muscle,
                                                        std::span<const btVector3> positions);

/// Edges (i < j, unsorted, may repeat) of the Delaunay tetrahedra of `positions`; throws
/// InputError naming the muscle when qhull cannot triangulate (e.g. all points coplanar).
std::vector<std::pair<uint32_t, uint32_t>> delaunayEdges(const MuscleInput& muscle,
                                                         std::span<const btVector3> positions);

}  // namespace fibremss::detail
