// Fibres generated from a surface (harmonic field + gradient streamlines), the sphere fits, the
// legacy VTK fibre writer and `fibremss fibres`.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>

#include "fibremss/Error.h"
#include "fibremss/FibreGeneration.h"
#include "fibremss/MeshIO.h"
#include "fibremss/Preparation.h"
#include "fibremss/Procedural.h"
#include "fibremss/Scene.h"
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

TEST(FibreGeneration, StripAlongTheSideToTheFarTip) {
  // The origin a strip 4 mm wide along the spindle's +x side over its upper 110 mm (as a psoas'
  // origin runs along the vertebrae), the insertion the lower tip.
  const TriangleMesh surface = spindle();
  std::vector<btVector3> strip;
  for (int k = -2; k <= 9; ++k) {
    const btScalar z = btScalar(0.01 * k);
    const btScalar r = kRadii.x() * std::sqrt(1 - (z / kRadii.z()) * (z / kRadii.z()));
    strip.push_back(kCentre + btVector3(r, 0, z));
  }
  const btVector3 tip = kCentre - btVector3(0, 0, kRadii.z());
  FibreGenerationOptions options;  // 64 fibres
  const FibreGenerationResult result =
      generateFibres(surface, AttachmentArea::fromLandmarks(strip, btScalar(0.004)),
                     AttachmentArea::fromLandmarks({tip}, btScalar(0.012)), options);
  const FibreQuality& q = result.quality;
  EXPECT_EQ(q.generated, 64);
  EXPECT_EQ(q.pointsOutside, 0);
  EXPECT_GE(q.rightEnds, 0.9);
  int onStrip = 0;
  for (size_t f = 0; f < result.fibres.fibreCount(); ++f) {
    const auto fibre = result.fibres.fibre(f);
    btScalar nearest = std::numeric_limits<btScalar>::infinity();
    for (const btVector3& p : strip) nearest = std::min(nearest, fibre.front().distance(p));
    // Landmarks 10 mm apart: a start on the strip lies within half that and the radius.
    onStrip += nearest < 0.005 + 0.004 + q.voxelSize;
    EXPECT_LT(fibre.back().distance(tip), 0.012 + 2 * q.voxelSize);  // in the tip's area
  }
  EXPECT_GE(onStrip, int(0.9 * 64));
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

// Seeds on the origin area follow the field out of a small tip, where the streamlines of
// neighbouring seeds stay close; seeds spread over the widest cross-section and traced both
// ways place the fibres evenly through the belly. A cone-like muscle: a 5 mm landmark at one
// tip of the spindle, the whole far half as the insertion.
TEST(FibreGeneration, SeedsOnTheWidestSectionCoverMoreThanSeedsOnTheOrigin) {
  const TriangleMesh surface = spindle();
  const btVector3 tip = kCentre - btVector3(0, 0, kRadii.z());
  const AttachmentArea origin = AttachmentArea::fromLandmarks({tip}, btScalar(0.005));
  AttachmentArea insertion;
  insertion.endFraction = 0.3;
  FibreGenerationOptions options;
  options.count = 16;
  options.sectionSeeds = false;
  const FibreGenerationResult onOrigin = generateFibres(surface, origin, insertion, options);
  options.sectionSeeds = true;
  const FibreGenerationResult onSection = generateFibres(surface, origin, insertion, options);
  ASSERT_EQ(onOrigin.fibres.fibreCount(), 16u);
  ASSERT_EQ(onSection.fibres.fibreCount(), 16u);
  EXPECT_EQ(pointsOutside(onSection.fibres, surface, onSection.quality.voxelSize / 4), 0u);
  EXPECT_GE(onSection.quality.rightEnds, 0.9);
  EXPECT_GT(onSection.quality.coverage, onOrigin.quality.coverage);
  std::cout << "[coverage] origin seeds " << onOrigin.quality.coverage * 100 << " %, section seeds "
            << onSection.quality.coverage * 100 << " %\n";
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

// The scene format's two ways to attach an origin without a bone (the shared data
// has no pelvis): landmark points in the scene, anchored to a static plate that preparation
// fixes the origin's particles to. A spindle (mm) from a landmark at its top to a plate below.
TEST(FibreGeneration, SceneWithALandmarkOriginOnAnAnchor) {
  testing::TemporaryDirectory directory("fibremss_landmark_scene");
  const std::string path = (directory.path() / "landmarks.json").string();
  std::ofstream(path) << R"({"units": "mm",
    "bones": [{"name": "plate",
               "mesh": {"generator": {"type": "box", "centre": [0, 0, -106], "size": [60, 60, 10]}}}],
    "muscles": [{"name": "spindle",
      "surface": {"generator": {"type": "ellipsoid", "radii": [20, 20, 100]}},
      "fibres": {"generator": {"type": "surface",
                 "origin": {"landmarks": [[0, 0, 100]], "radius": 15, "anchor": true},
                 "insertion": {"bone": "plate", "distance": 5}}},
      "fibre_count": 16, "resolution": 40, "attachment_distance": 12}]})";
  const LoadedScene scene = loadScene(path);
  ASSERT_EQ(scene.bones.size(), 2u);
  EXPECT_EQ(scene.bones[1].name, "spindle-origin-anchor");
  ASSERT_EQ(scene.muscles.size(), 1u);
  const FibreSet& fibres = scene.muscles[0].fibres;
  ASSERT_EQ(fibres.fibreCount(), 16u);
  for (size_t f = 0; f < fibres.fibreCount(); ++f) {
    // From within the landmark's 15 mm to within the plate's 5 mm, each plus the generator's
    // end tolerance (2.5 voxels of 200 / 47 mm).
    EXPECT_LT(fibres.fibre(f).front().distance(btVector3(0, 0, 0.1f)), 0.015f + 0.011f) << f;
    EXPECT_LT(fibres.fibre(f).back().z(), -0.1f + 0.005f + 0.011f) << f;
  }
  // Attachment distance 12 mm: a fibre's last particle lies up to one spacing (5 mm) before
  // its end, which lies up to the area's depth from the plate.
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, 1);
  const MuscleSettings& muscle = *prepared.muscles[0];
  size_t onPlate = 0, onAnchor = 0;
  for (uint32_t i : muscle.fixedParticles) (muscle.fixedBone[i] == 0 ? onPlate : onAnchor) += 1;
  EXPECT_GT(onPlate, 0u);
  EXPECT_GT(onAnchor, 0u);
}

// Explicit attachment areas: surface vertex indices, in the API and in a scene.
TEST(FibreGeneration, VertexIndexAreas) {
  const TriangleMesh surface = spindle();
  std::vector<uint32_t> bottom;
  for (uint32_t v = 0; v < surface.vertices.size(); ++v)
    if (surface.vertices[v].z() < kCentre.z() - 0.09f) bottom.push_back(v);
  ASSERT_GT(bottom.size(), 3u);
  FibreGenerationOptions options;
  options.count = 16;
  const FibreGenerationResult result =
      generateFibres(surface, AttachmentArea::fromVertices(bottom), AttachmentArea{}, options);
  ASSERT_EQ(result.fibres.fibreCount(), 16u);
  EXPECT_EQ(result.originArea, bottom);
  EXPECT_GE(result.quality.rightEnds, 0.9);
  for (size_t f = 0; f < result.fibres.fibreCount(); ++f)
    EXPECT_LT(result.fibres.fibre(f).front().z(), kCentre.z() - 0.09f + 0.011f) << f;
  EXPECT_THROW(generateFibres(surface, AttachmentArea::fromVertices({uint32_t(1) << 30}),
                              AttachmentArea{}, options),
               InputError);

  testing::TemporaryDirectory directory("fibremss_vertex_scene");
  auto write = [&](const std::string& origin) {
    const std::string path = (directory.path() / "vertices.json").string();
    std::ofstream(path) << R"({"muscles": [{"name": "spindle",
      "surface": {"generator": {"type": "ellipsoid", "radii": [0.02, 0.02, 0.1]}},
      "fibres": {"generator": {"type": "surface", "origin": )"
                        << origin << R"(}}, "fibre_count": 8}]})";
    return path;
  };
  // The scene's own ellipsoid (its vertex numbering), its bottom 10 mm as the origin.
  const TriangleMesh sceneSurface = loadScene(write("{}")).muscles[0].surface;
  std::string indices = "{\"anchor\": true, \"vertices\": [";
  for (uint32_t v = 0; v < sceneSurface.vertices.size(); ++v)
    if (sceneSurface.vertices[v].z() < -0.09f)
      indices += (indices.back() == '[' ? "" : ",") + std::to_string(v);
  const LoadedScene scene = loadScene(write(indices + "]}"));
  ASSERT_EQ(scene.bones.size(), 1u);  // the anchor
  EXPECT_EQ(scene.muscles[0].fibres.fibreCount(), 8u);
  try {
    loadScene(write("{\"vertices\": [-1]}"));
    ADD_FAILURE() << "a negative vertex index loaded";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("vertices"), std::string::npos) << e.what();
  }
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

/// Writes `surface` (metres) as an OBJ in millimetres.
std::string writeObj(const std::filesystem::path& path, const TriangleMesh& surface) {
  std::ofstream out(path);
  for (const auto& v : surface.vertices)
    out << "v " << v.x() * 1000 << ' ' << v.y() * 1000 << ' ' << v.z() * 1000 << '\n';
  for (const auto& t : surface.triangles)
    out << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
  return path.string();
}

TEST(FibresCommand, AnUnreachableCountFailsWithExit2AndWritesNoFile) {
  testing::TemporaryDirectory directory("fibremss_fibres_fail");
  const std::string obj = writeObj(directory.path() / "spindle.obj", spindle());
  const std::string out = (directory.path() / "fibres.vtk").string();
  // A grid of 16 voxels holds far fewer seeds than 2000 fibres; the cap keeps it at 16.
  auto run = [&](const std::string& options) {
    return testing::runProcess(std::string(FIBREMSS_CLI) + " fibres " + obj + " " + options +
                               " --out " + out + " 2>&1");
  };
  const auto tooMany = run("--count 2000 --grid 16 --max-grid 16 --samples 8");
  EXPECT_EQ(tooMany.exitCode, 2) << tooMany.output;
  EXPECT_NE(tooMany.output.find("fewer than the 1800 (90 %) required"), std::string::npos)
      << tooMany.output;
  EXPECT_NE(tooMany.output.find("ask for fewer fibres"), std::string::npos) << tooMany.output;
  EXPECT_FALSE(std::filesystem::exists(out));
  // Accepting a smaller share makes the same request succeed (the file then exists).
  const auto accepted = run("--count 2000 --grid 16 --max-grid 16 --samples 8 --min-share 0");
  EXPECT_EQ(accepted.exitCode, 0) << accepted.output;
  EXPECT_TRUE(std::filesystem::exists(out));
  std::filesystem::remove(out);
  // Two separate bodies: no grid connects an area on one to an area on the other.
  TriangleMesh apart = makeEllipsoid(btVector3(0, 0, 0), btVector3(0.01f, 0.01f, 0.02f), 3);
  const TriangleMesh other =
      makeEllipsoid(btVector3(0, 0, 0.1f), btVector3(0.01f, 0.01f, 0.02f), 3);
  const uint32_t base = uint32_t(apart.vertices.size());
  apart.vertices.insert(apart.vertices.end(), other.vertices.begin(), other.vertices.end());
  for (const auto& t : other.triangles)
    apart.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  const std::string twoBodies = writeObj(directory.path() / "apart.obj", apart);
  const auto disconnected = testing::runProcess(
      std::string(FIBREMSS_CLI) + " fibres " + twoBodies +
      " --origin 0,0,-20@5 --insertion 0,0,120@5 --grid 16 --max-grid 36 --out " + out + " 2>&1");
  EXPECT_EQ(disconnected.exitCode, 2) << disconnected.output;
  EXPECT_NE(disconnected.output.find("no interior voxel connects"), std::string::npos)
      << disconnected.output;
  EXPECT_NE(disconnected.output.find("grid 16, 24, 36"), std::string::npos) << disconnected.output;
  EXPECT_FALSE(std::filesystem::exists(out));
}

TEST(FibresCommand, LongLandmarkListsInlineOrFromAFile) {
  testing::TemporaryDirectory directory("fibremss_fibres_landmarks");
  const std::string obj = writeObj(directory.path() / "spindle.obj", spindle());
  const std::string out = (directory.path() / "fibres.vtk").string();
  // 40 landmarks around the lower tip (mm): more than 255 characters inline.
  const btVector3 tip = (kCentre - btVector3(0, 0, kRadii.z())) * 1000;
  std::string inline_list, json = "{\"landmarks\": [";
  for (int i = 0; i < 40; ++i) {
    const double a = 2 * M_PI * i / 40;
    const btVector3 p = tip + btVector3(btScalar(3 * std::cos(a)), btScalar(3 * std::sin(a)), 2);
    const std::string x = std::to_string(p.x()), y = std::to_string(p.y()),
                      z = std::to_string(p.z());
    inline_list += (i ? ";" : "") + x + "," + y + "," + z;
    json += std::string(i ? ", " : "") + "[" + x + ", " + y + ", " + z + "]";
  }
  json += "], \"radius\": 10}";
  ASSERT_GT(inline_list.size(), 255u);
  const std::string file = (directory.path() / "origin.json").string();
  std::ofstream(file) << json;
  for (const std::string& origin : {"'" + inline_list + "@10'", "@" + file}) {
    const auto result = testing::runProcess(std::string(FIBREMSS_CLI) + " fibres " + obj +
                                            " --origin " + origin + " --count 16 --out " + out);
    ASSERT_EQ(result.exitCode, 0) << result.output;
    EXPECT_NE(result.output.find("fibres:        16 of 16"), std::string::npos) << result.output;
    EXPECT_EQ(loadFibres(out, 0.001).fibreCount(), 16u);
    std::filesystem::remove(out);
  }
  // A broken landmark file names the file and the element.
  std::ofstream(file) << "{\"landmarks\": [[1, 2]]}";
  const auto bad = testing::runProcess(std::string(FIBREMSS_CLI) + " fibres " + obj +
                                       " --origin @" + file + " --out " + out + " 2>&1");
  EXPECT_EQ(bad.exitCode, 2);
  EXPECT_NE(bad.output.find("landmarks[0]"), std::string::npos) << bad.output;
  EXPECT_FALSE(std::filesystem::exists(out));
}

// A muscle passing over a bone on its way to its insertion on the same bone (a psoas over the
// femoral head to the lesser trochanter): the bone area keeps its patch at the muscle's end,
// so the fibres end there and not at the first contact.
TEST(FibreGeneration, BoneAreasKeepThePatchAtTheMusclesEnd) {
  const TriangleMesh surface = spindle();  // z from 0.2 to 0.4 m, 20 mm radius
  TriangleMesh bone = makeBox(kCentre + btVector3(0.026f, 0, 0), btVector3(0.01f, 0.03f, 0.03f),
                              {2, 2, 2});  // touches the belly's side
  const TriangleMesh end = makeBox(kCentre + btVector3(0, 0, kRadii.z() + 0.006f),
                                   btVector3(0.06f, 0.06f, 0.01f), {2, 2, 2});  // beyond +z
  const uint32_t base = uint32_t(bone.vertices.size());
  bone.vertices.insert(bone.vertices.end(), end.vertices.begin(), end.vertices.end());
  for (const auto& t : end.triangles)
    bone.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  FibreGenerationOptions options;
  options.count = 24;
  options.samples = 20;
  const FibreGenerationResult result =
      generateFibres(surface, AttachmentArea{}, AttachmentArea::fromBone(bone, 0.01f), options);
  ASSERT_EQ(result.fibres.fibreCount(), 24u);
  bool warned = false;
  for (const auto& w : result.warnings)
    warned |= w.find("passes over the bone") != std::string::npos;
  EXPECT_TRUE(warned);
  // Every insertion vertex lies at the +z end; every fibre ends there (beyond 85 % of the length).
  for (uint32_t v : result.insertionArea) EXPECT_GT(surface.vertices[v].z(), kCentre.z() + 0.07f);
  for (size_t f = 0; f < result.fibres.fibreCount(); ++f)
    EXPECT_GT(result.fibres.fibre(f).back().z(), kCentre.z() + 0.07f) << "fibre " << f;
  EXPECT_GE(result.quality.rightEnds, 0.9);
  EXPECT_LT(result.quality.worstEndGap, result.quality.voxelSize * 2);
}

TEST(FibreGeneration, OverlappingAreasAreNamedAsAnOverlap) {
  const TriangleMesh surface = spindle();
  const AttachmentArea everywhere = AttachmentArea::fromLandmarks({kCentre}, btScalar(1e30));
  const AttachmentArea tip =
      AttachmentArea::fromLandmarks({kCentre - btVector3(0, 0, kRadii.z())}, btScalar(0.005));
  std::vector<uint32_t> origin, insertion;
  std::vector<std::string> warnings;
  for (const AttachmentArea& other : {everywhere, tip}) {
    try {
      resolveAttachmentAreas(surface, other, everywhere, "muscle", origin, insertion, warnings);
      ADD_FAILURE() << "accepted";
    } catch (const InputError& e) {
      EXPECT_NE(e.problem().find("areas overlap"), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace fibremss
