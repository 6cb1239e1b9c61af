// VTK XML PolyData (.vtp) as a mesh format: every encoding VTK writes (inline ascii, inline
// base64 with and without zlib blocks, appended raw and base64; UInt32 and UInt64 headers; both
// byte orders), written here by a small writer, and hostile files that must end in InputError.
#include <gtest/gtest.h>
#include <zlib.h>

#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "fibremss/Error.h"
#include "fibremss/MeshIO.h"
#include "fibremss/Output.h"
#include "fibremss/VtkFiles.h"
#include "support/Process.h"

namespace fs = std::filesystem;
using fibremss::InputError;
using fibremss::loadFibres;
using fibremss::loadSurface;
using fibremss::TriangleMesh;

namespace {

enum class Encoding { Ascii, Binary, BinaryJoint, AppendedRaw, AppendedBase64 };

struct Format {
  Encoding encoding = Encoding::Ascii;
  bool compressed = false;
  bool uint64Header = false;
  bool bigEndian = false;
  size_t blockSize = 16;  ///< small, so that arrays span several zlib blocks
};

// A tetrahedron, outward triangles.
const float kPoints[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
const int64_t kConnectivity[12] = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
const int32_t kOffsets[4] = {3, 6, 9, 12};

std::string base64(const std::string& bytes) {
  static const char* kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (size_t i = 0; i < bytes.size(); i += 3) {
    uint32_t bits = 0;
    const size_t n = std::min<size_t>(3, bytes.size() - i);
    for (size_t k = 0; k < 3; ++k)
      bits = (bits << 8) | (k < n ? static_cast<unsigned char>(bytes[i + k]) : 0u);
    for (size_t k = 0; k < 4; ++k) out += k <= n ? kAlphabet[(bits >> (18 - 6 * k)) & 63] : '=';
  }
  return out;
}

/// `value`'s `size` low bytes in the format's byte order.
std::string word(uint64_t value, int size, bool bigEndian) {
  std::string out(size_t(size), '\0');
  for (int i = 0; i < size; ++i)
    out[size_t(bigEndian ? size - 1 - i : i)] = char((value >> (8 * i)) & 0xff);
  return out;
}

template <typename T>
std::string rawBytes(const T* values, size_t count, bool bigEndian) {
  std::string out;
  for (size_t i = 0; i < count; ++i) {
    uint64_t bits = 0;
    std::memcpy(&bits, &values[i], sizeof(T));
    out += word(bits, sizeof(T), bigEndian);
  }
  return out;
}

/// The header and the data of one array as VTK writes them (header, data encoded apart).
std::pair<std::string, std::string> payload(const std::string& raw, const Format& f) {
  const int h = f.uint64Header ? 8 : 4;
  if (!f.compressed) return {word(raw.size(), h, f.bigEndian), raw};
  std::string header, blocks;
  const size_t count = (raw.size() + f.blockSize - 1) / f.blockSize;
  header += word(count, h, f.bigEndian) + word(f.blockSize, h, f.bigEndian) +
            word(raw.size() % f.blockSize, h, f.bigEndian);
  for (size_t b = 0; b < count; ++b) {
    const std::string block = raw.substr(b * f.blockSize, f.blockSize);
    uLongf length = compressBound(uLong(block.size()));
    std::string compressed(length, '\0');
    compress2(reinterpret_cast<Bytef*>(compressed.data()), &length,
              reinterpret_cast<const Bytef*>(block.data()), uLong(block.size()), 6);
    compressed.resize(length);
    header += word(compressed.size(), h, f.bigEndian);
    blocks += compressed;
  }
  return {header, blocks};
}

/// A DataArray element in the format; appended payloads go to `appended`.
std::string dataArray(const std::string& attributes, const std::string& raw,
                      const std::string& ascii, const Format& f, std::string& appended) {
  const std::string open = "<DataArray " + attributes;
  if (f.encoding == Encoding::Ascii) return open + " format=\"ascii\">" + ascii + "</DataArray>\n";
  const auto [header, data] = payload(raw, f);
  if (f.encoding == Encoding::Binary)
    return open + " format=\"binary\">\n  " + base64(header) + base64(data) + "\n</DataArray>\n";
  if (f.encoding == Encoding::BinaryJoint)
    return open + " format=\"binary\">" + base64(header + data) + "</DataArray>\n";
  const std::string offset = std::to_string(appended.size());
  appended += f.encoding == Encoding::AppendedRaw ? header + data : base64(header) + base64(data);
  return open + " format=\"appended\" offset=\"" + offset + "\"/>\n";
}

std::string tetraVtp(const Format& f) {
  std::string appended;
  std::string xml =
      "<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"";
  xml += std::string(f.bigEndian ? "BigEndian" : "LittleEndian") + "\" header_type=\"" +
         (f.uint64Header ? "UInt64" : "UInt32") + "\"" +
         (f.compressed ? " compressor=\"vtkZLibDataCompressor\"" : "") + ">\n";
  xml +=
      "<PolyData>\n<Piece NumberOfPoints=\"4\" NumberOfVerts=\"0\" NumberOfLines=\"0\" "
      "NumberOfStrips=\"0\" NumberOfPolys=\"4\">\n<PointData Normals=\"n\"></PointData>\n";
  xml += "<Points>\n" +
         dataArray("type=\"Float32\" Name=\"Points\" NumberOfComponents=\"3\"",
                   rawBytes(kPoints, 12, f.bigEndian), "0 0 0 1 0 0\n 0 1 0 0 0 1", f, appended) +
         "</Points>\n<Polys>\n";
  xml += dataArray("type=\"Int64\" Name=\"connectivity\"", rawBytes(kConnectivity, 12, f.bigEndian),
                   "0 2 1 0 1 3 0 3 2 1 2 3", f, appended);
  xml += dataArray("type=\"Int32\" Name=\"offsets\"", rawBytes(kOffsets, 4, f.bigEndian),
                   "3 6 9 12", f, appended);
  xml += "</Polys>\n</Piece>\n</PolyData>\n";
  if (!appended.empty())
    xml += std::string("<AppendedData encoding=\"") +
           (f.encoding == Encoding::AppendedRaw ? "raw" : "base64") + "\">\n   _" + appended +
           "\n</AppendedData>\n";
  return xml + "</VTKFile>\n";
}

class VtpFiles : public ::testing::Test {
 protected:
  std::string write(const std::string& name, const std::string& bytes) {
    const fs::path path = directory_.path() / name;
    std::ofstream(path, std::ios::binary) << bytes;
    return path.string();
  }
  void expectTetra(const TriangleMesh& mesh, const std::string& what) {
    ASSERT_EQ(mesh.vertices.size(), 4u) << what;
    ASSERT_EQ(mesh.triangles.size(), 4u) << what;
    for (size_t i = 0; i < 4; ++i)
      EXPECT_EQ(mesh.vertices[i], btVector3(kPoints[3 * i], kPoints[3 * i + 1], kPoints[3 * i + 2]))
          << what;
    for (size_t t = 0; t < 4; ++t)
      for (size_t k = 0; k < 3; ++k)
        EXPECT_EQ(mesh.triangles[t][k], uint32_t(kConnectivity[3 * t + k])) << what;
  }
  /// The InputError loading `bytes` gives (a failure when it loads).
  InputError errorOf(const std::string& bytes) {
    const std::string path = write("bad.vtp", bytes);
    try {
      loadSurface(path);
    } catch (const InputError& error) {
      EXPECT_EQ(error.source(), path);
      return error;
    }
    ADD_FAILURE() << "no InputError for:\n" << bytes.substr(0, 2000);
    return InputError("", "", "");
  }

  fibremss::testing::TemporaryDirectory directory_{"fibremss_vtp_test"};
};

}  // namespace

TEST_F(VtpFiles, EveryEncodingGivesTheSameMesh) {
  for (Encoding encoding : {Encoding::Ascii, Encoding::Binary, Encoding::BinaryJoint,
                            Encoding::AppendedRaw, Encoding::AppendedBase64})
    for (bool compressed : {false, true})
      for (bool uint64Header : {false, true})
        for (bool bigEndian : {false, true}) {
          if (encoding == Encoding::Ascii && (compressed || uint64Header || bigEndian)) continue;
          Format f;
          f.encoding = encoding;
          f.compressed = compressed;
          f.uint64Header = uint64Header;
          f.bigEndian = bigEndian;
          const std::string what = "encoding " + std::to_string(int(encoding)) +
                                   (compressed ? " zlib" : "") + (uint64Header ? " UInt64" : "") +
                                   (bigEndian ? " big-endian" : "");
          expectTetra(loadSurface(write("tetra.vtp", tetraVtp(f))), what);
        }
  // A single zlib block holding a whole array (block size above the array's size).
  Format oneBlock;
  oneBlock.encoding = Encoding::Binary;
  oneBlock.compressed = true;
  oneBlock.blockSize = 1 << 15;
  expectTetra(loadSurface(write("tetra.vtp", tetraVtp(oneBlock))), "one block");
  // Recognised by content under another name; scaled to metres like every mesh.
  const TriangleMesh scaled = loadSurface(write("tetra.xml", tetraVtp(Format{})), 0.001);
  EXPECT_FLOAT_EQ(scaled.vertices[1].x(), 0.001f);
}

TEST_F(VtpFiles, StripsAndLinesAndFramesWrittenByFibreMss) {
  const std::string strip =
      "<VTKFile type=\"PolyData\"><PolyData><Piece NumberOfPoints=\"4\" NumberOfStrips=\"1\" "
      "NumberOfLines=\"1\"><Points><DataArray type=\"Float64\" NumberOfComponents=\"3\" "
      "format=\"ascii\">0 0 0 1 0 0 0 1 0 1 1 0</DataArray></Points><Strips><DataArray "
      "type=\"Int32\" Name=\"connectivity\" format=\"ascii\">0 1 2 3</DataArray><DataArray "
      "type=\"Int32\" Name=\"offsets\" format=\"ascii\">4</DataArray></Strips><Lines><DataArray "
      "type=\"Int32\" Name=\"connectivity\" format=\"ascii\">0 3</DataArray><DataArray "
      "type=\"Int32\" Name=\"offsets\" format=\"ascii\">2</DataArray></Lines></Piece></PolyData>"
      "</VTKFile>";
  const TriangleMesh mesh = loadSurface(write("strip.vtp", strip));
  ASSERT_EQ(mesh.triangles.size(), 2u);
  // Both triangles of the strip face the same way (+z).
  for (const auto& t : mesh.triangles)
    EXPECT_GT((mesh.vertices[t[1]] - mesh.vertices[t[0]])
                  .cross(mesh.vertices[t[2]] - mesh.vertices[t[0]])
                  .z(),
              0);
  EXPECT_EQ(loadFibres(write("lines.vtp", strip)).fibreCount(), 1u);
  // The frames FibreMSS writes (compressed, appended) read back as the same surface.
  fibremss::PolyData data;
  for (size_t i = 0; i < 4; ++i)
    data.points.push_back(btVector3(kPoints[3 * i], kPoints[3 * i + 1], kPoints[3 * i + 2]));
  for (size_t t = 0; t < 4; ++t)
    data.triangles.push_back({uint32_t(kConnectivity[3 * t]), uint32_t(kConnectivity[3 * t + 1]),
                              uint32_t(kConnectivity[3 * t + 2])});

  data.pointData.push_back({"radius", 1, std::vector<float>{1, 2, 3, 4}});
  data.fieldData.push_back({"TimeValue", 1, std::vector<double>{0.5}});
  data.pointScale = 1000;  // written in millimetres: read back at 0.001 m per unit
  const std::string frame = (directory_.path() / "frame.vtp").string();
  fibremss::writeVtp(frame, data);  // appended raw, zlib blocks, UInt64 headers
  expectTetra(loadSurface(frame, 0.001), "writeVtp");
}

TEST_F(VtpFiles, HostileFilesEndInInputErrorNamingWhatWasExpected) {
  Format binary;
  binary.encoding = Encoding::Binary;
  Format zlib = binary;
  zlib.compressed = true;
  Format appended;
  appended.encoding = Encoding::AppendedRaw;
  const std::string good = tetraVtp(binary), goodZlib = tetraVtp(zlib),
                    goodAppended = tetraVtp(appended), ascii = tetraVtp(Format{});
  auto replaced = [](std::string text, const std::string& from, const std::string& to) {
    const size_t at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    return at == std::string::npos ? text : text.replace(at, from.size(), to);
  };
  auto expectProblem = [&](const std::string& bytes, const std::string& words) {
    const InputError e = errorOf(bytes);
    EXPECT_NE(e.problem().find(words), std::string::npos) << e.what();
  };
  // Counts that the data cannot hold, before anything is allocated.
  expectProblem(replaced(ascii, "NumberOfPoints=\"4\"", "NumberOfPoints=\"4000000000\""), "values");
  expectProblem(replaced(good, "NumberOfPoints=\"4\"", "NumberOfPoints=\"4000000000\""),
                "can hold");
  expectProblem(replaced(goodZlib, "NumberOfPoints=\"4\"", "NumberOfPoints=\"400000000\""),
                "can hold");
  expectProblem(replaced(ascii, "NumberOfPoints=\"4\"", "NumberOfPoints=\"-4\""), "NumberOfPoints");
  expectProblem(replaced(ascii, "3 6 9 12", "3 6 9 1200000000000"), "values");
  // Wrong values: a decreasing offset, an index beyond the points, a word that is no number.
  expectProblem(replaced(ascii, "3 6 9 12", "3 6 2 12"), "offset 2");
  expectProblem(replaced(ascii, "0 2 1 0 1 3", "0 2 1 0 1 7"), "point index from 0 to 4-1");
  expectProblem(replaced(ascii, "0 0 0 1 0 0", "0 0 x 1 0 0"), "expected a number");
  // Truncation: base64 cut short, appended data cut short, a broken zlib block, unclosed tags.
  const size_t pointsEnd = good.find("\n</DataArray>");
  expectProblem(good.substr(0, pointsEnd - 9) + good.substr(pointsEnd), "bytes");
  expectProblem(goodAppended.substr(0, goodAppended.size() - 40), "");
  std::string broken = goodZlib;
  const size_t data = broken.find("eJ");  // the zlib stream's first bytes in base64
  ASSERT_NE(data, std::string::npos);
  broken[data + 6] = broken[data + 6] == 'A' ? 'B' : 'A';
  expectProblem(broken, "");
  // The header's byte count disagrees with the points; a foreign compressor; not PolyData.
  expectProblem(replaced(good, base64(word(48, 4, false)), base64(word(52, 4, false))),
                "the header says 52");
  expectProblem(replaced(goodZlib, "vtkZLibDataCompressor", "vtkLZ4DataCompressor"), "LZ4");
  expectProblem(replaced(ascii, "type=\"PolyData\"", "type=\"UnstructuredGrid\""), "PolyData");
  expectProblem(ascii.substr(0, ascii.find("</Polys>")), "expected </Polys>");
}

namespace {

/// A .vtp of `pieces` pieces of `points` points each, all zeros, every piece's Points pointing at
/// one appended zlib stream (UInt64 headers, VTK's 32 KiB blocks): about 1000:1.
std::string zeroPointsVtp(uint64_t points, int pieces) {
  const uint64_t bytes = 12 * points, blockSize = 32768,
                 blocks = (bytes + blockSize - 1) / blockSize;
  const auto compressed = [](uint64_t size) {
    const std::string zeros(size, '\0');
    uLongf length = compressBound(uLong(size));
    std::string out(length, '\0');
    compress2(reinterpret_cast<Bytef*>(out.data()), &length,
              reinterpret_cast<const Bytef*>(zeros.data()), uLong(size), 9);
    out.resize(length);
    return out;
  };
  const std::string full = compressed(blockSize),
                    last = compressed(bytes - (blocks - 1) * blockSize);
  std::string header = word(blocks, 8, false) + word(blockSize, 8, false) +
                       word(bytes % blockSize, 8, false),
              data;
  for (uint64_t b = 0; b < blocks; ++b) {
    const std::string& block = b + 1 == blocks ? last : full;
    header += word(block.size(), 8, false);
    data += block;
  }
  std::string xml =
      "<VTKFile type=\"PolyData\" header_type=\"UInt64\" compressor=\"vtkZLibDataCompressor\">\n"
      "<PolyData>\n";
  for (int p = 0; p < pieces; ++p)
    xml += "<Piece NumberOfPoints=\"" + std::to_string(points) +
           "\"><Points><DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"appended\" "
           "offset=\"0\"/></Points></Piece>\n";
  return xml + "</PolyData>\n<AppendedData encoding=\"raw\">_" + header + data +
         "</AppendedData>\n</VTKFile>\n";
}

}  // namespace

TEST_F(VtpFiles, DeclaredSizesBeyondTheBudgetAreRefusedBeforeInflating) {
  // A zip bomb: 30 million points, 360 MB of zeros in about half a megabyte.
  InputError e = errorOf(zeroPointsVtp(30000000, 1));
  EXPECT_NE(e.problem().find("one file may hold in all"), std::string::npos) << e.what();
  // Pieces that all point at one appended block, to read it again and again.
  e = errorOf(zeroPointsVtp(1000, 2));
  EXPECT_EQ(e.where(), "line 4") << e.what();
  EXPECT_NE(e.problem().find("offset 0 is also that of the DataArray on line 3"), std::string::npos)
      << e.what();
}

TEST_F(VtpFiles, SharedOpenSimGeometryLoadsInMetres) {
  const fs::path folder = fs::path(FIBREMSS_SHARED_DATA_DIR) / "opensim-motions";
  if (!fs::exists(folder / "femur_r.vtp")) GTEST_SKIP() << "shared data not found: " << folder;
  for (const char* name : {"femur_r.vtp", "pelvis.vtp", "sacrum.vtp", "tibia_r.vtp"}) {
    fibremss::MeshReport report;
    const TriangleMesh mesh = loadSurface((folder / name).string(), 1.0, &report);
    EXPECT_GE(mesh.vertices.size(), 100u) << name;
    EXPECT_GE(mesh.triangles.size(), 200u) << name;
    btVector3 lower, upper;
    fibremss::pointBounds(mesh.vertices, lower, upper);
    const btScalar extent = (upper - lower).length();
    EXPECT_GT(extent, 0.05) << name;  // bones of an adult, in metres
    EXPECT_LT(extent, 0.6) << name;
  }
  // The femur's long axis is its frame's y (OpenSim: +y superior), about 0.4 m.
  const TriangleMesh femur = loadSurface((folder / "femur_r.vtp").string());
  btVector3 lower, upper;
  fibremss::pointBounds(femur.vertices, lower, upper);
  EXPECT_GT(upper.y() - lower.y(), 0.3);
  EXPECT_LT(upper.y() - lower.y(), 0.5);
}

namespace fibremss {
namespace {

TEST(VtpFrames, PointDataAndACollectionReadBackAsWritten) {
  testing::TemporaryDirectory dir("fibremss_vtp_frames");
  PolyData data;
  data.points = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  data.pointScale = 1000;
  data.triangles = {{0, 1, 2}, {0, 2, 3}};
  data.lineIndices = {0, 1, 3};
  data.lineOffsets = {0, 3};
  data.pointData = {{"stretch", 1, std::vector<float>{1.0f, 1.25f, 0.5f, 2.0f}},
                    {"id", 1, std::vector<int32_t>{7, 7, 7, 7}},
                    {"d", 3, std::vector<double>{0, 0, 0, 1, 2, 3, -1, 0, 0.5, 4, 4, 4}}};
  const std::string path = (dir.path() / "a.vtp").string();
  writeVtp(path, data);
  const PolyDataFile file = readVtp(path, 0.001);
  ASSERT_EQ(file.points.size(), 4u);
  EXPECT_NEAR(file.points[1].x(), 1.0, 1e-6);
  EXPECT_EQ(file.triangles.size(), 2u);
  EXPECT_EQ(file.lineIndices, data.lineIndices);
  ASSERT_EQ(file.pointData.size(), 3u);
  EXPECT_EQ(file.array("stretch")->values, (std::vector<float>{1.0f, 1.25f, 0.5f, 2.0f}));
  EXPECT_EQ(file.array("id")->values, (std::vector<float>{7, 7, 7, 7}));
  EXPECT_EQ(file.array("d")->components, 3);
  EXPECT_EQ(file.array("d")->values[5], 3.0f);
  EXPECT_EQ(file.array("none"), nullptr);

  PvdCollection pvd;
  pvd.add(0.5, "a.vtp", 0);
  pvd.add(0.5, "b.vtp", 1);
  pvd.add(0.00457108166301623, "c.vtp", 0);
  pvd.write((dir.path() / "run.pvd").string());
  const std::vector<PvdDataSet> sets = readPvd((dir.path() / "run.pvd").string());
  ASSERT_EQ(sets.size(), 3u);
  EXPECT_EQ(sets[1].file, "b.vtp");
  EXPECT_EQ(sets[1].part, 1);
  EXPECT_DOUBLE_EQ(sets[2].time, 0.00457108166301623);
  std::ofstream(dir.path() / "bad.pvd") << "<VTKFile type=\"PolyData\"></VTKFile>";
  EXPECT_THROW(readPvd((dir.path() / "bad.pvd").string()), InputError);
}

}  // namespace
}  // namespace fibremss
