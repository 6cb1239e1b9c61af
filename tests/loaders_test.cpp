// Loaders: legacy VTK (ASCII, big-endian BINARY, 5.1 layout), assimp formats, OBJ and VTK
// fibres, the mesh checks, the real shared meshes, and bad files of every kind.
#include <gtest/gtest.h>
#include <unistd.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>
#include <string>

#include "fibremss/Error.h"
#include "fibremss/Geometry.h"
#include "fibremss/MeshIO.h"

namespace fibremss {
namespace {

const std::string kFixtures = std::string(FIBREMSS_SOURCE_DIR) + "/tests/data/loaders/";
const std::string kShared = std::string(FIBREMSS_SHARED_DATA_DIR) + "/muscle-deformation-pbd/";

std::string fixture(const std::string& name) {
  return kFixtures + name;
}

/// A directory of its own for files the tests write; removed afterwards.
class Scratch {
 public:
  Scratch() {
    const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = std::filesystem::temp_directory_path() /
            ("fibremss_loaders_" + std::to_string(::getpid()) + "_" + test->name());
    std::filesystem::create_directories(path_);
  }
  ~Scratch() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  std::string write(const std::string& name, const std::string& bytes) const {
    const std::string file = (path_ / name).string();
    std::ofstream(file, std::ios::binary) << bytes;
    return file;
  }

 private:
  std::filesystem::path path_;
};

/// Builds the bytes of a binary file, big-endian unless told otherwise.
struct BigEndian {
  std::string bytes;
  bool littleEndian = false;
  BigEndian& text(const std::string& line) {
    bytes += line;
    return *this;
  }
  template <class T>
  BigEndian& value(T number) {
    using Bits = std::conditional_t<sizeof(T) == 8, uint64_t, uint32_t>;
    const auto bits = std::bit_cast<Bits>(number);
    for (int k = 0; k < int(sizeof(T)); ++k) {
      const int shift = 8 * (littleEndian ? k : int(sizeof(T)) - 1 - k);
      bytes += static_cast<char>((bits >> shift) & 0xff);
    }
    return *this;
  }
};

/// Catches the InputError `load` must throw; checks it names `path`; returns its message.
template <class Load>
std::string expectInputError(Load&& load, const std::string& path) {
  try {
    load();
  } catch (const InputError& error) {
    EXPECT_EQ(error.source(), path);
    EXPECT_NE(std::string(error.what()).find(path), std::string::npos) << error.what();
    return error.what();
  } catch (const std::exception& error) {
    ADD_FAILURE() << "expected InputError for " << path << ", got: " << error.what();
    return {};
  }
  ADD_FAILURE() << "expected InputError for " << path << ", nothing was thrown";
  return {};
}

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// The unit cube (corner i at (i&1, i>>1&1, i>>2&1)) as six outward quads.
constexpr uint32_t kCubeQuads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                       {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};

btVector3 cubeCorner(uint32_t i) {
  return btVector3(i & 1, (i >> 1) & 1, (i >> 2) & 1);
}

/// A closed unit cube scaled by `scale`, 8 vertices and 12 outward triangles.
void expectCube(const TriangleMesh& mesh, const MeshReport& report, double scale) {
  EXPECT_EQ(mesh.vertices.size(), 8u);
  EXPECT_EQ(mesh.triangles.size(), 12u);
  EXPECT_TRUE(report.closed()) << report.openEdges << " open, " << report.nonManifoldEdges
                               << " non-manifold";
  EXPECT_EQ(report.inconsistentEdges, 0u);
  EXPECT_EQ(report.degenerateTriangles, 0u);
  EXPECT_FALSE(report.insideOut);
  EXPECT_NEAR(meshVolume(mesh), scale * scale * scale, 1e-6 * scale * scale * scale);
}

/// The cube as a binary legacy VTK file like MAF writes: extra header line, float points,
/// int cells, a trailing CELL_DATA section. `cellsEnd` gets the offset where the cells end.
std::string binaryCube(size_t* cellsEnd = nullptr, bool littleEndian = false) {
  BigEndian file;
  file.littleEndian = littleEndian;
  file.text("# vtk DataFile Version 3.0\n# MAF data file - mafVMEItemVTK output\n\nBINARY\n")
      .text("DATASET POLYDATA\nPOINTS 8 float\n");
  for (uint32_t i = 0; i < 8; ++i) {
    const btVector3 p = cubeCorner(i);
    file.value(float(p.x())).value(float(p.y())).value(float(p.z()));
  }
  file.text("\nPOLYGONS 6 30\n");
  for (const auto& quad : kCubeQuads) {
    file.value(int32_t(4));
    for (const uint32_t v : quad) file.value(int32_t(v));
  }
  if (cellsEnd) *cellsEnd = file.bytes.size();
  file.text("\nCELL_DATA 6\nSCALARS region int 1\nLOOKUP_TABLE default\n");
  for (int32_t i = 0; i < 6; ++i) file.value(i);
  file.text("\n");
  return file.bytes;
}

// ---------------------------------------------------------------------------------------------
// Good surfaces

TEST(LoadersSurface, AsciiVtkQuadsAreFanTriangulatedAndMetadataIsSkipped) {
  MeshReport report;
  const TriangleMesh mesh = loadSurface(fixture("cube_quads.vtk"), 1.0, &report);
  expectCube(mesh, report, 1.0);
  EXPECT_TRUE(report.warnings.empty()) << report.warnings.front();
}

TEST(LoadersSurface, ScaleConvertsFileUnitsToMetres) {
  MeshReport report;
  const TriangleMesh mesh = loadSurface(fixture("cube_quads.vtk"), 0.001, &report);
  expectCube(mesh, report, 0.001);
  EXPECT_FLOAT_EQ(mesh.vertices[7].x(), 0.001f);
}

TEST(LoadersSurface, Vtk51OffsetsLayout) {
  MeshReport report;
  expectCube(loadSurface(fixture("cube_offsets.vtk"), 1.0, &report), report, 1.0);
}

TEST(LoadersSurface, BinaryBigEndianVtkWithMafHeader) {
  Scratch scratch;
  MeshReport report;
  const std::string path = scratch.write("cube.vtk", binaryCube());
  const TriangleMesh mesh = loadSurface(path, 2.0, &report);
  expectCube(mesh, report, 2.0);
  EXPECT_EQ(mesh.vertices[5], btVector3(2, 0, 2));  // corner 5 = (1, 0, 1), scaled
}

TEST(LoadersSurface, BinaryVtk51DoublePointsInt64Offsets) {
  Scratch scratch;
  BigEndian file;
  file.text("# vtk DataFile Version 5.1\nvtk output\nBINARY\nDATASET POLYDATA\n")
      .text("POINTS 8 double\n");
  for (uint32_t i = 0; i < 8; ++i) {
    const btVector3 p = cubeCorner(i);
    file.value(double(p.x())).value(double(p.y())).value(double(p.z()));
  }
  file.text("\nMETADATA\nINFORMATION 0\n\nPOLYGONS 7 24\nOFFSETS vtktypeint64\n");
  for (int64_t i = 0; i <= 6; ++i) file.value(4 * i);
  file.text("\nCONNECTIVITY vtktypeint64\n");
  for (const auto& quad : kCubeQuads) {
    for (const uint32_t v : quad) file.value(int64_t(v));
  }
  file.text("\n");
  MeshReport report;
  expectCube(loadSurface(scratch.write("cube51.vtk", file.bytes), 1.0, &report), report, 1.0);
}

TEST(LoadersSurface, TriangleStripAlternatesWindingSoTheTetrahedronIsConsistent) {
  MeshReport report;
  const TriangleMesh mesh = loadSurface(fixture("tetra_strip.vtk"), 1.0, &report);
  ASSERT_EQ(mesh.triangles.size(), 4u);  // a strip of 6 points holds 6 - 2 triangles
  // Strip 0 1 2 3 0 1: every odd triangle swaps its first two points.
  const std::vector<std::array<uint32_t, 3>> expected = {
      {0, 1, 2}, {2, 1, 3}, {2, 3, 0}, {0, 3, 1}};
  EXPECT_EQ(mesh.triangles, expected);
  EXPECT_TRUE(report.closed());
  EXPECT_EQ(report.inconsistentEdges, 0u);
  EXPECT_NEAR(meshVolume(mesh), 1.0 / 6.0, 1e-6);
}

TEST(LoadersSurface, ObjThroughAssimp) {
  MeshReport report;
  expectCube(loadSurface(fixture("cube.obj"), 1.0, &report), report, 1.0);
}

TEST(LoadersSurface, StlThroughAssimpJoinsTheCornersOfSeparateFacets) {
  MeshReport report;
  expectCube(loadSurface(fixture("cube.stl"), 1.0, &report), report, 1.0);
}

TEST(LoadersSurface, PlyThroughAssimp) {
  MeshReport report;
  expectCube(loadSurface(fixture("cube.ply"), 1.0, &report), report, 1.0);
}

TEST(LoadersSurface, BinaryStlThroughAssimpJoinsTheCornersOfSeparateFacets) {
  Scratch scratch;
  BigEndian file;
  file.littleEndian = true;  // binary STL is little-endian
  file.text(std::string(80, ' ')).value(uint32_t(12));
  for (const auto& q : kCubeQuads) {
    for (const auto& triangle : {std::array{q[0], q[1], q[2]}, std::array{q[0], q[2], q[3]}}) {
      file.value(0.0f).value(0.0f).value(0.0f);  // normal: assimp recomputes what it needs
      for (const uint32_t corner : triangle) {
        const btVector3 p = cubeCorner(corner);
        file.value(float(p.x())).value(float(p.y())).value(float(p.z()));
      }
      file.bytes += std::string(2, '\0');  // attribute byte count
    }
  }
  MeshReport report;
  expectCube(loadSurface(scratch.write("cube.stl", file.bytes), 1.0, &report), report, 1.0);
}

/// Standard base64 with padding (for a glTF data URI).
std::string base64(const std::string& bytes) {
  constexpr char kDigits[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string text;
  for (size_t i = 0; i < bytes.size(); i += 3) {
    const size_t n = std::min<size_t>(3, bytes.size() - i);
    uint32_t group = 0;
    for (size_t k = 0; k < 3; ++k) {
      group = (group << 8) | (k < n ? static_cast<unsigned char>(bytes[i + k]) : 0u);
    }
    for (size_t k = 0; k < 4; ++k) text += k <= n ? kDigits[(group >> (18 - 6 * k)) & 63] : '=';
  }
  return text;
}

TEST(LoadersSurface, GltfMeshesOfAllNodesAreMergedInPlace) {
  // One cube mesh used by two nodes, the second moved by 3 along x.
  BigEndian buffer;
  buffer.littleEndian = true;  // glTF buffers are little-endian
  for (uint32_t i = 0; i < 8; ++i) {
    const btVector3 p = cubeCorner(i);
    buffer.value(float(p.x())).value(float(p.y())).value(float(p.z()));
  }
  for (const auto& q : kCubeQuads) {
    for (const uint32_t v : {q[0], q[1], q[2], q[0], q[2], q[3]}) {
      buffer.bytes += static_cast<char>(v);
      buffer.bytes += '\0';  // uint16 indices
    }
  }
  ASSERT_EQ(buffer.bytes.size(), 96u + 72u);
  const std::string gltf = R"({"asset": {"version": "2.0"}, "scene": 0,
    "scenes": [{"nodes": [0, 1]}],
    "nodes": [{"mesh": 0}, {"mesh": 0, "translation": [3, 0, 0]}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
    "buffers": [{"byteLength": 168, "uri": "data:application/octet-stream;base64,)" +
                           base64(buffer.bytes) + R"("}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 96},
                    {"buffer": 0, "byteOffset": 96, "byteLength": 72}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3",
                   "min": [0, 0, 0], "max": [1, 1, 1]},
                  {"bufferView": 1, "componentType": 5123, "count": 36, "type": "SCALAR"}]})";
  Scratch scratch;
  MeshReport report;
  const TriangleMesh mesh = loadSurface(scratch.write("cubes.gltf", gltf), 1.0, &report);
  EXPECT_EQ(mesh.vertices.size(), 16u);
  EXPECT_EQ(mesh.triangles.size(), 24u);
  EXPECT_TRUE(report.closed());
  EXPECT_EQ(report.inconsistentEdges, 0u);
  EXPECT_NEAR(meshVolume(mesh), 2.0, 1e-5);
  btVector3 lower, upper;
  pointBounds(mesh.vertices, lower, upper);
  EXPECT_FLOAT_EQ(lower.x(), 0.0f);
  EXPECT_FLOAT_EQ(upper.x(), 4.0f);
}

TEST(LoadersSurface, DatasetFieldBeforeThePointsIsSkipped) {
  Scratch scratch;
  std::ifstream in(fixture("cube_quads.vtk"));
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t points = text.find("POINTS");
  text.insert(points, "FIELD FieldData 2\nTIME 1 1 double\n0.5\nNAMES 2 3 int\n1 2 3\n4 5 6\n");
  MeshReport report;
  expectCube(loadSurface(scratch.write("field.vtk", text), 1.0, &report), report, 1.0);
}

TEST(LoadersSurface, AsciiNumbersAreReadAsStrtodWouldAndOverflowIsAnError) {
  Scratch scratch;
  const std::string head =
      "# vtk DataFile Version 3.0\nnumbers\nascii\nDATASET POLYDATA\nPOINTS 3 FLOAT\n";
  const std::string cells = "\npolygons 1 4\n3 0 1 2\n";
  MeshReport report;
  const TriangleMesh mesh = loadSurface(
      scratch.write("numbers.vtk", head + "+0 1e-400 -0.0\n+1.5E+00 0 0\n.5 2. 0" + cells), 1.0,
      &report);
  ASSERT_EQ(mesh.vertices.size(), 3u);
  EXPECT_EQ(mesh.vertices[0], btVector3(0, 0, 0));  // 1e-400 underflows to 0
  EXPECT_EQ(mesh.vertices[1], btVector3(1.5f, 0, 0));
  EXPECT_EQ(mesh.vertices[2], btVector3(0.5f, 2, 0));
  const std::string huge = scratch.write("huge.vtk", head + "0 0 0 1e400 0 0 0 1 0" + cells);
  EXPECT_TRUE(contains(expectInputError([&] { loadSurface(huge); }, huge), "finite"));
  if (std::numeric_limits<btScalar>::max() < 1e39) {  // float btScalar: 1e39 does not fit
    const std::string overflow =
        scratch.write("overflow.vtk", head + "0 0 0 1e39 0 0 0 1 0" + cells);
    EXPECT_TRUE(contains(expectInputError([&] { loadSurface(overflow); }, overflow), "point 1"));
  }
}

TEST(LoadersSurface, VtkContentIsRecognisedUnderAnotherExtension) {
  Scratch scratch;
  std::ifstream in(fixture("cube_quads.vtk"));
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  MeshReport report;
  expectCube(loadSurface(scratch.write("cube.txt", text), 1.0, &report), report, 1.0);
}

// ---------------------------------------------------------------------------------------------
// Surface checks

TEST(LoadersCheckSurface, InvertedCubeIsFlippedWithAWarning) {
  MeshReport report;
  const std::string path = fixture("cube_inverted.vtk");
  const TriangleMesh mesh = loadSurface(path, 1.0, &report);
  EXPECT_TRUE(report.insideOut);
  EXPECT_EQ(report.reorientedTriangles, 12u);
  EXPECT_NEAR(meshVolume(mesh), 1.0, 1e-6);  // flipped back outward
  ASSERT_FALSE(report.warnings.empty());
  EXPECT_TRUE(contains(report.warnings.front(), path));
  EXPECT_TRUE(contains(report.warnings.front(), "negative volume"));
}

TEST(LoadersCheckSurface, TrianglesTurnedOverAreReorientedByTheMajority) {
  Scratch scratch;
  std::ifstream in(fixture("cube_quads.vtk"));
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string quad = "4 0 2 3 1", reversed = "4 1 3 2 0";  // the bottom face turned over
  ASSERT_NE(text.find(quad), std::string::npos);
  text.replace(text.find(quad), quad.size(), reversed);
  const std::string path = scratch.write("turned.vtk", text);
  MeshReport report;
  const TriangleMesh mesh = loadSurface(path, 1.0, &report);
  EXPECT_EQ(report.inconsistentEdges, 4u);  // the border of the turned face, as read
  EXPECT_EQ(report.reorientedTriangles, 2u);
  const MeshReport after = checkSurface(mesh, path);
  EXPECT_EQ(after.inconsistentEdges, 0u);
  EXPECT_FALSE(after.insideOut);
  EXPECT_NEAR(meshVolume(mesh), 1.0, 1e-6);
}

// A unit cube cracked as exported meshes are: its top face uses a copy of corner 7 that lies
// 0.4 mm (at metre scale) away, and one triangle of its bottom face is missing.
TEST(LoadersCheckSurface, RepairWeldsACrackAndClosesASmallHole) {
  Scratch scratch;
  const std::string path = scratch.write(
      "cracked.vtk",
      "# vtk DataFile Version 4.2\ncracked cube\nASCII\nDATASET POLYDATA\nPOINTS 9 float\n"
      "0 0 0\n1 0 0\n0 1 0\n1 1 0\n0 0 1\n1 0 1\n0 1 1\n1 1 1\n1 1 1.0004\n"
      "POLYGONS 11 44\n3 0 2 3\n3 4 5 8\n3 4 8 6\n3 0 1 5\n3 0 5 4\n3 2 6 7\n3 2 7 3\n"
      "3 0 4 6\n3 0 6 2\n3 1 3 7\n3 1 7 5\n");
  MeshReport asRead;
  loadSurface(path, 1.0, &asRead);
  EXPECT_EQ(asRead.openEdges, 7u);  // the crack's four edges and the hole's three
  MeshReport report;
  const TriangleMesh mesh = loadSurface(path, 1.0, &report, SurfaceRepair{0.001, 3});
  EXPECT_EQ(report.weldedVertices, 1u);
  EXPECT_EQ(report.filledHoles, 1u);
  EXPECT_TRUE(report.closed());
  EXPECT_TRUE(report.warnings.empty()) << report.warnings.front();
  EXPECT_EQ(mesh.vertices.size(), 8u);
  EXPECT_EQ(mesh.triangles.size(), 12u);
  EXPECT_NEAR(meshVolume(mesh), 1.0, 1e-6);
  // A weld shorter than the crack leaves it open (the hole of three edges is still closed).
  MeshReport tooShort;
  loadSurface(path, 1.0, &tooShort, SurfaceRepair{0.0001, 3});
  EXPECT_EQ(tooShort.weldedVertices, 0u);
  EXPECT_EQ(tooShort.openEdges, 4u);
}

TEST(LoadersCheckSurface, MoebiusStripCannotBeOrientedAndIsLeftAsRead) {
  // A strip of 8 quads around a ring with a half twist: non-orientable.
  TriangleMesh strip;
  constexpr int kSegments = 8;
  for (int i = 0; i < kSegments; ++i) {
    const double angle = 2 * M_PI * i / kSegments, twist = angle / 2;
    const btVector3 centre(std::cos(angle), std::sin(angle), 0);
    const btVector3 across = btVector3(std::cos(angle) * std::cos(twist),
                                       std::sin(angle) * std::cos(twist), std::sin(twist)) *
                             0.2f;
    strip.vertices.push_back(centre - across);
    strip.vertices.push_back(centre + across);
  }
  for (uint32_t i = 0; i < kSegments; ++i) {
    const uint32_t a = 2 * i, b = 2 * i + 1;
    // The last quad joins the first edge reversed: that is the half twist.
    const uint32_t c = i + 1 < kSegments ? 2 * i + 2 : 1, d = i + 1 < kSegments ? 2 * i + 3 : 0;
    strip.triangles.push_back({a, c, b});
    strip.triangles.push_back({b, c, d});
  }
  const MeshReport before = checkSurface(strip, "moebius");
  EXPECT_EQ(before.nonManifoldEdges, 0u);
  EXPECT_GT(before.inconsistentEdges, 0u);
  Scratch scratch;
  BigEndian file;
  file.text("# vtk DataFile Version 3.0\nmoebius\nBINARY\nDATASET POLYDATA\n")
      .text("POINTS " + std::to_string(strip.vertices.size()) + " float\n");
  for (const btVector3& v : strip.vertices)
    file.value(float(v.x())).value(float(v.y())).value(float(v.z()));
  file.text("\nPOLYGONS " + std::to_string(strip.triangles.size()) + " " +
            std::to_string(4 * strip.triangles.size()) + "\n");
  for (const auto& t : strip.triangles) {
    file.value(int32_t(3));
    for (const uint32_t v : t) file.value(int32_t(v));
  }
  MeshReport report;
  const TriangleMesh loaded = loadSurface(scratch.write("moebius.vtk", file.bytes), 1.0, &report);
  EXPECT_EQ(report.reorientedTriangles, 0u);
  EXPECT_EQ(loaded.triangles, strip.triangles);
  EXPECT_TRUE(contains(report.warnings.back(), "cannot be oriented")) << report.warnings.back();
}

TEST(LoadersCheckSurface, OpenCubeCountsItsFourBorderEdges) {
  MeshReport report;
  const std::string path = fixture("cube_open.vtk");
  const TriangleMesh mesh = loadSurface(path, 1.0, &report);
  EXPECT_EQ(mesh.triangles.size(), 10u);
  EXPECT_EQ(report.openEdges, 4u);
  EXPECT_FALSE(report.closed());
  EXPECT_FALSE(report.insideOut);  // the sign of an open surface's volume means nothing
  ASSERT_EQ(report.warnings.size(), 1u);
  EXPECT_TRUE(contains(report.warnings.front(), "4 open edges"));
}

TEST(LoadersCheckSurface, DegenerateDuplicateNonManifoldAndInconsistentTrianglesAreCounted) {
  TriangleMesh mesh;
  for (uint32_t i = 0; i < 8; ++i) mesh.vertices.push_back(cubeCorner(i));
  mesh.vertices.emplace_back(2, 0, 0);  // 8: on the line through 0 and 1
  mesh.vertices.emplace_back(5, 5, 5);  // 9: used by no triangle
  for (const auto& q : kCubeQuads) {
    mesh.triangles.push_back({q[0], q[1], q[2]});
    mesh.triangles.push_back({q[0], q[2], q[3]});
  }
  const size_t cubeTriangles = mesh.triangles.size();
  mesh.triangles.push_back({0, 1, 8});          // zero area (collinear)
  mesh.triangles.push_back({3, 3, 5});          // repeated vertex
  mesh.triangles.push_back(mesh.triangles[0]);  // duplicate: its edges now have 3 users
  MeshReport report = checkSurface(mesh, "made-up");
  EXPECT_EQ(report.degenerateTriangles, 2u);
  EXPECT_EQ(report.duplicateTriangles, 1u);
  // The duplicate's three edges and 0-1, which the collinear triangle shares with the cube.
  EXPECT_EQ(report.nonManifoldEdges, 4u);
  EXPECT_EQ(report.unusedVertices, 1u);
  EXPECT_EQ(report.openEdges, 2u);  // 1-8 and 8-0 of the collinear triangle
  EXPECT_FALSE(report.insideOut);

  mesh.triangles.resize(cubeTriangles);
  std::swap(mesh.triangles[0][1], mesh.triangles[0][2]);  // one triangle turned over
  report = checkSurface(mesh, "made-up");
  EXPECT_EQ(report.inconsistentEdges, 3u);
  EXPECT_EQ(report.openEdges, 0u);
  EXPECT_FALSE(report.insideOut);
}

TEST(LoadersCheckSurface, FatalDefectsThrowNamingTheElement) {
  TriangleMesh mesh;
  for (uint32_t i = 0; i < 3; ++i) mesh.vertices.push_back(cubeCorner(i));
  EXPECT_TRUE(contains(expectInputError([&] { checkSurface(mesh, "mesh.x"); }, "mesh.x"),
                       "at least one triangle"));
  mesh.triangles.push_back({0, 1, 3});
  EXPECT_TRUE(
      contains(expectInputError([&] { checkSurface(mesh, "mesh.x"); }, "mesh.x"), "triangle 0"));
  mesh.triangles.back() = {0, 1, 2};
  mesh.vertices[1].setY(std::numeric_limits<btScalar>::infinity());
  EXPECT_TRUE(
      contains(expectInputError([&] { checkSurface(mesh, "mesh.x"); }, "mesh.x"), "vertex 1"));
}

// ---------------------------------------------------------------------------------------------
// Fibres

TEST(LoadersFibres, ObjPolylinesAndChainedSegments) {
  const FibreSet fibres = loadFibres(fixture("fibres.obj"), 1.0);
  ASSERT_EQ(fibres.fibreCount(), 2u);
  ASSERT_EQ(fibres.fibre(0).size(), 4u);
  ASSERT_EQ(fibres.fibre(1).size(), 4u);
  EXPECT_EQ(fibres.fibre(0)[3], btVector3(btScalar(0.9), btScalar(0.5), btScalar(0.5)));
  // The second fibre came as segments 5-6, 6-7 (relative -3 -2) and 7-8 (with texture refs).
  for (size_t p = 0; p < 4; ++p) {
    EXPECT_FLOAT_EQ(fibres.fibre(1)[p].y(), 0.2f);
    if (p > 0) {
      EXPECT_GT(fibres.fibre(1)[p].x(), fibres.fibre(1)[p - 1].x());
    }
  }
}

TEST(LoadersFibres, VtkSegmentsAreChainedIntoPolylines) {
  const FibreSet fibres = loadFibres(fixture("fibre_segments.vtk"), 0.01);
  ASSERT_EQ(fibres.fibreCount(), 3u);
  for (size_t f = 0; f < 3; ++f) {
    ASSERT_EQ(fibres.fibre(f).size(), 3u);
    EXPECT_FLOAT_EQ(fibres.fibre(f)[0].x(), 0.001f);
    EXPECT_FLOAT_EQ(fibres.fibre(f)[2].x(), 0.009f);
  }
}

TEST(LoadersFibres, BinaryVtkDoublePointsAndSegments) {
  Scratch scratch;
  BigEndian file;
  file.text("# vtk DataFile Version 3.0\nfibres\nBINARY\nDATASET POLYDATA\nPOINTS 6 double\n");
  for (int i = 0; i < 6; ++i) file.value(double(i % 3)).value(double(i / 3)).value(0.5);
  // Two fibres 0-1-2 and 3-4-5 as segments, then CELL_DATA.
  file.text("\nLINES 4 12\n");
  for (const int32_t start : {0, 1, 3, 4}) file.value(int32_t(2)).value(start).value(start + 1);
  file.text("\nCELL_DATA 4\n");
  const FibreSet fibres = loadFibres(scratch.write("fibres.vtk", file.bytes), 1.0);
  ASSERT_EQ(fibres.fibreCount(), 2u);
  EXPECT_EQ(fibres.fibre(0).size(), 3u);
  EXPECT_EQ(fibres.fibre(1).size(), 3u);
  EXPECT_EQ(fibres.fibre(1)[2], btVector3(2, 1, 0.5));
}

TEST(LoadersCheckFibres, FibreLeavingTheMuscleIsAWarningNamingIt) {
  MeshReport report;
  const TriangleMesh cube = loadSurface(fixture("cube_quads.vtk"), 1.0, &report);
  FibreSet fibres = loadFibres(fixture("fibres.obj"), 1.0);
  EXPECT_TRUE(checkFibres(fibres, cube, "fibres.obj", 1e-3).empty());
  const std::vector<btVector3> outside = {{0.5f, 0.5f, 0.5f}, {1.5f, 0.5f, 0.5f}};
  fibres.addFibre(outside);
  const auto warnings = checkFibres(fibres, cube, "fibres.obj", 1e-3);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_TRUE(contains(warnings.front(), "fibre 2")) << warnings.front();
  EXPECT_TRUE(contains(warnings.front(), "1 of 2 points")) << warnings.front();
}

TEST(LoadersCheckFibres, EmptyAndNonFiniteFibresThrow) {
  MeshReport report;
  const TriangleMesh cube = loadSurface(fixture("cube_quads.vtk"), 1.0, &report);
  FibreSet fibres;
  expectInputError([&] { checkFibres(fibres, cube, "f", 0); }, "f");
  fibres.offsets.push_back(0);  // an empty fibre
  EXPECT_TRUE(
      contains(expectInputError([&] { checkFibres(fibres, cube, "f", 0); }, "f"), "fibre 0"));
  FibreSet nan;
  const std::vector<btVector3> points = {{0, 0, 0}, {0, std::nanf(""), 0}};
  nan.addFibre(points);
  EXPECT_TRUE(
      contains(expectInputError([&] { checkFibres(nan, cube, "f", 0); }, "f"), "fibre 0, point 1"));
}

// ---------------------------------------------------------------------------------------------
// Real meshes from ../shared/data

class LoadersSharedData : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!std::filesystem::exists(kShared + "README.md")) {
      GTEST_SKIP() << "shared data not found at " << kShared
                   << " (FIBREMSS_SHARED_DATA_DIR); the real-mesh tests need it";
    }
  }
};

TEST_F(LoadersSharedData, BinaryFemurHasTheDocumentedCountsAndIsClosed) {
  MeshReport report;
  const TriangleMesh bone = loadSurface(kShared + "bone1_s1.vtk", 0.001, &report);
  EXPECT_EQ(bone.vertices.size(), 21230u);
  EXPECT_EQ(bone.triangles.size(), 42456u);
  EXPECT_EQ(report.openEdges, 0u);
  EXPECT_EQ(report.nonManifoldEdges, 0u);
  EXPECT_EQ(checkSurface(bone, "bone").inconsistentEdges, 0u);  // the file has a few turned
  EXPECT_GT(meshVolume(bone), 0);
  btVector3 lower, upper;
  pointBounds(bone.vertices, lower, upper);
  // README bounds in mm: x 79..167, z -855..-410.
  EXPECT_NEAR(lower.x(), 0.079, 0.001);
  EXPECT_NEAR(upper.x(), 0.167, 0.001);
  EXPECT_NEAR(lower.z(), -0.855, 0.001);
  EXPECT_NEAR(upper.z(), -0.410, 0.001);
}

TEST_F(LoadersSharedData, AsciiMuscleWithMetadataHasTheDocumentedCountsAndIsClosed) {
  MeshReport report;
  const TriangleMesh muscle = loadSurface(kShared + "muscle3_s1.vtk", 0.001, &report);
  EXPECT_EQ(muscle.vertices.size(), 8564u);
  EXPECT_EQ(muscle.triangles.size(), 17124u);
  EXPECT_EQ(report.openEdges, 0u);
  EXPECT_EQ(report.nonManifoldEdges, 0u);
  EXPECT_GT(meshVolume(muscle), 0);
}

TEST_F(LoadersSharedData, EverySurfaceIsClosedWithTheDocumentedCounts) {
  struct Expected {
    const char* file;
    size_t points, triangles;
  };
  for (const Expected& e : {Expected{"muscle0_s1.vtk", 9878, 19752},
                            {"muscle1_s1.vtk", 5313, 10622},
                            {"muscle2_s1.vtk", 6931, 13858},
                            {"muscle0_s2.vtk", 2648, 5292},
                            {"bone0_s2.vtk", 8, 12},
                            {"bone1_s2.vtk", 8, 12},
                            {"rod.vtk", 5768, 11532},
                            {"block.vtk", 26, 48},
                            {"tetra.vtk", 4, 4}}) {
    SCOPED_TRACE(e.file);
    MeshReport report;
    const TriangleMesh mesh = loadSurface(kShared + e.file, 0.001, &report);
    EXPECT_EQ(mesh.vertices.size(), e.points);
    EXPECT_EQ(mesh.triangles.size(), e.triangles);
    EXPECT_TRUE(report.closed());
    // Outward and consistent after loading, whatever the file had (some have turned triangles).
    const MeshReport after = checkSurface(mesh, e.file);
    EXPECT_EQ(after.inconsistentEdges, 0u);
    EXPECT_FALSE(after.insideOut);
    EXPECT_GT(meshVolume(mesh), 0);
  }
}

TEST_F(LoadersSharedData, FibreSegmentsChainIntoFiveFibresOfSixPoints) {
  const FibreSet fibres = loadFibres(kShared + "fibre0_s1.vtk", 0.001);
  ASSERT_EQ(fibres.fibreCount(), 5u);
  for (size_t f = 0; f < 5; ++f) EXPECT_EQ(fibres.fibre(f).size(), 6u);
  MeshReport report;
  const TriangleMesh muscle = loadSurface(kShared + "muscle0_s1.vtk", 0.001, &report);
  const auto warnings = checkFibres(fibres, muscle, kShared + "fibre0_s1.vtk", 0.001);
  for (const std::string& warning : warnings) std::cout << "[ note ] " << warning << "\n";
}

TEST_F(LoadersSharedData, TruncatedRealBinaryFileIsAnInputError) {
  Scratch scratch;
  std::ifstream in(kShared + "bone1_s1.vtk", std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (const size_t length :
       {size_t(120), bytes.size() / 4, bytes.size() / 2, size_t(934190 - 3)}) {
    const std::string path = scratch.write("bone.vtk", bytes.substr(0, length));
    expectInputError([&] { loadSurface(path); }, path);
  }
}

// ---------------------------------------------------------------------------------------------
// Bad files: every one an InputError naming the file, none a crash

TEST(LoadersBadInput, EmptyFilesForEveryLoader) {
  for (const char* name : {"empty.vtk", "empty.obj", "empty.stl"}) {
    const std::string path = fixture(name);
    EXPECT_TRUE(contains(expectInputError([&] { loadSurface(path); }, path), "empty"));
    expectInputError([&] { loadFibres(path); }, path);
  }
}

TEST(LoadersBadInput, MissingFile) {
  const std::string path = fixture("no_such_file.vtk");
  EXPECT_TRUE(contains(expectInputError([&] { loadSurface(path); }, path), "does not exist"));
  expectInputError([&] { loadFibres(path); }, path);
}

TEST(LoadersBadInput, NanCoordinateNamesTheLineAndPoint) {
  const std::string path = fixture("nan_coordinate.vtk");
  const std::string message = expectInputError([&] { loadSurface(path); }, path);
  EXPECT_TRUE(contains(message, "line 7")) << message;
  EXPECT_TRUE(contains(message, "point 1")) << message;
}

TEST(LoadersBadInput, IndexOutOfRangeNamesTheLineAndCell) {
  const std::string path = fixture("index_out_of_range.vtk");
  const std::string message = expectInputError([&] { loadSurface(path); }, path);
  EXPECT_TRUE(contains(message, "line 10")) << message;
  EXPECT_TRUE(contains(message, "POLYGONS cell 0")) << message;
}

TEST(LoadersBadInput, HugeCountsAreRejectedBeforeAllocating) {
  const std::string points = fixture("huge_point_count.vtk");
  EXPECT_TRUE(contains(expectInputError([&] { loadSurface(points); }, points), "1000000000000"));
  const std::string cells = fixture("huge_cell_count.vtk");
  EXPECT_TRUE(contains(expectInputError([&] { loadSurface(cells); }, cells), "bytes are left"));
  Scratch scratch;
  BigEndian file;
  file.text("# vtk DataFile Version 3.0\nhuge\nBINARY\nDATASET POLYDATA\n")
      .text("POINTS 4000000000 double\n")
      .value(0.0);
  const std::string path = scratch.write("huge.vtk", file.bytes);
  const std::string message = expectInputError([&] { loadSurface(path); }, path);
  EXPECT_TRUE(contains(message, "byte offset")) << message;
  EXPECT_TRUE(contains(message, "bytes are left")) << message;
}

TEST(LoadersBadInput, LittleEndianBinaryVtkIsRejectedWithAHint) {
  Scratch scratch;
  const std::string path = scratch.write("little.vtk", binaryCube(nullptr, true));
  const std::string message = expectInputError([&] { loadSurface(path); }, path);
  EXPECT_TRUE(contains(message, "POLYGONS cell 0")) << message;
  EXPECT_TRUE(contains(message, "must be big-endian")) << message;
}

TEST(LoadersBadInput, NanInABinaryFileNamesTheByteOffset) {
  Scratch scratch;
  BigEndian file;
  file.text("# vtk DataFile Version 3.0\nnan\nBINARY\nDATASET POLYDATA\nPOINTS 3 float\n");
  const size_t start = file.bytes.size();
  file.value(0.0f).value(0.0f).value(0.0f).value(1.0f).value(0.0f);
  file.value(std::numeric_limits<float>::quiet_NaN()).value(0.0f).value(1.0f).value(0.0f);
  file.text("\nPOLYGONS 1 4\n").value(int32_t(3)).value(int32_t(0)).value(int32_t(1));
  file.value(int32_t(2));
  const std::string path = scratch.write("nan.vtk", file.bytes);
  const std::string message = expectInputError([&] { loadSurface(path); }, path);
  // The last coordinate of point 1 (the NaN) starts 5 floats into the point data.
  EXPECT_TRUE(contains(message, "byte offset " + std::to_string(start + 5 * 4))) << message;
  EXPECT_TRUE(contains(message, "point 1")) << message;
}

TEST(LoadersBadInput, EveryTruncationOfABinaryFileIsAnInputError) {
  Scratch scratch;
  size_t cellsEnd = 0;
  const std::string bytes = binaryCube(&cellsEnd);
  for (size_t length = 0; length < cellsEnd; ++length) {
    SCOPED_TRACE(length);
    const std::string path = scratch.write("cut.vtk", bytes.substr(0, length));
    expectInputError([&] { loadSurface(path); }, path);
  }
}

TEST(LoadersBadInput, EveryTruncationOfAnAsciiFileFailsCleanly) {
  Scratch scratch;
  std::ifstream in(fixture("cube_quads.vtk"));
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t cellsEnd = text.find("VERTICES");
  for (size_t length = 0; length + 2 < cellsEnd; ++length) {
    SCOPED_TRACE(length);
    const std::string path = scratch.write("cut.vtk", text.substr(0, length));
    expectInputError([&] { loadSurface(path); }, path);
  }
}

TEST(LoadersBadInput, BinaryGarbageInEveryFormat) {
  Scratch scratch;
  std::mt19937 random(12345);
  for (int round = 0; round < 20; ++round) {
    std::string garbage(64 + random() % 2000, '\0');
    for (char& c : garbage) c = static_cast<char>(random() & 0xff);
    for (const char* extension : {".vtk", ".obj", ".stl", ".ply", ".gltf"}) {
      SCOPED_TRACE(std::string(extension) + " round " + std::to_string(round));
      const std::string path = scratch.write(std::string("garbage") + extension, garbage);
      expectInputError([&] { loadSurface(path); }, path);
      if (std::string(extension) == ".vtk" || std::string(extension) == ".obj") {
        expectInputError([&] { loadFibres(path); }, path);
      }
    }
    // A valid header followed by garbage exercises the binary section reader.
    const std::string path =
        scratch.write("header.vtk",
                      "# vtk DataFile Version 3.0\ngarbage\nBINARY\nDATASET POLYDATA\nPOINTS 40 "
                      "float\n" +
                          garbage);
    try {
      loadSurface(path);  // garbage may happen to decode; it must never crash
    } catch (const InputError& error) {
      EXPECT_EQ(error.source(), path);
    }
  }
}

TEST(LoadersBadInput, WrongFormats) {
  Scratch scratch;
  const std::string png = std::string("\x89PNG\r\n\x1a\n\0\0\0\rIHDR", 16) + std::string(64, '\0');
  for (const char* name : {"image.png", "image.vtk", "image.obj", "image.stl"}) {
    const std::string path = scratch.write(name, png);
    expectInputError([&] { loadSurface(path); }, path);
    expectInputError([&] { loadFibres(path); }, path);
  }
  const std::string json = fixture("not_a_mesh.json");
  expectInputError([&] { loadSurface(json); }, json);
  expectInputError([&] { loadFibres(json); }, json);
  const std::string grid = fixture("unstructured_grid.vtk");
  EXPECT_TRUE(contains(expectInputError([&] { loadSurface(grid); }, grid), "UNSTRUCTURED_GRID"));
}

TEST(LoadersBadInput, SurfaceFromAFibreFileAndFibresFromASurfaceFile) {
  const std::string lines = fixture("fibre_segments.vtk");
  EXPECT_TRUE(contains(expectInputError([&] { loadSurface(lines); }, lines), "no triangles"));
  const std::string surface = fixture("cube_quads.vtk");
  EXPECT_TRUE(contains(expectInputError([&] { loadFibres(surface); }, surface), "LINES"));
  const std::string objSurface = fixture("cube.obj");
  EXPECT_TRUE(contains(expectInputError([&] { loadFibres(objSurface); }, objSurface), "`l`"));
}

TEST(LoadersBadInput, AnUnknownFibreExtensionIsRefusedListingEveryFibreFormat) {
  Scratch scratch;
  const std::string path = scratch.write("fibres.xyz", "0 0 0\n1 0 0\n");
  const std::string message = expectInputError([&] { loadFibres(path); }, path);
  for (const char* named :
       {"legacy VTK (.vtk, LINES)", "VTK XML (.vtp, Lines)", "OBJ (.obj, `l` polylines)", "'.xyz'"})
    EXPECT_TRUE(contains(message, named)) << message;
}

TEST(LoadersFibres, VtkContentIsRecognisedUnderTheExtensionOfAFormatWithoutASignature) {
  Scratch scratch;
  std::ifstream in(fixture("fibre_segments.vtk"));
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const FibreSet read = loadFibres(scratch.write("fibres.obj", text), 0.01);
  EXPECT_EQ(read.points, loadFibres(fixture("fibre_segments.vtk"), 0.01).points);
  EXPECT_EQ(read.offsets, loadFibres(fixture("fibre_segments.vtk"), 0.01).offsets);
}

TEST(LoadersBadInput, BadFibres) {
  const std::string obj = fixture("single_point_fibre.obj");
  EXPECT_TRUE(contains(expectInputError([&] { loadFibres(obj); }, obj), "line 5"));
  const std::string vtk = fixture("single_point_fibre.vtk");
  EXPECT_TRUE(contains(expectInputError([&] { loadFibres(vtk); }, vtk), "LINES cell 1"));
  const std::string reference = fixture("fibre_reference_out_of_range.obj");
  EXPECT_TRUE(contains(expectInputError([&] { loadFibres(reference); }, reference), "reference 9"));
  const std::string zero = fixture("zero_length_fibre.obj");
  EXPECT_TRUE(contains(expectInputError([&] { loadFibres(zero); }, zero), "coincide"));
}

TEST(LoadersBadInput, NonPositiveScale) {
  const std::string path = fixture("cube_quads.vtk");
  for (const double scale : {0.0, -1.0, std::nan("")}) {
    expectInputError([&] { loadSurface(path, scale); }, path);
    expectInputError([&] { loadFibres(fixture("fibres.obj"), scale); }, fixture("fibres.obj"));
  }
}

}  // namespace
}  // namespace fibremss
