#pragma once
// The closest point of a triangle to a point, and of a box: MeshDistance's, for callers that
// search candidate triangles of their own and must find the same distances bit for bit.
#include <LinearMath/btVector3.h>

#include <cstdint>

namespace fibremss {

/// Which part of a triangle a closest point lies on; the edge i runs from corner i to i+1.
enum class TriangleFeature : uint8_t { Vertex0, Vertex1, Vertex2, Edge0, Edge1, Edge2, Face };

/// A triangle's closest point to a query point, and where on the triangle it lies.
struct TrianglePoint {
  btVector3 point;          ///< the closest point [the triangle's unit, m in FibreMSS]
  TriangleFeature feature;  ///< the corner, edge or face it lies on
};

/// Exact closest point on triangle abc (Voronoi regions of corners, edges and face).
inline TrianglePoint closestOnTriangle(const btVector3& p, const btVector3& a, const btVector3& b,
                                       const btVector3& c) {
  const btVector3 ab = b - a, ac = c - a, ap = p - a;
  const btScalar d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {a, TriangleFeature::Vertex0};
  const btVector3 bp = p - b;
  const btScalar d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {b, TriangleFeature::Vertex1};
  const btScalar vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return {a + ab * (d1 / (d1 - d3)), TriangleFeature::Edge0};
  const btVector3 cp = p - c;
  const btScalar d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {c, TriangleFeature::Vertex2};
  const btScalar vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return {a + ac * (d2 / (d2 - d6)), TriangleFeature::Edge2};
  const btScalar va = d3 * d6 - d5 * d4;
  if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0)
    return {b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))), TriangleFeature::Edge1};
  const btScalar sum = va + vb + vc;
  if (sum > 0) return {a + ab * (vb / sum) + ac * (vc / sum), TriangleFeature::Face};
  // Degenerate (zero-area) triangle that slipped through the tests above: nearest corner.
  const btScalar da = ap.length2(), db = bp.length2(), dc = cp.length2();
  if (da <= db && da <= dc) return {a, TriangleFeature::Vertex0};
  return db <= dc ? TrianglePoint{b, TriangleFeature::Vertex1}
                  : TrianglePoint{c, TriangleFeature::Vertex2};
}

/// The squared distance from p to the box [lower, upper] (0 inside).
inline btScalar boxDistance2(const btVector3& p, const btVector3& lower, const btVector3& upper) {
  btVector3 outside = lower - p;
  outside.setMax(p - upper);
  outside.setMax(btVector3(0, 0, 0));
  return outside.length2();
}

}  // namespace fibremss
