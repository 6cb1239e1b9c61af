// Output writers: .vtp well-formed with the right counts and compression headers, atomic
// writes, .pvd entries. (tests/frames_vtk_test.py reads the frames with VTK and ParaView.)
#include "fibremss/Output.h"

#include <gtest/gtest.h>

#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

namespace fibremss {
namespace {

namespace fs = std::filesystem;

class OutputTest : public ::testing::Test {
 protected:
  void SetUp() override {
    directory_ = fs::temp_directory_path() /
                 ("fibremss_output_test_" +
                  std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(directory_);
  }
  void TearDown() override { fs::remove_all(directory_); }
  fs::path directory_;
};

std::string readFile(const fs::path& path) {
  std::ifstream file(path);
  std::stringstream buffer;
  buffer << file.rdbuf();
  return buffer.str();
}

/// Checks that every tag opened is closed in order (a minimal well-formedness test) and
/// returns the element names in document order.
std::vector<std::string> checkTagsBalanced(const std::string& xml) {
  std::vector<std::string> stack, names;
  for (size_t open = xml.find('<'); open != std::string::npos; open = xml.find('<', open + 1)) {
    const size_t close = xml.find('>', open);
    EXPECT_NE(close, std::string::npos) << "unterminated tag";
    if (close == std::string::npos) break;
    const std::string tag = xml.substr(open + 1, close - open - 1);
    if (tag.empty() || tag[0] == '?') continue;  // the XML declaration
    const bool closing = tag[0] == '/', selfClosing = tag.back() == '/';
    const size_t nameStart = closing ? 1 : 0;
    const std::string name = tag.substr(nameStart, tag.find_first_of(" /", nameStart) - nameStart);
    if (closing) {
      EXPECT_FALSE(stack.empty()) << "closing " << name << " with nothing open";
      if (stack.empty()) break;
      EXPECT_EQ(stack.back(), name);
      stack.pop_back();
    } else {
      names.push_back(name);
      if (!selfClosing) stack.push_back(name);
    }
  }
  EXPECT_TRUE(stack.empty()) << "unclosed tags";
  return names;
}

/// The value of the first attribute `name` at or after `from`.
std::string attribute(const std::string& xml, const std::string& name, size_t from = 0) {
  const size_t start = xml.find(" " + name + "=\"", from);
  EXPECT_NE(start, std::string::npos) << name;
  if (start == std::string::npos) return "";
  const size_t valueStart = start + name.size() + 3;
  return xml.substr(valueStart, xml.find('"', valueStart) - valueStart);
}

/// The attributes of the DataArray named `name` within block `block` (e.g. Lines): its tag text.
std::string arrayTag(const std::string& xml, const std::string& block, const std::string& name) {
  const size_t blockStart = xml.find("<" + block);
  EXPECT_NE(blockStart, std::string::npos) << block;
  const size_t start = xml.find("Name=\"" + name + "\"", blockStart);
  EXPECT_NE(start, std::string::npos) << block << "/" << name;
  if (start == std::string::npos) return "";
  const size_t open = xml.rfind("<DataArray", start);
  return xml.substr(open, xml.find('>', start) - open + 1);
}

/// The first numbers of the compression header (UInt64) of the array whose tag is `tag`: block
/// count, block size, size of the partial last block. Checks the first compressed size too.
std::array<uint64_t, 3> compressionHeader(const std::string& xml, const std::string& tag) {
  const size_t data = xml.find('_', xml.find("<AppendedData encoding=\"raw\">")) + 1;
  const size_t offset = std::stoul(attribute(tag, "offset"));
  std::array<uint64_t, 4> header{};
  EXPECT_LE(data + offset + 32, xml.size());
  std::memcpy(header.data(), xml.data() + data + offset,
              std::min<size_t>(32, xml.size() - data - offset));
  if (header[0] > 0) {
    EXPECT_GT(header[3], 0u);
  }
  return {header[0], header[1], header[2]};
}

/// A header for `bytes` uncompressed bytes in blocks of 32768 as vtkZLibDataCompressor writes it.
std::array<uint64_t, 3> expectedHeader(uint64_t bytes) {
  return {(bytes + 32767) / 32768, 32768, bytes % 32768};
}

TEST_F(OutputTest, VtpHasTheRightCountsAndArrays) {
  PolyData data;
  data.points = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {0.5f, 0.25f, -3}};
  data.pointScale = 1000;
  data.pointsAsVertices = true;
  data.lineIndices = {0, 1, 2, 3, 4};
  data.lineOffsets = {0, 3, 5};
  data.triangles = {{0, 1, 2}, {1, 2, 3}};
  data.pointData = {{"radius", 1, std::vector<float>{0.1f, 0.2f, 0.3f, 0.4f, 0.5f}},
                    {"muscle_id", 1, std::vector<int32_t>(5, 7)},
                    {"displacement", 3, std::vector<float>(15, 0.5f)}};
  data.fieldData = {{"TimeValue", 1, std::vector<double>{0.25}},
                    {"transform", 16, std::vector<double>(16, 1.0)}};
  const fs::path path = directory_ / "nested" / "particles.vtp";
  writeVtp(path.string(), data);
  ASSERT_TRUE(fs::exists(path));
  const std::string file = readFile(path);
  EXPECT_EQ(file.rfind("<?xml", 0), 0u);
  const size_t appended = file.find("<AppendedData");
  ASSERT_NE(appended, std::string::npos);
  const std::string xml = file.substr(0, appended) + "</VTKFile>";
  EXPECT_TRUE(file.ends_with("</AppendedData>\n</VTKFile>\n"));
  EXPECT_EQ(attribute(xml, "header_type"), "UInt64");
  EXPECT_EQ(attribute(xml, "compressor"), "vtkZLibDataCompressor");
  const auto names = checkTagsBalanced(xml);
  EXPECT_EQ(std::count(names.begin(), names.end(), "DataArray"), 2 + 3 + 1 + 3 * 2);
  EXPECT_EQ(attribute(xml, "NumberOfPoints"), "5");
  EXPECT_EQ(attribute(xml, "NumberOfVerts"), "5");
  EXPECT_EQ(attribute(xml, "NumberOfLines"), "2");
  EXPECT_EQ(attribute(xml, "NumberOfPolys"), "2");
  EXPECT_EQ(attribute(xml, "Scalars"), "radius");

  // Every array appended raw, its header announcing exactly the bytes of its values.
  const std::string points = arrayTag(xml, "Points", "Points");
  EXPECT_EQ(attribute(points, "type"), "Float32");
  EXPECT_EQ(attribute(points, "NumberOfComponents"), "3");
  EXPECT_EQ(compressionHeader(file, points), expectedHeader(5 * 3 * 4));
  const std::string id = arrayTag(xml, "PointData", "muscle_id");
  EXPECT_EQ(attribute(id, "type"), "Int32");
  EXPECT_EQ(compressionHeader(file, id), expectedHeader(5 * 4));
  EXPECT_EQ(attribute(arrayTag(xml, "PointData", "displacement"), "NumberOfComponents"), "3");
  const std::string transform = arrayTag(xml, "FieldData", "transform");
  EXPECT_EQ(attribute(transform, "type"), "Float64");
  EXPECT_EQ(attribute(transform, "NumberOfTuples"), "1");
  EXPECT_EQ(compressionHeader(file, transform), expectedHeader(16 * 8));
  EXPECT_EQ(compressionHeader(file, arrayTag(xml, "Lines", "connectivity")), expectedHeader(5 * 4));
  EXPECT_EQ(compressionHeader(file, arrayTag(xml, "Lines", "offsets")), expectedHeader(2 * 4));
  EXPECT_EQ(compressionHeader(file, arrayTag(xml, "Polys", "connectivity")), expectedHeader(6 * 4));
  EXPECT_EQ(compressionHeader(file, arrayTag(xml, "Verts", "offsets")), expectedHeader(5 * 4));
}

TEST_F(OutputTest, LargeArraysAreSplitIntoBlocks) {
  PolyData data;
  data.points.assign(10000, btVector3(1, 2, 3));  // 120 000 bytes: three full blocks and a part
  const fs::path path = directory_ / "large.vtp";
  writeVtp(path.string(), data);
  const std::string file = readFile(path);
  EXPECT_EQ(compressionHeader(file, arrayTag(file, "Points", "Points")),
            (std::array<uint64_t, 3>{4, 32768, 120000 - 3 * 32768}));
  EXPECT_EQ(file.find("<Polys"), std::string::npos);  // empty cell blocks are left out
  EXPECT_LT(file.size(), 2000u);                      // and the repeated points compressed
}

TEST_F(OutputTest, VtpRejectsInconsistentData) {
  PolyData data;
  data.points = {{0, 0, 0}, {1, 0, 0}};
  data.triangles = {{0, 1, 2}};
  const fs::path path = directory_ / "bad.vtp";
  EXPECT_THROW(writeVtp(path.string(), data), std::runtime_error);
  data.triangles.clear();
  data.pointData = {{"radius", 1, std::vector<float>{1}}};
  EXPECT_THROW(writeVtp(path.string(), data), std::runtime_error);
  data.pointData = {{"displacement", 3, std::vector<float>(4)}};
  EXPECT_THROW(writeVtp(path.string(), data), std::runtime_error);
  data.pointData.clear();
  data.fieldData = {{"transform", 16, std::vector<double>(15)}};
  EXPECT_THROW(writeVtp(path.string(), data), std::runtime_error);
  data.fieldData.clear();
  data.lineIndices = {0, 1};
  EXPECT_THROW(writeVtp(path.string(), data), std::runtime_error);  // offsets do not cover it
  EXPECT_FALSE(fs::exists(path));
}

TEST_F(OutputTest, ArrayNamesAreEscaped) {
  PolyData data;
  data.points = {{0, 0, 0}};
  data.pointData = {{"a<b & \"c\"", 1, std::vector<float>{1}}};
  const fs::path path = directory_ / "escaped.vtp";
  writeVtp(path.string(), data);
  const std::string xml = readFile(path);
  EXPECT_NE(xml.find("a&lt;b &amp; &quot;c&quot;"), std::string::npos);
}

TEST_F(OutputTest, AtomicWriteReplacesAndLeavesNoTemporaryFile) {
  const fs::path path = directory_ / "a" / "b" / "file.txt";
  writeFileAtomically(path.string(), "first");
  writeFileAtomically(path.string(), "second, longer content");
  EXPECT_EQ(readFile(path), "second, longer content");
  size_t files = 0;
  for (const auto& entry : fs::directory_iterator(path.parent_path())) {
    ++files;
    EXPECT_EQ(entry.path().filename(), "file.txt");
  }
  EXPECT_EQ(files, 1u);
}

TEST_F(OutputTest, AtomicWriteFailsWithThePathWhenTheDirectoryIsAFile) {
  fs::create_directories(directory_);
  writeFileAtomically((directory_ / "plain").string(), "x");
  const std::string target = (directory_ / "plain" / "child.txt").string();
  try {
    writeFileAtomically(target, "y");
    FAIL() << "expected an error";
  } catch (const std::runtime_error& error) {
    EXPECT_NE(std::string(error.what()).find(target), std::string::npos) << error.what();
  }
}

TEST_F(OutputTest, PvdListsEveryEntry) {
  PvdCollection collection;
  collection.add(0.0, "frame_0000/muscles.vtp", 0, "muscles & <tendons>");
  collection.add(0.0, "frame_0000/bones.vtp", 1);
  collection.add(0.25, "frame_0001/muscles.vtp", 0);
  const fs::path path = directory_ / "run.pvd";
  collection.write(path.string());
  collection.add(0.25, "frame_0001/bones.vtp", 1);
  collection.write(path.string());  // rewritten as frames are added
  const std::string xml = readFile(path);
  const auto names = checkTagsBalanced(xml);
  EXPECT_EQ(std::count(names.begin(), names.end(), "DataSet"), 4);
  EXPECT_NE(xml.find("type=\"Collection\""), std::string::npos);
  std::vector<std::string> files;
  for (size_t at = xml.find("<DataSet"); at != std::string::npos; at = xml.find("<DataSet", at + 1))
    files.push_back(attribute(xml, "file", at));
  EXPECT_EQ(files, (std::vector<std::string>{"frame_0000/muscles.vtp", "frame_0000/bones.vtp",
                                             "frame_0001/muscles.vtp", "frame_0001/bones.vtp"}));
  const size_t last = xml.rfind("<DataSet");
  EXPECT_DOUBLE_EQ(std::stod(attribute(xml, "timestep", last)), 0.25);
  EXPECT_EQ(attribute(xml, "part", last), "1");
  EXPECT_EQ(attribute(xml, "group", last), "");
  EXPECT_EQ(attribute(xml, "name", xml.find("<DataSet")), "muscles &amp; &lt;tendons&gt;");
  EXPECT_EQ(xml.find("name=", last), std::string::npos);  // no name given, none written
}

}  // namespace
}  // namespace fibremss
