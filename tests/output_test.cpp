// Output writers: .vtp well-formed with the right counts, atomic writes, .pvd entries.
#include "fibremss/Output.h"

#include <gtest/gtest.h>

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

/// The numbers inside the DataArray named `name` within block `block` (e.g. Lines).
std::vector<double> arrayValues(const std::string& xml, const std::string& block,
                                const std::string& name) {
  const size_t blockStart = block.empty() ? 0 : xml.find("<" + block);
  EXPECT_NE(blockStart, std::string::npos) << block;
  const size_t start = xml.find("Name=\"" + name + "\"", blockStart);
  EXPECT_NE(start, std::string::npos) << block << "/" << name;
  const size_t open = xml.find('>', start) + 1, close = xml.find("</DataArray>", open);
  std::istringstream numbers(xml.substr(open, close - open));
  std::vector<double> values;
  for (double v; numbers >> v;) values.push_back(v);
  return values;
}

TEST_F(OutputTest, VtpHasTheRightCountsAndArrays) {
  PolyData data;
  data.points = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {0.5f, 0.25f, -3}};
  data.pointsAsVertices = true;
  data.lineIndices = {0, 1, 2, 3, 4};
  data.lineOffsets = {0, 3, 5};
  data.triangles = {{0, 1, 2}, {1, 2, 3}};
  data.pointScalars = {{"radius", {0.1f, 0.2f, 0.3f, 0.4f, 0.5f}}, {"fixed", {0, 1, 0, 1, 0}}};
  const fs::path path = directory_ / "nested" / "particles.vtp";
  writeVtp(path.string(), data);
  ASSERT_TRUE(fs::exists(path));
  const std::string xml = readFile(path);
  EXPECT_EQ(xml.rfind("<?xml", 0), 0u);
  const auto names = checkTagsBalanced(xml);
  EXPECT_EQ(std::count(names.begin(), names.end(), "DataArray"), 2 + 1 + 2 * 3);
  EXPECT_EQ(attribute(xml, "NumberOfPoints"), "5");
  EXPECT_EQ(attribute(xml, "NumberOfVerts"), "5");
  EXPECT_EQ(attribute(xml, "NumberOfLines"), "2");
  EXPECT_EQ(attribute(xml, "NumberOfPolys"), "2");

  const auto points = arrayValues(xml, "Points", "Points");
  ASSERT_EQ(points.size(), 15u);
  for (size_t i = 0; i < data.points.size(); ++i)
    for (int k = 0; k < 3; ++k) EXPECT_FLOAT_EQ(points[3 * i + k], data.points[i][k]);
  const auto radius = arrayValues(xml, "PointData", "radius");
  ASSERT_EQ(radius.size(), 5u);
  EXPECT_FLOAT_EQ(radius[2], 0.3f);
  EXPECT_EQ(arrayValues(xml, "PointData", "fixed"), (std::vector<double>{0, 1, 0, 1, 0}));
  EXPECT_EQ(arrayValues(xml, "Lines", "connectivity"), (std::vector<double>{0, 1, 2, 3, 4}));
  EXPECT_EQ(arrayValues(xml, "Lines", "offsets"), (std::vector<double>{3, 5}));
  EXPECT_EQ(arrayValues(xml, "Polys", "connectivity"), (std::vector<double>{0, 1, 2, 1, 2, 3}));
  EXPECT_EQ(arrayValues(xml, "Polys", "offsets"), (std::vector<double>{3, 6}));
  EXPECT_EQ(arrayValues(xml, "Verts", "offsets").size(), 5u);
}

TEST_F(OutputTest, VtpRejectsInconsistentData) {
  PolyData data;
  data.points = {{0, 0, 0}, {1, 0, 0}};
  data.triangles = {{0, 1, 2}};
  const fs::path path = directory_ / "bad.vtp";
  EXPECT_THROW(writeVtp(path.string(), data), std::runtime_error);
  data.triangles.clear();
  data.pointScalars = {{"radius", {1}}};
  EXPECT_THROW(writeVtp(path.string(), data), std::runtime_error);
  data.pointScalars.clear();
  data.lineIndices = {0, 1};
  EXPECT_THROW(writeVtp(path.string(), data), std::runtime_error);  // offsets do not cover it
  EXPECT_FALSE(fs::exists(path));
}

TEST_F(OutputTest, ArrayNamesAreEscaped) {
  PolyData data;
  data.points = {{0, 0, 0}};
  data.pointScalars = {{"a<b & \"c\"", {1}}};
  const fs::path path = directory_ / "escaped.vtp";
  writeVtp(path.string(), data);
  const std::string xml = readFile(path);
  checkTagsBalanced(xml);
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
  collection.add(0.0, "frame_0000/muscles.vtp", 0);
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
}

}  // namespace
}  // namespace fibremss
