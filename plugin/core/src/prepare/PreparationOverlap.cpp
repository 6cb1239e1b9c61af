// Rest-pose overlaps (seed 001 §4.1): meshes from different scans overlap, so particles can
// start inside a bone or inside another muscle. Collisions would push them out in the first
// iterations, violently and against their springs; moving them out along the other body's
// normal before springs are built lets the muscle start at rest, as seed 001 does with its
// surface vertices.
#include <algorithm>
#include <cmath>

#include "PreparationInternal.h"

namespace fibremss::detail {

PushedOut pushOutOf(std::span<btVector3> points, const MeshDistance& body, btScalar minDepth,
                    btScalar margin, const std::function<bool(const btVector3&)>& mayStay) {
  btVector3 lower, upper;
  pointBounds(body.mesh().vertices, lower, upper);
  PushedOut pushed;
  for (btVector3& p : points) {
    if (p.x() < lower.x() || p.y() < lower.y() || p.z() < lower.z() || p.x() > upper.x() ||
        p.y() > upper.y() || p.z() > upper.z())
      continue;
    const MeshDistance::Closest closest = body.closest(p);
    if (!closest.inside || !(closest.distance > 0)) continue;
    if (closest.distance <= minDepth && (!mayStay || mayStay(p))) continue;
    // p is inside, so the closest surface point lies outward of it.
    p = closest.point + (closest.point - p) / closest.distance * margin;
    ++pushed.count;
    pushed.deepest = std::max(pushed.deepest, closest.distance);
  }
  return pushed;
}

}  // namespace fibremss::detail
