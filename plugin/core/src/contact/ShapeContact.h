#pragma once
// Exact contact of a particle sphere with a rigid body's collision shape (internal): analytic
// for spheres, boxes, capsules and static planes, GJK/EPA signed distance for other convex
// shapes, the deepest child of a compound. Concave meshes and other shapes never touch.
#include <LinearMath/btTransform.h>

class btCollisionShape;

namespace fibremss {

/// Where a sphere overlaps a shape.
struct ShapeContact {
  btVector3 normal{1, 0, 0};  ///< unit direction out of the shape towards the sphere's centre
  btScalar depth = 0;         ///< overlap: radius − signed distance of the centre (> 0) [m]
  btVector3 point{0, 0, 0};   ///< the shape's surface point nearest the centre [m]
};

/// Whether the sphere (centre `p`, radius `r`) overlaps `shape` placed at `transform`; if so,
/// `out` says where. No allocation.
bool sphereShapeContact(const btCollisionShape& shape, const btTransform& transform,
                        const btVector3& p, btScalar r, ShapeContact& out);

/// Whether sphereShapeContact can find contacts with `shape` (convex, compound, static plane).
bool touchableShape(const btCollisionShape& shape);

}  // namespace fibremss
