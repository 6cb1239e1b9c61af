// Output writers: atomic file writes, VTK XML PolyData (.vtp, ASCII) and .pvd collections.
#include "fibremss/Output.h"

#include <unistd.h>

#include <atomic>
#include <charconv>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <system_error>

namespace fibremss {
namespace {

namespace fs = std::filesystem;

/// A name unique per process and call, so concurrent writers never share a temporary file.
fs::path temporaryPathFor(const fs::path& target) {
  static std::atomic<unsigned> counter{0};
  fs::path temporary = target;
  temporary += ".tmp." + std::to_string(::getpid()) + "." + std::to_string(counter++);
  return temporary;
}

std::string escapeXml(std::string_view text) {
  std::string escaped;
  for (char c : text) {
    switch (c) {
      case '&':
        escaped += "&amp;";
        break;
      case '<':
        escaped += "&lt;";
        break;
      case '>':
        escaped += "&gt;";
        break;
      case '"':
        escaped += "&quot;";
        break;
      default:
        escaped += c;
    }
  }
  return escaped;
}

/// Appends numbers separated by spaces, shortest round-trip form, a line break every few.
class NumberWriter {
 public:
  explicit NumberWriter(std::string& out) : out_(out) {}
  template <typename T>
  void operator()(T value) {
    char buffer[32];
    const auto result = std::to_chars(buffer, buffer + sizeof buffer, value);
    out_.append(buffer, result.ptr);
    out_ += ++count_ % 12 == 0 ? '\n' : ' ';
  }

 private:
  std::string& out_;
  size_t count_ = 0;
};

void openArray(std::string& out, std::string_view type, std::string_view name, int components) {
  out += "        <DataArray type=\"";
  out += type;
  out += '"';
  if (!name.empty()) out += " Name=\"" + escapeXml(name) + '"';
  if (components > 1) out += " NumberOfComponents=\"" + std::to_string(components) + '"';
  out += " format=\"ascii\">\n";
}

void closeArray(std::string& out) {
  out += "\n        </DataArray>\n";
}

/// Writes one cell block (Verts, Lines, Polys): connectivity and end offsets.
template <typename EmitConnectivity, typename EmitOffsets>
void writeCells(std::string& out, std::string_view tag, EmitConnectivity connectivity,
                EmitOffsets offsets) {
  out += "      <";
  out += tag;
  out += ">\n";
  openArray(out, "Int64", "connectivity", 1);
  connectivity(NumberWriter(out));
  closeArray(out);
  openArray(out, "Int64", "offsets", 1);
  offsets(NumberWriter(out));
  closeArray(out);
  out += "      </";
  out += tag;
  out += ">\n";
}

void checkPolyData(const std::string& path, const PolyData& data) {
  const size_t n = data.points.size();
  auto fail = [&](const std::string& what) {
    throw std::runtime_error(path + ": cannot write PolyData: " + what);
  };
  if (data.lineOffsets.empty() || data.lineOffsets.front() != 0 ||
      data.lineOffsets.back() != data.lineIndices.size())
    fail("line offsets must start at 0 and end at the number of line indices");
  for (size_t i = 1; i < data.lineOffsets.size(); ++i)
    if (data.lineOffsets[i] < data.lineOffsets[i - 1]) fail("line offsets must not decrease");
  for (uint32_t index : data.lineIndices)
    if (index >= n) fail("line index " + std::to_string(index) + " >= point count");
  for (const auto& triangle : data.triangles)
    for (uint32_t index : triangle)
      if (index >= n) fail("triangle index " + std::to_string(index) + " >= point count");
  for (const auto& [name, values] : data.pointScalars)
    if (values.size() != n)
      fail("array '" + name + "' has " + std::to_string(values.size()) + " values for " +
           std::to_string(n) + " points");
}

}  // namespace

void writeFileAtomically(const std::string& path, std::string_view content) {
  const fs::path target(path);
  std::error_code error;
  if (target.has_parent_path()) {
    fs::create_directories(target.parent_path(), error);
    if (error)
      throw std::runtime_error(path + ": cannot create directory " + target.parent_path().string() +
                               ": " + error.message());
  }
  const fs::path temporary = temporaryPathFor(target);
  {
    std::ofstream file(temporary, std::ios::binary | std::ios::trunc);
    if (!file)
      throw std::runtime_error(path + ": cannot open " + temporary.string() + " for writing");
    file.write(content.data(), static_cast<std::streamsize>(content.size()));
    file.flush();
    if (!file) {
      file.close();
      fs::remove(temporary, error);
      throw std::runtime_error(path + ": write failed (disk full?)");
    }
  }
  fs::rename(temporary, target, error);
  if (error) {
    std::error_code ignored;
    fs::remove(temporary, ignored);
    throw std::runtime_error(path +
                             ": cannot rename the temporary file into place: " + error.message());
  }
}

void writeVtp(const std::string& path, const PolyData& data) {
  checkPolyData(path, data);
  const size_t pointCount = data.points.size();
  const size_t vertCount = data.pointsAsVertices ? pointCount : 0;
  const size_t lineCount = data.lineOffsets.size() - 1;
  std::string out;
  out.reserve(64 * pointCount + 32 * (data.lineIndices.size() + 3 * data.triangles.size()) + 1024);
  out += "<?xml version=\"1.0\"?>\n";
  out +=
      "<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" "
      "header_type=\"UInt64\">\n  <PolyData>\n";
  out += "    <Piece NumberOfPoints=\"" + std::to_string(pointCount) + "\" NumberOfVerts=\"" +
         std::to_string(vertCount) + "\" NumberOfLines=\"" + std::to_string(lineCount) +
         "\" NumberOfStrips=\"0\" NumberOfPolys=\"" + std::to_string(data.triangles.size()) +
         "\">\n";
  out += "      <PointData";
  if (!data.pointScalars.empty())
    out += " Scalars=\"" + escapeXml(data.pointScalars.front().first) + '"';
  out += ">\n";
  for (const auto& [name, values] : data.pointScalars) {
    openArray(out, "Float32", name, 1);
    NumberWriter write(out);
    for (float value : values) write(value);
    closeArray(out);
  }
  out += "      </PointData>\n      <Points>\n";
  openArray(out, sizeof(btScalar) == 8 ? "Float64" : "Float32", "Points", 3);
  {
    NumberWriter write(out);
    for (const btVector3& p : data.points) {
      write(p.x());
      write(p.y());
      write(p.z());
    }
  }
  closeArray(out);
  out += "      </Points>\n";
  writeCells(
      out, "Verts",
      [&](NumberWriter write) {
        for (size_t i = 0; i < vertCount; ++i) write(i);
      },
      [&](NumberWriter write) {
        for (size_t i = 0; i < vertCount; ++i) write(i + 1);
      });
  writeCells(
      out, "Lines",
      [&](NumberWriter write) {
        for (uint32_t index : data.lineIndices) write(index);
      },
      [&](NumberWriter write) {
        for (size_t i = 1; i < data.lineOffsets.size(); ++i) write(data.lineOffsets[i]);
      });
  writeCells(
      out, "Polys",
      [&](NumberWriter write) {
        for (const auto& triangle : data.triangles)
          for (uint32_t index : triangle) write(index);
      },
      [&](NumberWriter write) {
        for (size_t i = 0; i < data.triangles.size(); ++i) write(3 * (i + 1));
      });
  out += "    </Piece>\n  </PolyData>\n</VTKFile>\n";
  writeFileAtomically(path, out);
}

void PvdCollection::add(double time, const std::string& file, int part) {
  entries_.push_back({time, file, part});
}

void PvdCollection::write(const std::string& path) const {
  std::string out = "<?xml version=\"1.0\"?>\n";
  out += "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n";
  out += "  <Collection>\n";
  for (const Entry& entry : entries_) {
    char time[32];
    const auto end = std::to_chars(time, time + sizeof time, entry.time).ptr;
    out += "    <DataSet timestep=\"" + std::string(time, end) + "\" group=\"\" part=\"" +
           std::to_string(entry.part) + "\" file=\"" + escapeXml(entry.file) + "\"/>\n";
  }
  out += "  </Collection>\n</VTKFile>\n";
  writeFileAtomically(path, out);
}

}  // namespace fibremss
