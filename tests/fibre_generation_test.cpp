// Fibres generated from a surface (harmonic field + gradient streamlines), the sphere fits, the
// legacy VTK fibre writer and `fibremss fibres`.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>

#include "fibremss/Error.h"
#include "fibremss/FibreGeneration.h"
#include "fibremss/MeshIO.h"
#include "fibremss/Procedural.h"
#include "support/Process.h"

namespace fibremss {
namespace {

// A spindle: an ellipsoid 200 mm long (z), 40 mm thick.
const btVector3 kCentre(0.01f, -0.02f, 0.3f);
const btVector3 kRadii(0.02f, 0.02f, 0.1f);

TriangleMesh spindle() {
  return makeEllipsoid(kCentre, kRadii, 4);
}

btScalar fibreLength(std::span<const btVector3> fibre) {
  btScalar length = 0;
  for (size_t i = 1; i < fibre.size(); ++i) length += fibre[i].distance(fibre[i - 1]);
  return length;
}

/// Every fibre point inside the surface (within `tolerance`), checked independently.
size_t pointsOutside(const FibreSet& fibres, const TriangleMesh& surface, btScalar tolerance) {
  const MeshDistance distance(surface);
  size_t outside = 0;
  for (const auto& p : fibres.points) outside += distance.signedDistance(p) > tolerance;
  return outside;
}

TEST(FibreGeneration, SpindleFromLandmarkToFarEnd) {
  const TriangleMesh surface = spindle();
  const btVector3 tip = kCentre - btVector3(0, 0, kRadii.z());
  const AttachmentArea origin = AttachmentArea::fromLandmarks({tip}, btScalar(0.015));
  FibreGenerationOptions options;  // 64 fibres, 64 samples
  const FibreGenerationResult result = generateFibres(surface, origin, AttachmentArea{}, options);
  const FibreQuality& q = result.quality;
  ASSERT_EQ(result.fibres.fibreCount(), 64u) << (result.warnings.empty() ? "" : result.warnings[0]);
  EXPECT_EQ(q.generated, 64);
  EXPECT_EQ(q.pointsOutside, 0);
  // Inside, checked here with a tolerance of a quarter voxel (the generator's own).
  EXPECT_EQ(pointsOutside(result.fibres, surface, q.voxelSize / 4), 0u);
  int rightEnds = 0;
  for (size_t f = 0; f < result.fibres.fibreCount(); ++f) {
    const auto fibre = result.fibres.fibre(f);
    ASSERT_EQ(fibre.size(), 64u);
    // Starts within the landmark radius (plus a voxel) of the tip; ends at the far (+z) end,
    // the 6 % of the 200 mm length nearest the other tip (plus a voxel).
    const bool start = fibre.front().distance(tip) < 0.015 + q.voxelSize;
    const bool end = fibre.back().z() > kCentre.z() + kRadii.z() - 0.06 * 0.2 - q.voxelSize;
    rightEnds += start && end;
    // No fibre is shorter than the tip-to-tip distance between the two areas.
    EXPECT_GT(fibreLength(fibre), 0.2 - 0.015 - 0.012 - 2 * q.voxelSize);
  }
  EXPECT_GE(rightEnds, int(0.9 * 64));
  EXPECT_GE(q.rightEnds, 0.9);
  // 64 fibres through a 40 mm thick spindle: nearly all of it within 5 mm of a fibre.
  EXPECT_GE(q.coverage, 0.8);
  EXPECT_GT(q.minLength, 0.17);
  EXPECT_LE(q.minLength, q.medianLength);
  EXPECT_LE(q.medianLength, q.maxLength);
  EXPECT_GT(q.interiorVoxels, 1000u);
}

TEST(FibreGeneration, SpindleBetweenTwoBones) {
  const TriangleMesh surface = spindle();
  // Two plates just beyond the tips (1 mm gap), 60 x 60 x 10 mm.
  const TriangleMesh lower = makeBox(kCentre - btVector3(0, 0, kRadii.z() + 0.006f),
                                     btVector3(0.06f, 0.06f, 0.01f), {2, 2, 2});
  const TriangleMesh upper = makeBox(kCentre + btVector3(0, 0, kRadii.z() + 0.006f),
                                     btVector3(0.06f, 0.06f, 0.01f), {2, 2, 2});
  const btScalar distance = 0.01f;
  FibreGenerationOptions options;
  options.count = 32;
  options.samples = 20;
  const FibreGenerationResult result =
      generateFibres(surface, AttachmentArea::fromBone(lower, distance),
                     AttachmentArea::fromBone(upper, distance), options);
  ASSERT_EQ(result.fibres.fibreCount(), 32u);
  const MeshDistance lowerDistance(lower), upperDistance(upper);
  int right = 0;
  for (size_t f = 0; f < result.fibres.fibreCount(); ++f) {
    const auto fibre = result.fibres.fibre(f);
    right += lowerDistance.closest(fibre.front()).distance < distance + 0.002 &&
             upperDistance.closest(fibre.back()).distance < distance + 0.002;
  }
  EXPECT_GE(right, int(0.9 * 32));
  EXPECT_EQ(pointsOutside(result.fibres, surface, result.quality.voxelSize / 4), 0u);
  EXPECT_GE(result.quality.rightEnds, 0.9);
}

TEST(FibreGeneration, RejectsEmptySurfaceAndBadOptions) {
  EXPECT_THROW(generateFibres(TriangleMesh{}, AttachmentArea{}, AttachmentArea{}, {}), InputError);
  FibreGenerationOptions options;
  options.count = 0;
  EXPECT_THROW(generateFibres(spindle(), AttachmentArea{}, AttachmentArea{}, options), InputError);
}

TEST(FibreGeneration, FarLandmarksWidenTheAreaWithAWarning) {
  const AttachmentArea origin =
      AttachmentArea::fromLandmarks({kCentre - btVector3(0, 0, 0.2f)}, btScalar(0.005));
  FibreGenerationOptions options;
  options.count = 8;
  const FibreGenerationResult result = generateFibres(spindle(), origin, AttachmentArea{}, options);
  EXPECT_EQ(result.fibres.fibreCount(), 8u);
  ASSERT_FALSE(result.warnings.empty());
  EXPECT_NE(result.warnings.front().find("landmark"), std::string::npos);
}

TEST(SphereFit, RecoversASphereAndAFemoralHead) {
  const btVector3 centre(0.01f, 0.02f, 0.4f);
  const TriangleMesh ball = makeEllipsoid(centre, btVector3(0.024f, 0.024f, 0.024f), 3);
  btVector3 fitted;
  btScalar radius;
  ASSERT_TRUE(fitSphere(ball.vertices, fitted, radius));
  EXPECT_LT(fitted.distance(centre), 1e-4);
  EXPECT_NEAR(radius, 0.024, 2e-4);  // a subdivided icosahedron's vertices lie on the sphere
  // A "femur": the head on top of a shaft whose top reaches into the head's lower half.
  TriangleMesh femur =
      makeBox(centre - btVector3(0, 0, 0.19f), btVector3(0.03f, 0.03f, 0.37f), {3, 3, 30});
  for (const auto& v : ball.vertices)
    if (v.z() > centre.z() - 0.01) femur.vertices.push_back(v);
  ASSERT_TRUE(fitFemoralHead(femur, btVector3(0, 0, 1), btScalar(0.03), fitted, radius));
  EXPECT_LT(fitted.distance(centre), 1e-3);
  EXPECT_NEAR(radius, 0.024, 1e-3);
}

TEST(FibreWriter, LegacyVtkRoundTrip) {
  FibreSet fibres;
  const btVector3 a[3] = {{0, 0, 0}, {0.001f, 0.002f, 0.003f}, {0.01f, 0, -0.02f}};
  const btVector3 b[2] = {{1, 2, 3}, {4, 5, 6.5f}};
  fibres.addFibre(a);
  fibres.addFibre(b);
  testing::TemporaryDirectory directory("fibremss_fibre_writer");
  const std::string path = (directory.path() / "fibres.vtk").string();
  saveFibresVtk(path, fibres, 0.001);  // metres -> mm in the file
  const FibreSet back = loadFibres(path, 0.001);
  ASSERT_EQ(back.fibreCount(), 2u);
  ASSERT_EQ(back.points.size(), 5u);
  for (size_t i = 0; i < 5; ++i) EXPECT_LT(back.points[i].distance(fibres.points[i]), 1e-6);
  std::ifstream in(path);
  std::string first;
  std::getline(in, first);
  EXPECT_EQ(first, "# vtk DataFile Version 3.0");
}

TEST(FibresCommand, WritesTheRequestedCountReadableByTheLoader) {
  testing::TemporaryDirectory directory("fibremss_fibres_cli");
  // The spindle as an OBJ in millimetres.
  const TriangleMesh surface = spindle();
  const std::string obj = (directory.path() / "spindle.obj").string();
  {
    std::ofstream out(obj);
    for (const auto& v : surface.vertices)
      out << "v " << v.x() * 1000 << ' ' << v.y() * 1000 << ' ' << v.z() * 1000 << '\n';
    for (const auto& t : surface.triangles)
      out << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
  }
  const std::string out = (directory.path() / "fibres.vtk").string();
  const btVector3 tip = (kCentre - btVector3(0, 0, kRadii.z())) * 1000;
  const std::string landmarks = std::to_string(tip.x()) + "," + std::to_string(tip.y()) + "," +
                                std::to_string(tip.z()) + "@15";
  const auto result = testing::runProcess(std::string(FIBREMSS_CLI) + " fibres " + obj +
                                          " --origin '" + landmarks + "' --count 24 --out " + out);
  ASSERT_EQ(result.exitCode, 0) << result.output;
  EXPECT_NE(result.output.find("fibres:        24 of 24"), std::string::npos) << result.output;
  EXPECT_NE(result.output.find("coverage:"), std::string::npos);
  const FibreSet fibres = loadFibres(out, 0.001);
  EXPECT_EQ(fibres.fibreCount(), 24u);
  EXPECT_EQ(pointsOutside(fibres, surface, btScalar(0.002)), 0u);
  // A bad attachment is an error naming the option.
  const auto bad = testing::runProcess(std::string(FIBREMSS_CLI) + " fibres " + obj +
                                       " --origin nonsense --out " + out + " 2>&1");
  EXPECT_EQ(bad.exitCode, 2);
  EXPECT_NE(bad.output.find("--origin"), std::string::npos) << bad.output;
}

}  // namespace
}  // namespace fibremss
