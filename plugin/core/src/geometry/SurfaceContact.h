#pragma once
// Surface contact (internal): the stage after the skin (method.md §7) that keeps a muscle's
// deformed surface out of the bones' true meshes. The collision spheres keep the boundary
// particles out, but a surface vertex lies up to a few millimetres beyond its particles' spheres
// (their radius is the mean distance to the vertices that chose them, and radii shrink until the
// rest pose is free of overlaps), so where a muscle presses on a bone the layer between the
// spheres and the surface reached into it (hip-pelvis: 1.38 mm into the pelvis, measured on
// vertices whose particles' spheres had shrunk to 0-1.2 mm). Here that layer is squashed onto
// the bone instead: the vertex moves to the bone's surface.
#include <LinearMath/btTransform.h>

#include <span>

#include "fibremss/Geometry.h"

namespace fibremss {

/// A bone as surface contact sees it: closest points on its true mesh and the mesh's bounds,
/// bone frame. Built once per bone (allocates).
struct ContactMesh {
  explicit ContactMesh(const TriangleMesh& mesh);
  MeshDistance distance;  ///< closest points [m]
  btVector3 lower;        ///< lower corner of the mesh's bounds [m]
  btVector3 upper;        ///< upper corner [m]
};

/// Moves every vertex of `surface` (world frame) that lies inside `bone` (placed at
/// `boneToWorld`) at most `reach[v]` [m] deep onto the mesh's closest point; a deeper vertex stays
/// where it is (the closest-point query stops at its reach, which makes a vertex far from the bone
/// cost a box test or two). `lower`, `upper`: world bounds of the surface grown by the largest
/// reach; nothing is tested when the bone's bounds miss them. Returns how many vertices moved. No
/// allocation; thread-safe for different surfaces.
size_t liftOutOfBone(const ContactMesh& bone, const btTransform& boneToWorld,
                     std::span<const btScalar> reach, const btVector3& lower,
                     const btVector3& upper, std::span<btVector3> surface);

}  // namespace fibremss
