#pragma once
// The rule by which a muscle's declared attachment areas fix material to bones, for callers
// other than preparation (the CalculiX reference attaches its mesh nodes by it).
#include <cstdint>
#include <vector>

#include "fibremss/Geometry.h"
#include "fibremss/Preparation.h"

namespace fibremss {

/// Per point, the bone the declared `areas` fix it to (-1: free), by the rule preparation fixes
/// a muscle's particles by (DeclaredAttachment): of the areas within `attachmentDistance` of
/// one of whose bones the point lies and whose surface vertices are at most that distance
/// farther from it than the nearest vertex of `restSurface` (the prepared surface, into which
/// the areas index), the nearest such bone. `bones` in the scene's order.
std::vector<int32_t> declaredAreaBones(const std::vector<DeclaredAttachment>& areas,
                                       btScalar attachmentDistance,
                                       const std::vector<btVector3>& restSurface,
                                       const std::vector<const MeshDistance*>& bones,
                                       const std::vector<btVector3>& points);

}  // namespace fibremss
