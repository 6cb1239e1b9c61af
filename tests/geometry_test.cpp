// Geometry: volumes, bounds, transforms and MeshDistance against brute force.
#include "fibremss/Geometry.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <thread>

#include "support/PrepFixtures.h"

namespace fibremss {
namespace {

using testing::boxMesh;
using testing::sphereMesh;
using testing::tubeMesh;

using testing::bruteClosestOnTriangle;
using testing::bruteDistance;

TEST(Geometry, VolumeOfUnitCubeIsOne) {
  EXPECT_NEAR(meshVolume(boxMesh({0, 0, 0}, {1, 1, 1})), 1.0, 1e-6);
  EXPECT_NEAR(meshVolume(boxMesh({-2, 3, 1}, {1, 4, 3})), 3.0 * 1 * 2, 1e-5);
}

TEST(Geometry, VolumeOfTetrahedronIsOneSixthAndFlipsWithOrientation) {
  TriangleMesh tetra;
  tetra.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  tetra.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  EXPECT_NEAR(meshVolume(tetra), 1.0 / 6.0, 1e-7);
  for (auto& t : tetra.triangles) std::swap(t[1], t[2]);
  EXPECT_NEAR(meshVolume(tetra), -1.0 / 6.0, 1e-7);
}

TEST(Geometry, SphereVolumeApproachesAnalytic) {
  const btScalar radius = 0.05;
  const double exact = 4.0 / 3.0 * M_PI * radius * radius * radius;
  const double coarse = meshVolume(sphereMesh({0, 0, 0}, radius, 2));
  const double fine = meshVolume(sphereMesh({0, 0, 0}, radius, 4));
  EXPECT_LT(coarse, exact);  // inscribed polyhedron
  EXPECT_LT(fine, exact);
  EXPECT_LT(exact - fine, exact - coarse);
  EXPECT_NEAR(fine, exact, exact * 0.01);
}

TEST(Geometry, TubeVolumeMatchesPrism) {
  const int segments = 16;
  const btScalar radius = 0.02, length = 0.1;
  const double polygonArea = 0.5 * segments * radius * radius * std::sin(2 * M_PI / segments);
  EXPECT_NEAR(meshVolume(tubeMesh(0, length, radius, segments, 5)), polygonArea * length, 1e-8);
}

TEST(Geometry, PointBoundsAndTransform) {
  std::vector<btVector3> points = {{1, -2, 3}, {-1, 5, 0}, {0, 0, 7}};
  btVector3 lower, upper;
  pointBounds(points, lower, upper);
  EXPECT_EQ(lower, btVector3(-1, -2, 0));
  EXPECT_EQ(upper, btVector3(1, 5, 7));

  const TriangleMesh box = boxMesh({0, 0, 0}, {1, 1, 1});
  const btTransform transform(btQuaternion(btVector3(0, 0, 1), SIMD_HALF_PI), btVector3(1, 2, 3));
  const TriangleMesh moved = transformed(box, transform);
  ASSERT_EQ(moved.vertices.size(), box.vertices.size());
  EXPECT_EQ(moved.triangles, box.triangles);
  for (size_t i = 0; i < box.vertices.size(); ++i)
    EXPECT_LT((moved.vertices[i] - transform * box.vertices[i]).length(), 1e-6);
  EXPECT_NEAR(meshVolume(moved), 1.0, 1e-5);  // rigid: volume and orientation kept
}

TEST(MeshDistance, ClosestMatchesBruteForceOnRandomPoints) {
  const TriangleMesh mesh = sphereMesh({0.1f, -0.2f, 0.05f}, 0.05f, 3);
  const MeshDistance distance(mesh);
  std::mt19937 random(7);
  std::uniform_real_distribution<btScalar> coordinate(-0.12f, 0.12f);
  for (int i = 0; i < 500; ++i) {
    const btVector3 p = btVector3(0.1f, -0.2f, 0.05f) +
                        btVector3(coordinate(random), coordinate(random), coordinate(random));
    const MeshDistance::Closest closest = distance.closest(p);
    ASSERT_LT(closest.triangle, mesh.triangles.size());
    const btScalar expected = bruteDistance(mesh, p);
    EXPECT_NEAR(closest.distance, expected, 1e-6) << "point " << i;
    EXPECT_NEAR((closest.point - p).length(), closest.distance, 1e-6);
    // The reported point lies on the reported triangle.
    const auto& t = mesh.triangles[closest.triangle];
    const btVector3 onTriangle = bruteClosestOnTriangle(closest.point, mesh.vertices[t[0]],
                                                        mesh.vertices[t[1]], mesh.vertices[t[2]]);
    EXPECT_LT((onTriangle - closest.point).length(), 1e-6);
  }
}

TEST(MeshDistance, ALimitedSearchFindsTheClosestPointWithinItOrNothing) {
  const TriangleMesh mesh = sphereMesh({0.1f, -0.2f, 0.05f}, 0.05f, 3);
  const MeshDistance distance(mesh);
  std::mt19937 random(11);
  std::uniform_real_distribution<btScalar> coordinate(-0.12f, 0.12f);
  std::uniform_real_distribution<btScalar> share(0.2f, 2.0f);
  int within = 0, beyond = 0;
  for (int i = 0; i < 500; ++i) {
    const btVector3 p = btVector3(0.1f, -0.2f, 0.05f) +
                        btVector3(coordinate(random), coordinate(random), coordinate(random));
    const MeshDistance::Closest anywhere = distance.closest(p);
    const btScalar limit = anywhere.distance * share(random);
    const MeshDistance::Closest limited = distance.closest(p, limit);
    if (anywhere.distance < limit * btScalar(0.999)) {
      ++within;
      EXPECT_EQ(limited.triangle, anywhere.triangle) << "point " << i;
      EXPECT_EQ(limited.distance, anywhere.distance) << "point " << i;
      EXPECT_EQ(limited.inside, anywhere.inside) << "point " << i;
    } else if (anywhere.distance > limit * btScalar(1.001)) {
      ++beyond;
      EXPECT_EQ(limited.triangle, UINT32_MAX) << "point " << i;
    }
  }
  EXPECT_GT(within, 100);
  EXPECT_GT(beyond, 100);
}

TEST(MeshDistance, SignedDistanceInsideAndOutsideOfClosedSphere) {
  const btVector3 centre(0.3f, 0.1f, -0.4f);
  const btScalar radius = 0.04f;
  const TriangleMesh mesh = sphereMesh(centre, radius, 3);
  const MeshDistance distance(mesh);
  // The inscribed polyhedron lies between the inner radius (face planes) and the sphere.
  btScalar innerRadius = radius;
  for (const auto& t : mesh.triangles) {
    const btVector3 normal = (mesh.vertices[t[1]] - mesh.vertices[t[0]])
                                 .cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]);
    innerRadius = std::min(innerRadius, (mesh.vertices[t[0]] - centre).dot(normal.normalized()));
  }
  std::mt19937 random(11);
  std::uniform_real_distribution<btScalar> coordinate(-2 * radius, 2 * radius);
  int inside = 0, outside = 0;
  for (int i = 0; i < 2000; ++i) {
    const btVector3 p =
        centre + btVector3(coordinate(random), coordinate(random), coordinate(random));
    const btScalar r = (p - centre).length();
    if (std::abs(r - innerRadius) < 1e-5f || std::abs(r - radius) < 1e-5f) continue;
    const btScalar signedDistance = distance.signedDistance(p);
    EXPECT_NEAR(std::abs(signedDistance), bruteDistance(mesh, p), 1e-6);
    EXPECT_EQ(distance.closest(p).inside, signedDistance < 0);
    if (r < innerRadius) {
      EXPECT_LT(signedDistance, 0) << "point " << i << " at r=" << r;
      ++inside;
    } else if (r > radius) {
      EXPECT_GT(signedDistance, 0) << "point " << i << " at r=" << r;
      ++outside;
    }
  }
  EXPECT_GT(inside, 100);
  EXPECT_GT(outside, 100);
}

TEST(MeshDistance, SignIsRightNearEdgesAndVerticesOfACube) {
  // Points just outside a cube's edges and corners are nearest to an edge or a vertex, where
  // a plain face normal gives the wrong sign half the time.
  const TriangleMesh cube = boxMesh({0, 0, 0}, {1, 1, 1});
  const MeshDistance distance(cube);
  const btScalar e = 0.01f;
  for (const btVector3& p :
       {btVector3(1 + e, 1 + e, 0.5f), btVector3(-e, 0.5f, -e), btVector3(1 + e, 1 + e, 1 + e),
        btVector3(-e, -e, -e), btVector3(0.5f, 1 + e, 1 + e), btVector3(1 + e, -e, 0.3f)})
    EXPECT_GT(distance.signedDistance(p), 0) << p.x() << " " << p.y() << " " << p.z();
  for (const btVector3& p :
       {btVector3(1 - e, 1 - e, 0.5f), btVector3(e, 0.5f, e), btVector3(1 - e, 1 - e, 1 - e),
        btVector3(e, e, e), btVector3(0.5f, 0.5f, 0.5f)})
    EXPECT_LT(distance.signedDistance(p), 0) << p.x() << " " << p.y() << " " << p.z();
  EXPECT_NEAR(distance.signedDistance({1 + e, 1 + e, 1 + e}), std::sqrt(3.f) * e, 1e-6);
  EXPECT_NEAR(distance.signedDistance({0.5f, 0.5f, 0.5f}), -0.5f, 1e-6);
}

TEST(MeshDistance, FrontFaceOfAPointOutsideACubeIsItsFarthestFacePlane) {
  // Outside a convex mesh the face plane a point lies farthest in front of is the mesh inflated
  // with sharp edges: for the unit cube, the largest of the six signed plane distances, which is
  // shorter than the distance to the closest edge or corner.
  const MeshDistance distance(boxMesh({0, 0, 0}, {1, 1, 1}));
  std::mt19937 random(7);
  std::uniform_real_distribution<float> coordinate(-0.6f, 1.6f);
  int edges = 0;
  for (int k = 0; k < 2000; ++k) {
    const btVector3 p(coordinate(random), coordinate(random), coordinate(random));
    const MeshDistance::Closest closest = distance.closest(p);
    if (closest.inside) continue;
    const btScalar planes = std::max({p.x() - 1, -p.x(), p.y() - 1, -p.y(), p.z() - 1, -p.z()});
    const MeshDistance::Plane face = distance.frontFace(p, closest);
    EXPECT_NEAR(face.distance, planes, 1e-5) << p.x() << " " << p.y() << " " << p.z();
    EXPECT_NEAR(face.normal.length(), 1, 1e-5);
    EXPECT_LE(face.distance, closest.distance + 1e-5f);
    edges += closest.feature != 6 && face.distance < closest.distance - 0.01f ? 1 : 0;
  }
  EXPECT_GT(edges, 100);
  const btVector3 beside(1.3f, 0.5f, 1.1f);  // off the edge x = z = 1, farther out along x
  const MeshDistance::Plane face = distance.frontFace(beside, distance.closest(beside));
  EXPECT_NEAR(face.normal.x(), 1, 1e-6);
  EXPECT_NEAR(face.distance, 0.3f, 1e-6);
}

TEST(MeshDistance, MaxDistanceLimitsTheSearch) {
  const MeshDistance distance(boxMesh({0, 0, 0}, {1, 1, 1}));
  const MeshDistance::Closest far = distance.closest({3, 0.5f, 0.5f}, 1.5f);
  EXPECT_TRUE(std::isinf(far.distance));
  EXPECT_EQ(far.triangle, UINT32_MAX);
  EXPECT_EQ(distance.closest({0.5f, 0.5f, 0.5f}, -1).triangle, UINT32_MAX);
  const MeshDistance::Closest near = distance.closest({3, 0.5f, 0.5f}, 2.5f);
  EXPECT_NEAR(near.distance, 2.0f, 1e-6);
  EXPECT_NEAR(near.point.x(), 1.0f, 1e-6);
}

TEST(MeshDistance, EmptyMeshFindsNothing) {
  const MeshDistance distance{TriangleMesh{}};
  EXPECT_TRUE(std::isinf(distance.closest({0, 0, 0}).distance));
  EXPECT_GT(distance.signedDistance({0, 0, 0}), 0);
}

TEST(MeshDistance, DegenerateTrianglesDoNotBreakQueries) {
  TriangleMesh cube = boxMesh({0, 0, 0}, {1, 1, 1});
  cube.triangles.push_back({0, 0, 1});  // zero-area sliver along an existing edge
  cube.triangles.push_back({2, 2, 2});  // collapsed to a point
  const MeshDistance distance(cube);
  EXPECT_NEAR(distance.closest({0.5f, -1, 0}).distance, 1.0f, 1e-6);
  EXPECT_LT(distance.signedDistance({0.5f, 0.5f, 0.5f}), 0);
  EXPECT_GT(distance.signedDistance({0.5f, -0.2f, 0.5f}), 0);
}

TEST(MeshDistance, ConcurrentQueriesAgree) {
  const TriangleMesh mesh = sphereMesh({0, 0, 0}, 1, 3);
  const MeshDistance distance(mesh);
  std::vector<btVector3> points;
  std::mt19937 random(3);
  std::uniform_real_distribution<btScalar> coordinate(-2, 2);
  for (int i = 0; i < 2000; ++i)
    points.emplace_back(coordinate(random), coordinate(random), coordinate(random));
  std::vector<btScalar> serial(points.size()), parallel(points.size());
  for (size_t i = 0; i < points.size(); ++i) serial[i] = distance.signedDistance(points[i]);
  std::vector<std::thread> threads;
  for (size_t t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      for (size_t i = t; i < points.size(); i += 4)
        parallel[i] = distance.signedDistance(points[i]);
    });
  for (auto& thread : threads) thread.join();
  EXPECT_EQ(serial, parallel);
}

TEST(MeshDistance, MoveKeepsTheMesh) {
  MeshDistance first(boxMesh({0, 0, 0}, {1, 1, 1}));
  MeshDistance second = std::move(first);
  EXPECT_EQ(second.mesh().triangles.size(), 12u);
  EXPECT_NEAR(second.closest({2, 0.5f, 0.5f}).distance, 1.0f, 1e-6);
}

}  // namespace
}  // namespace fibremss
