#include "fibremss/Geometry.h"

namespace fibremss {

btScalar meshVolume(const TriangleMesh& mesh) {
  // Divergence theorem: sum of signed tetrahedra (origin, a, b, c); double for large meshes.
  double sixVolume = 0;
  for (const auto& t : mesh.triangles) {
    const btVector3& a = mesh.vertices[t[0]];
    const btVector3& b = mesh.vertices[t[1]];
    const btVector3& c = mesh.vertices[t[2]];
    sixVolume += double(a.x()) * (double(b.y()) * c.z() - double(b.z()) * c.y()) +
                 double(a.y()) * (double(b.z()) * c.x() - double(b.x()) * c.z()) +
                 double(a.z()) * (double(b.x()) * c.y() - double(b.y()) * c.x());
  }
  return static_cast<btScalar>(sixVolume / 6.0);
}

void pointBounds(std::span<const btVector3> points, btVector3& lower, btVector3& upper) {
  if (points.empty()) {
    lower.setZero();
    upper.setZero();
    return;
  }
  lower = upper = points.front();
  for (const btVector3& p : points) {
    lower.setMin(p);
    upper.setMax(p);
  }
}

TriangleMesh transformed(const TriangleMesh& mesh, const btTransform& transform) {
  TriangleMesh result;
  result.vertices.reserve(mesh.vertices.size());
  for (const btVector3& v : mesh.vertices) result.vertices.push_back(transform * v);
  result.triangles = mesh.triangles;
  return result;
}

}  // namespace fibremss
