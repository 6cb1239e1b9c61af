// Legacy VTK POLYDATA reader (ASCII and BINARY, classic and 5.1 OFFSETS/CONNECTIVITY layout).
// Every count in a header is checked against the bytes left in the file before anything is
// allocated, and every index against the point count, so bad files end in an InputError.
#include <algorithm>
#include <bit>
#include <cctype>
#include <charconv>
#include <cmath>
#include <limits>

#include "MeshIOInternal.h"
#include "fibremss/Error.h"

namespace fibremss::meshio {
namespace {

/// A scalar type name of the legacy format, its size in bytes and how to decode it.
struct ScalarType {
  std::string_view name;
  int bytes;
  enum Kind { Signed, Unsigned, Real } kind;
};

// vtkIdType is written as a 32-bit int by VTK's legacy writer; long is the LP64 long.
constexpr ScalarType kScalarTypes[] = {{"char", 1, ScalarType::Signed},
                                       {"unsigned_char", 1, ScalarType::Unsigned},
                                       {"short", 2, ScalarType::Signed},
                                       {"unsigned_short", 2, ScalarType::Unsigned},
                                       {"int", 4, ScalarType::Signed},
                                       {"unsigned_int", 4, ScalarType::Unsigned},
                                       {"long", 8, ScalarType::Signed},
                                       {"unsigned_long", 8, ScalarType::Unsigned},
                                       {"vtkidtype", 4, ScalarType::Signed},
                                       {"vtktypeint8", 1, ScalarType::Signed},
                                       {"vtktypeuint8", 1, ScalarType::Unsigned},
                                       {"vtktypeint16", 2, ScalarType::Signed},
                                       {"vtktypeuint16", 2, ScalarType::Unsigned},
                                       {"vtktypeint32", 4, ScalarType::Signed},
                                       {"vtktypeuint32", 4, ScalarType::Unsigned},
                                       {"vtktypeint64", 8, ScalarType::Signed},
                                       {"vtktypeuint64", 8, ScalarType::Unsigned},
                                       {"float", 4, ScalarType::Real},
                                       {"double", 8, ScalarType::Real},
                                       {"vtktypefloat32", 4, ScalarType::Real},
                                       {"vtktypefloat64", 8, ScalarType::Real}};

/// Classic-layout binary cell arrays are big-endian 32-bit ints.
constexpr ScalarType kClassicCellType = {"int", 4, ScalarType::Signed};

std::string lowerCase(std::string_view text) {
  std::string result(text);
  for (char& c : result) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return result;
}

std::string upperCase(std::string_view text) {
  std::string result(text);
  for (char& c : result) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return result;
}

bool isSpace(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f';
}

/// Reads tokens, lines and binary values from the file, tracking the location of the last
/// thing read: a line number in ASCII files, a byte offset in binary ones.
class Cursor {
 public:
  Cursor(const std::string& path, std::string_view bytes) : path_(path), bytes_(bytes) {}

  void setBinary() { binary_ = true; }

  std::string where() const {
    if (binary_) return "byte offset " + std::to_string(mark_);
    return "line " + std::to_string(markLine_);
  }

  [[noreturn]] void fail(const std::string& what) const { throw InputError(path_, where(), what); }

  size_t remaining() const { return bytes_.size() - pos_; }

  /// Next whitespace-separated token ("" at end of file).
  std::string_view token() {
    skipSpace();
    markHere();
    const size_t start = pos_;
    while (pos_ < bytes_.size() && !isSpace(bytes_[pos_])) ++pos_;
    return bytes_.substr(start, pos_ - start);
  }

  /// The rest of the current line without its line break; consumes the break.
  std::string_view line() {
    markHere();
    const size_t start = pos_;
    while (pos_ < bytes_.size() && bytes_[pos_] != '\n') ++pos_;
    std::string_view text = bytes_.substr(start, pos_ - start);
    if (pos_ < bytes_.size()) {
      ++pos_;
      ++line_;
    }
    if (!text.empty() && text.back() == '\r') text.remove_suffix(1);
    return text;
  }

  /// Ends a keyword line: only blanks may follow before the line break. Binary data starts
  /// right after the break, so nothing beyond it may be skipped.
  void endLine() {
    while (pos_ < bytes_.size() &&
           (bytes_[pos_] == ' ' || bytes_[pos_] == '\t' || bytes_[pos_] == '\r')) {
      ++pos_;
    }
    if (pos_ >= bytes_.size()) return;
    if (bytes_[pos_] != '\n') {
      markHere();
      fail("expected the end of the line, found " + quoted(bytes_.substr(pos_, 16)));
    }
    ++pos_;
    ++line_;
  }

  /// True (and consumed) when the next token is `keyword`, compared case-insensitively.
  bool acceptKeyword(std::string_view keyword) {
    const size_t savedPos = pos_, savedLine = line_, savedMark = mark_, savedMarkLine = markLine_;
    if (upperCase(token()) == keyword) return true;
    pos_ = savedPos;
    line_ = savedLine;
    mark_ = savedMark;
    markLine_ = savedMarkLine;
    return false;
  }

  uint64_t count(std::string_view what) {
    const std::string_view text = token();
    uint64_t value = 0;
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (text.empty() || error != std::errc() || end != text.data() + text.size()) {
      fail("expected " + std::string(what) + " (a non-negative integer), found " + describe(text));
    }
    return value;
  }

  const ScalarType& scalarType(bool integerOnly) {
    const std::string_view text = token();
    const std::string name = lowerCase(text);
    for (const ScalarType& type : kScalarTypes) {
      if (type.name == name && (!integerOnly || type.kind != ScalarType::Real)) return type;
    }
    fail(std::string("expected a ") + (integerOnly ? "integer " : "") +
         "data type (float, double, int, vtkIdType, vtktypeint64, ...), found " + describe(text));
  }

  /// Fails unless `values` values of `bytesEach` bytes (binary) or at least `values` tokens
  /// (ASCII, two bytes each at the least) can still be in the file.
  void requireValues(uint64_t values, int bytesEach, std::string_view what) {
    const uint64_t possible = binary_ ? remaining() / static_cast<uint64_t>(bytesEach)
                                      : (static_cast<uint64_t>(remaining()) + 1) / 2;
    if (values > possible) {
      fail("the header announces " + std::to_string(values) + " " + std::string(what) +
           " but only " + std::to_string(remaining()) + " bytes are left in the file");
    }
  }

  double real(const ScalarType& type) {
    if (binary_) return decode(type, rawValue(type));
    const std::string_view text = token();
    double value = 0;
    if (!parseReal(text, value)) fail("expected a number, found " + describe(text));
    return value;
  }

  int64_t integer(const ScalarType& type) {
    if (binary_) {
      const uint64_t raw = rawValue(type);
      if (type.kind == ScalarType::Unsigned) {
        return raw > uint64_t(INT64_MAX) ? INT64_MAX : static_cast<int64_t>(raw);
      }
      const int unused = 64 - 8 * type.bytes;
      return static_cast<int64_t>(raw << unused) >> unused;
    }
    const std::string_view text = token();
    int64_t value = 0;
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (text.empty() || error != std::errc() || end != text.data() + text.size()) {
      fail("expected an integer, found " + describe(text));
    }
    return value;
  }

  /// For an out-of-range binary integer: a hint when its bytes read little-endian would fit.
  std::string endiannessHint(int64_t lowest, int64_t highest) const {
    if (!binary_ || lastBytes_ < 2) return "";
    uint64_t swapped = 0;
    for (int i = 0; i < lastBytes_; ++i) swapped = (swapped << 8) | ((lastRaw_ >> (8 * i)) & 0xff);
    const int unused = 64 - 8 * lastBytes_;
    const int64_t value = static_cast<int64_t>(swapped << unused) >> unused;
    if (value < lowest || value > highest) return "";
    return " (read little-endian it would be " + std::to_string(value) +
           ": legacy VTK binary data must be big-endian)";
  }

  /// Skips `values` values of `type` (data this reader does not use).
  void skipValues(uint64_t values, const ScalarType& type) {
    requireValues(values, type.bytes, "values");
    if (binary_) {
      pos_ += values * static_cast<uint64_t>(type.bytes);
      return;
    }
    for (uint64_t i = 0; i < values; ++i) {
      if (token().empty()) fail("expected a value, found the end of the file");
    }
  }

  /// A METADATA block runs to the first blank line.
  void skipMetadataBlock() {
    line();  // the rest of the METADATA line
    while (pos_ < bytes_.size()) {
      const std::string_view text = line();
      if (std::all_of(text.begin(), text.end(), isSpace)) return;
    }
  }

 private:
  void skipSpace() {
    while (pos_ < bytes_.size() && isSpace(bytes_[pos_])) {
      if (bytes_[pos_] == '\n') ++line_;
      ++pos_;
    }
  }

  void markHere() {
    mark_ = pos_;
    markLine_ = line_;
  }

  uint64_t rawValue(const ScalarType& type) {
    markHere();
    if (remaining() < static_cast<size_t>(type.bytes)) {
      fail("expected a " + std::to_string(type.bytes) + "-byte big-endian " +
           std::string(type.name) + ", found the end of the file");
    }
    uint64_t raw = 0;
    for (int i = 0; i < type.bytes; ++i) {
      raw = (raw << 8) | static_cast<unsigned char>(bytes_[pos_ + static_cast<size_t>(i)]);
    }
    pos_ += static_cast<size_t>(type.bytes);
    lastRaw_ = raw;
    lastBytes_ = type.bytes;
    return raw;
  }

  static double decode(const ScalarType& type, uint64_t raw) {
    switch (type.kind) {
      case ScalarType::Real:
        return type.bytes == 4 ? double(std::bit_cast<float>(static_cast<uint32_t>(raw)))
                               : std::bit_cast<double>(raw);
      case ScalarType::Unsigned:
        return static_cast<double>(raw);
      case ScalarType::Signed:
        break;
    }
    const int unused = 64 - 8 * type.bytes;
    return static_cast<double>(static_cast<int64_t>(raw << unused) >> unused);
  }

  static std::string describe(std::string_view text) {
    return text.empty() ? std::string("the end of the file") : quoted(text);
  }

  const std::string& path_;
  std::string_view bytes_;
  size_t pos_ = 0;
  size_t line_ = 1;      ///< line of pos_ (meaningful in ASCII files)
  size_t mark_ = 0;      ///< byte offset of the last token or value read
  size_t markLine_ = 1;  ///< line of the last token or value read
  bool binary_ = false;
  uint64_t lastRaw_ = 0;  ///< bytes of the last binary value, as read big-endian
  int lastBytes_ = 0;     ///< size of the last binary value
};

/// Reads the sections of a POLYDATA data set into `data`.
class PolyDataReader {
 public:
  PolyDataReader(Cursor& in, double scale) : in_(in), scale_(scale) {}

  VtkPolyData read() {
    readHeader();
    while (true) {
      const std::string_view keyword = in_.token();
      if (keyword.empty()) break;
      const std::string name = upperCase(keyword);
      if (name == "POINTS") {
        readPoints();
      } else if (name == "POLYGONS" || name == "TRIANGLE_STRIPS" || name == "LINES" ||
                 name == "VERTICES") {
        readCells(name);
      } else if (name == "METADATA") {
        in_.skipMetadataBlock();
      } else if (name == "FIELD") {
        skipField();
      } else if (name == "CELL_DATA" || name == "POINT_DATA") {
        break;  // attributes: not needed for geometry
      } else {
        in_.fail(
            "expected POINTS, POLYGONS, TRIANGLE_STRIPS, LINES, VERTICES, METADATA, FIELD, "
            "CELL_DATA or POINT_DATA, found " +
            quoted(keyword));
      }
    }
    if (!havePoints_) in_.fail("expected a POINTS section, found the end of the file");
    if (skippedCells_ > kListedSkips)
      data_.warnings.push_back("... and " + std::to_string(skippedCells_ - kListedSkips) +
                               " more cells with fewer than 3 points skipped (" +
                               std::to_string(skippedCells_) + " in all)");
    return std::move(data_);
  }

 private:
  void readHeader() {
    const std::string_view first = in_.line();
    if (!looksLikeLegacyVtk(first)) {
      in_.fail("expected a legacy VTK header '# vtk DataFile Version x.x', found " +
               quoted(first.substr(0, 40)));
    }
    in_.line();  // title, any text
    const std::string_view format = in_.token();
    const std::string formatName = upperCase(format);
    if (formatName == "BINARY") {
      in_.setBinary();
    } else if (formatName != "ASCII") {
      in_.fail("expected ASCII or BINARY, found " + quoted(format));
    }
    const std::string_view dataset = in_.token();
    if (upperCase(dataset) != "DATASET") in_.fail("expected DATASET, found " + quoted(dataset));
    const std::string_view type = in_.token();
    if (upperCase(type) != "POLYDATA") {
      in_.fail("expected DATASET POLYDATA (surfaces and lines), found DATASET " + quoted(type));
    }
  }

  void readPoints() {
    if (havePoints_) in_.fail("expected one POINTS section, found a second one");
    const uint64_t count = in_.count("a point count");
    const ScalarType& type = in_.scalarType(false);
    in_.endLine();
    if (count > UINT32_MAX) {
      in_.fail("expected at most 2^32-1 points, found a count of " + std::to_string(count));
    }
    in_.requireValues(3 * count, type.bytes, "point coordinates");
    data_.points.reserve(count);
    for (uint64_t i = 0; i < count; ++i) {
      double xyz[3];
      for (double& value : xyz) value = in_.real(type) * scale_;
      const btVector3 point(static_cast<btScalar>(xyz[0]), static_cast<btScalar>(xyz[1]),
                            static_cast<btScalar>(xyz[2]));
      if (!std::isfinite(point.x()) || !std::isfinite(point.y()) || !std::isfinite(point.z())) {
        in_.fail("point " + std::to_string(i) + ": expected finite coordinates, found (" +
                 std::to_string(xyz[0]) + ", " + std::to_string(xyz[1]) + ", " +
                 std::to_string(xyz[2]) + ")");
      }
      data_.points.push_back(point);
    }
    havePoints_ = true;
  }

  void readCells(const std::string& kind) {
    const uint64_t first = in_.count("a cell count");
    const uint64_t second = in_.count("a cell array size");
    in_.endLine();
    if (!havePoints_) in_.fail("expected POINTS before " + kind);
    if (in_.acceptKeyword("OFFSETS")) {
      readOffsetCells(kind, first, second);
    } else {
      readClassicCells(kind, first, second);
    }
  }

  /// Classic layout: `size` integers, each cell its point count followed by its indices.
  void readClassicCells(const std::string& kind, uint64_t cells, uint64_t size) {
    in_.requireValues(size, kClassicCellType.bytes, kind + " values");
    if (cells > size) {
      in_.fail("expected a cell array size of at least the cell count (" + std::to_string(cells) +
               "), found " + std::to_string(size));
    }
    uint64_t used = 0;
    for (uint64_t cell = 0; cell < cells; ++cell) {
      const int64_t pointCount = in_.integer(kClassicCellType);
      const std::string location = in_.where();
      if (pointCount < 0 || static_cast<uint64_t>(pointCount) + 1 > size - used) {
        in_.fail(kind + " cell " + std::to_string(cell) + ": expected a point count from 0 to " +
                 std::to_string(size - used - 1) + " (what is left of the " + std::to_string(size) +
                 " values the header announces), found " + std::to_string(pointCount) +
                 in_.endiannessHint(0, static_cast<int64_t>(size - used) - 1));
      }
      used += static_cast<uint64_t>(pointCount) + 1;
      cell_.clear();
      for (int64_t k = 0; k < pointCount; ++k) {
        cell_.push_back(index(kind, cell, in_.integer(kClassicCellType)));
      }
      addCell(kind, cell, location);
    }
    if (used != size) {
      in_.fail("the " + std::to_string(cells) + " " + kind + " cells hold " + std::to_string(used) +
               " values, expected " + std::to_string(size) + " as the header announces");
    }
  }

  /// VTK 5.1 layout: OFFSETS (cells + 1 values, from 0 to the connectivity size), then
  /// CONNECTIVITY.
  void readOffsetCells(const std::string& kind, uint64_t offsetCount, uint64_t connectivitySize) {
    const ScalarType& offsetType = in_.scalarType(true);
    in_.endLine();
    in_.requireValues(offsetCount, offsetType.bytes, "offsets");
    std::vector<uint64_t> offsets;
    offsets.reserve(offsetCount);
    for (uint64_t i = 0; i < offsetCount; ++i) {
      const int64_t offset = in_.integer(offsetType);
      const uint64_t previous = offsets.empty() ? 0 : offsets.back();
      if (offset < 0 || static_cast<uint64_t>(offset) < previous ||
          static_cast<uint64_t>(offset) > connectivitySize || (i == 0 && offset != 0)) {
        in_.fail(kind + " offset " + std::to_string(i) + ": expected " +
                 (i == 0 ? std::string("0")
                         : "a value from " + std::to_string(previous) + " to " +
                               std::to_string(connectivitySize)) +
                 ", found " + std::to_string(offset));
      }
      offsets.push_back(static_cast<uint64_t>(offset));
    }
    const uint64_t last = offsets.empty() ? 0 : offsets.back();
    if (last != connectivitySize) {
      in_.fail(kind + ": expected the last offset to equal the connectivity size " +
               std::to_string(connectivitySize) + ", found " + std::to_string(last));
    }
    if (!in_.acceptKeyword("CONNECTIVITY")) in_.fail("expected CONNECTIVITY after the OFFSETS");
    const ScalarType& indexType = in_.scalarType(true);
    in_.endLine();
    in_.requireValues(connectivitySize, indexType.bytes, "connectivity values");
    for (size_t cell = 0; cell + 1 < offsets.size(); ++cell) {
      cell_.clear();
      std::string location;
      for (uint64_t k = offsets[cell]; k < offsets[cell + 1]; ++k) {
        cell_.push_back(index(kind, cell, in_.integer(indexType)));
        if (location.empty()) location = in_.where();
      }
      if (location.empty()) location = in_.where();
      addCell(kind, cell, location);
    }
  }

  uint32_t index(const std::string& kind, uint64_t cell, int64_t value) {
    if (value < 0 || static_cast<uint64_t>(value) >= data_.points.size()) {
      in_.fail(kind + " cell " + std::to_string(cell) + ": expected a point index from 0 to " +
               std::to_string(data_.points.size()) + "-1, found " + std::to_string(value) +
               in_.endiannessHint(0, static_cast<int64_t>(data_.points.size()) - 1));
    }
    return static_cast<uint32_t>(value);
  }

  void addCell(const std::string& kind, uint64_t cell, const std::string& location) {
    if (kind == "VERTICES") return;
    if (kind == "LINES") {
      auto& lines = data_.lines;
      if (lines.indices.size() + cell_.size() > UINT32_MAX) in_.fail("expected fewer LINES points");
      lines.indices.insert(lines.indices.end(), cell_.begin(), cell_.end());
      lines.offsets.push_back(static_cast<uint32_t>(lines.indices.size()));
      lines.origins.push_back("LINES cell " + std::to_string(cell) + " (" + location + ")");
      return;
    }
    if (cell_.size() < 3) {
      if (++skippedCells_ > kListedSkips) return;  // counted, summed up at the end
      data_.warnings.push_back(kind + " cell " + std::to_string(cell) + " (" + location + ") has " +
                               std::to_string(cell_.size()) +
                               " points, expected at least 3; skipped");
      return;
    }
    if (kind == "POLYGONS") {
      appendPolygon(data_.triangles, cell_);
    } else {
      appendStrip(data_.triangles, cell_);
    }
  }

  /// FIELD name arrayCount, then per array: name components tuples type, its values, and an
  /// optional METADATA block.
  void skipField() {
    in_.token();  // field name
    const uint64_t arrays = in_.count("an array count");
    in_.endLine();
    for (uint64_t a = 0; a < arrays; ++a) {
      const std::string_view name = in_.token();
      if (name.empty()) in_.fail("expected a FIELD array, found the end of the file");
      if (upperCase(name) == "NULL_ARRAY") continue;
      const uint64_t components = in_.count("a component count");
      const uint64_t tuples = in_.count("a tuple count");
      const ScalarType& type = in_.scalarType(false);
      in_.endLine();
      if (components != 0 && tuples > std::numeric_limits<uint64_t>::max() / components) {
        in_.fail("expected a FIELD array of a size that fits in memory");
      }
      in_.skipValues(components * tuples, type);
      if (in_.acceptKeyword("METADATA")) in_.skipMetadataBlock();
    }
  }

  Cursor& in_;
  double scale_;
  VtkPolyData data_;
  bool havePoints_ = false;
  std::vector<uint32_t> cell_;  ///< point indices of the cell being read
  /// Skipped cells named one by one before a count (2 000 000 empty cells: 11 lines, not 2 M).
  static constexpr size_t kListedSkips = 10;
  size_t skippedCells_ = 0;  ///< cells with fewer than 3 points
};

}  // namespace

bool looksLikeLegacyVtk(std::string_view bytes) {
  constexpr std::string_view kMagic = "# vtk DataFile Version";
  if (bytes.size() < kMagic.size()) return false;
  return lowerCase(bytes.substr(0, kMagic.size())) == lowerCase(kMagic);
}

VtkPolyData readLegacyVtk(const std::string& path, std::string_view bytes, double scale) {
  Cursor in(path, bytes);
  return PolyDataReader(in, scale).read();
}

const MeshFormatRegistration registration(vtkFormat<readLegacyVtk>("legacy VTK", ".vtk", "LINES",
                                                                   looksLikeLegacyVtk));

}  // namespace fibremss::meshio
