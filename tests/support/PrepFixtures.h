#pragma once
// Small closed meshes with known geometry for the geometry, preparation and output tests.
#include <algorithm>
#include <cmath>
#include <limits>

#include "fibremss/Geometry.h"
#include "fibremss/MuscleSettings.h"
#include "fibremss/Procedural.h"

namespace fibremss::testing {

/// Axis-aligned box [lower, upper], 12 triangles, outward normals.
inline TriangleMesh boxMesh(const btVector3& lower, const btVector3& upper) {
  TriangleMesh mesh;
  for (int i = 0; i < 8; ++i)
    mesh.vertices.emplace_back(i & 1 ? upper.x() : lower.x(), i & 2 ? upper.y() : lower.y(),
                               i & 4 ? upper.z() : lower.z());
  mesh.triangles = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                    {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return mesh;
}

/// Icosphere of `radius` around `centre` with `subdivisions` levels (20·4^s triangles): the
/// procedural scenes' ellipsoid with equal radii.
inline TriangleMesh sphereMesh(const btVector3& centre, btScalar radius, int subdivisions) {
  return makeEllipsoid(centre, btVector3(radius, radius, radius), subdivisions);
}

/// Closed cylinder along x from x0 to x1, `segments` around, `rings` along, capped with fans.
inline TriangleMesh tubeMesh(btScalar x0, btScalar x1, btScalar radius, int segments, int rings) {
  TriangleMesh mesh;
  const btScalar pi = std::acos(btScalar(-1));
  for (int r = 0; r <= rings; ++r)
    for (int s = 0; s < segments; ++s) {
      const btScalar angle = 2 * pi * s / segments;
      mesh.vertices.emplace_back(x0 + (x1 - x0) * r / rings, radius * std::cos(angle),
                                 radius * std::sin(angle));
    }
  auto at = [&](int r, int s) { return static_cast<uint32_t>(r * segments + (s % segments)); };
  for (int r = 0; r < rings; ++r)
    for (int s = 0; s < segments; ++s) {
      mesh.triangles.push_back({at(r, s), at(r, s + 1), at(r + 1, s + 1)});
      mesh.triangles.push_back({at(r, s), at(r + 1, s + 1), at(r + 1, s)});
    }
  const auto start = static_cast<uint32_t>(mesh.vertices.size());
  mesh.vertices.emplace_back(x0, 0, 0);
  mesh.vertices.emplace_back(x1, 0, 0);
  for (int s = 0; s < segments; ++s) {
    mesh.triangles.push_back({start, at(0, s + 1), at(0, s)});
    mesh.triangles.push_back({start + 1, at(rings, s), at(rings, s + 1)});
  }
  return mesh;
}

/// Closest point on a triangle by brute force: the face projection if inside, else the nearest
/// of the three edges (each a clamped segment projection).
inline btVector3 bruteClosestOnTriangle(const btVector3& p, const btVector3& a, const btVector3& b,
                                        const btVector3& c) {
  const btVector3 normal = (b - a).cross(c - a).normalized();
  const btVector3 projected = p - normal * (p - a).dot(normal);
  auto insideEdge = [&](const btVector3& u, const btVector3& v) {
    return (v - u).cross(projected - u).dot(normal) >= 0;
  };
  if (insideEdge(a, b) && insideEdge(b, c) && insideEdge(c, a)) return projected;
  auto onSegment = [&](const btVector3& u, const btVector3& v) {
    const btScalar t = std::clamp((p - u).dot(v - u) / (v - u).length2(), btScalar(0), btScalar(1));
    return u + (v - u) * t;
  };
  btVector3 best = onSegment(a, b);
  for (const btVector3& candidate : {onSegment(b, c), onSegment(c, a)})
    if ((candidate - p).length2() < (best - p).length2()) best = candidate;
  return best;
}

/// Whether particles a and b lie on one fibre of the muscle.
inline bool shareAFibre(const MuscleSettings& muscle, uint32_t a, uint32_t b) {
  for (size_t f = 0; f < muscle.fibreCount(); ++f) {
    const auto begin = muscle.fibreParticles.begin() + muscle.fibreOffsets[f];
    const auto end = muscle.fibreParticles.begin() + muscle.fibreOffsets[f + 1];
    if (std::find(begin, end, a) != end && std::find(begin, end, b) != end) return true;
  }
  return false;
}

/// Distance from p to a mesh by testing every triangle.
inline btScalar bruteDistance(const TriangleMesh& mesh, const btVector3& p) {
  btScalar best = std::numeric_limits<btScalar>::infinity();
  for (const auto& t : mesh.triangles)
    best = std::min(best, (p - bruteClosestOnTriangle(p, mesh.vertices[t[0]], mesh.vertices[t[1]],
                                                      mesh.vertices[t[2]]))
                              .length());
  return best;
}

}  // namespace fibremss::testing
