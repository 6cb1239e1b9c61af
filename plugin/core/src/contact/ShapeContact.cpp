#include "ShapeContact.h"

#include <BulletCollision/CollisionShapes/btBoxShape.h>
#include <BulletCollision/CollisionShapes/btCapsuleShape.h>
#include <BulletCollision/CollisionShapes/btCompoundShape.h>
#include <BulletCollision/CollisionShapes/btSphereShape.h>
#include <BulletCollision/CollisionShapes/btStaticPlaneShape.h>
#include <BulletCollision/NarrowPhaseCollision/btGjkEpa2.h>

#include <algorithm>
#include <cmath>

namespace fibremss {
namespace {

/// Contact from the signed distance `distance` of p along the unit `normal` out of the shape.
bool fromDistance(const btVector3& p, btScalar r, btScalar distance, const btVector3& normal,
                  ShapeContact& out) {
  if (!(distance < r)) return false;
  out.normal = normal;
  out.depth = r - distance;
  out.point = p - normal * distance;
  return true;
}

/// The unit vector of `d`, or +y when it has no length (a centre on the feature itself).
btVector3 directionOf(const btVector3& d, btScalar length) {
  return length > SIMD_EPSILON ? d / length : btVector3(0, 1, 0);
}

bool sphereContact(const btSphereShape& sphere, const btTransform& transform, const btVector3& p,
                   btScalar r, ShapeContact& out) {
  const btVector3 d = p - transform.getOrigin();
  const btScalar length = d.length();
  return fromDistance(p, r, length - sphere.getRadius(), directionOf(d, length), out);
}

bool capsuleContact(const btCapsuleShape& capsule, const btTransform& transform, const btVector3& p,
                    btScalar r, ShapeContact& out) {
  const btVector3 local = transform.invXform(p);
  const int up = capsule.getUpAxis();
  btVector3 nearest(0, 0, 0);
  nearest[up] = std::clamp(local[up], -capsule.getHalfHeight(), capsule.getHalfHeight());
  const btVector3 d = local - nearest;
  const btScalar length = d.length();
  return fromDistance(p, r, length - capsule.getRadius(),
                      transform.getBasis() * directionOf(d, length), out);
}

bool boxContact(const btBoxShape& box, const btTransform& transform, const btVector3& p, btScalar r,
                ShapeContact& out) {
  const btVector3 local = transform.invXform(p);
  const btVector3 half = box.getHalfExtentsWithMargin();
  btVector3 clamped = local;
  clamped.setMax(-half);
  clamped.setMin(half);
  const btVector3 outside = local - clamped;
  const btScalar length = outside.length();
  if (length > 0) return fromDistance(p, r, length, transform.getBasis() * (outside / length), out);
  // Inside: out through the nearest face.
  int axis = 0;
  btScalar room = half[0] - std::abs(local[0]);
  for (int k = 1; k < 3; ++k)
    if (half[k] - std::abs(local[k]) < room) {
      room = half[k] - std::abs(local[k]);
      axis = k;
    }
  btVector3 normal(0, 0, 0);
  normal[axis] = local[axis] < 0 ? -1 : 1;
  return fromDistance(p, r, -room, transform.getBasis() * normal, out);
}

bool planeContact(const btStaticPlaneShape& plane, const btTransform& transform, const btVector3& p,
                  btScalar r, ShapeContact& out) {
  const btVector3 normal = transform.getBasis() * plane.getPlaneNormal();
  const btVector3 onPlane = transform * (plane.getPlaneNormal() * plane.getPlaneConstant());
  return fromDistance(p, r, normal.dot(p - onPlane), normal, out);
}

bool convexContact(const btConvexShape& shape, const btTransform& transform, const btVector3& p,
                   btScalar r, ShapeContact& out) {
  btGjkEpaSolver2::sResults results;
  const btScalar distance = btGjkEpaSolver2::SignedDistance(p, 0, &shape, transform, results);
  if (!(distance < r) || !std::isfinite(results.normal.length2())) return false;
  // The normal at a surface point points to where the shape extends least beyond it: right at
  // the surface GJK may call a point inside and give the normal reversed.
  const btVector3& surface = results.witnesses[0];
  const auto reach = [&](const btVector3& direction) {
    const btVector3 local = transform.getBasis().transpose() * direction;
    return (transform * shape.localGetSupportingVertex(local) - surface).dot(direction);
  };
  out.normal = reach(results.normal) <= reach(-results.normal) ? results.normal : -results.normal;
  out.depth = r - distance;
  out.point = surface;
  return true;
}

}  // namespace

bool sphereShapeContact(const btCollisionShape& shape, const btTransform& transform,
                        const btVector3& p, btScalar r, ShapeContact& out) {
  switch (shape.getShapeType()) {
    case SPHERE_SHAPE_PROXYTYPE:
      return sphereContact(static_cast<const btSphereShape&>(shape), transform, p, r, out);
    case CAPSULE_SHAPE_PROXYTYPE:
      return capsuleContact(static_cast<const btCapsuleShape&>(shape), transform, p, r, out);
    case BOX_SHAPE_PROXYTYPE:
      return boxContact(static_cast<const btBoxShape&>(shape), transform, p, r, out);
    case STATIC_PLANE_PROXYTYPE:
      return planeContact(static_cast<const btStaticPlaneShape&>(shape), transform, p, r, out);
    case COMPOUND_SHAPE_PROXYTYPE: {
      const auto& compound = static_cast<const btCompoundShape&>(shape);
      bool found = false;
      ShapeContact child;
      for (int k = 0; k < compound.getNumChildShapes(); ++k)
        if (sphereShapeContact(*compound.getChildShape(k),
                               transform * compound.getChildTransform(k), p, r, child) &&
            (!found || child.depth > out.depth)) {
          out = child;
          found = true;
        }
      return found;
    }
    default:
      return shape.isConvex() &&
             convexContact(static_cast<const btConvexShape&>(shape), transform, p, r, out);
  }
}

bool touchableShape(const btCollisionShape& shape) {
  return shape.isConvex() || shape.isCompound() || shape.getShapeType() == STATIC_PLANE_PROXYTYPE;
}

}  // namespace fibremss
