// VTK XML PolyData reader (.vtp, as OpenSim and ParaView write it): inline ascii, inline binary
// (base64, raw or vtkZLibDataCompressor blocks, UInt32 or UInt64 headers, either byte order)
// and appended data (raw or base64). Every count is checked against the bytes that can hold it
// before anything is allocated, and every index against the point count.
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <span>
#include <unordered_map>

#include "MeshIOInternal.h"
#include "XmlTags.h"
#include "fibremss/Error.h"

namespace fibremss::meshio {
namespace {

/// deflate expands at most about 1032:1; a header announcing more is not a zlib stream.
constexpr uint64_t kMaxInflation = 1032;

/// A DataArray element: the section it sits in (Points, Polys, ...) and where its text is.
struct ArrayElement {
  std::string section;  ///< Points, Verts, Lines, Strips, Polys, PointData, CellData, ...
  size_t piece = 0;     ///< index of its Piece
  Attributes attributes;
  size_t begin = 0, end = 0;  ///< its text content in the file
  size_t line = 0;            ///< line of its start tag
};

struct Piece {
  Attributes attributes;
  size_t line = 0;
  size_t firstArray = 0, endArray = 0;  ///< its DataArrays lie in arrays_[firstArray, endArray)
};

/// Values one file may declare in all: 64 Mi (about 20 million points with their triangles;
/// 768 MiB while decoded). Counted before an array is inflated or decoded, so a small file
/// declaring more (a zip bomb) is refused at once.
constexpr uint64_t kMaxValues = uint64_t(1) << 26;

/// Where the encoded bytes of one array come from: base64 text (inline, or appended with
/// encoding="base64") or raw bytes (appended). Base64 is decoded quartet by quartet, so that
/// a header encoded apart from its data (padding in the middle) reads like one stream.
class ByteSource {
 public:
  ByteSource(std::string_view data, bool base64) : data_(data), base64_(base64) {}

  /// At most this many bytes can still come.
  uint64_t available() const {
    return base64_ ? (data_.size() - pos_) / 4 * 3 + pending_.size() - taken_ : data_.size() - pos_;
  }

  /// The next `count` bytes; false when the data ends first or is not base64.
  bool take(uint64_t count, std::string& out) {
    out.clear();
    if (count > available()) return false;
    if (!base64_) {
      out.assign(data_.substr(pos_, count));
      pos_ += count;
      return true;
    }
    while (pending_.size() - taken_ < count)
      if (!decodeQuartet()) return false;
    out.assign(pending_, taken_, count);
    taken_ += count;
    if (taken_ == pending_.size()) pending_.clear(), taken_ = 0;
    return true;
  }

 private:
  static int sextet(char c) {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  }

  bool decodeQuartet() {
    char quartet[4];
    for (char& c : quartet) {
      while (pos_ < data_.size() && isBlank(data_[pos_])) ++pos_;
      if (pos_ >= data_.size()) return false;
      c = data_[pos_++];
    }
    uint32_t bits = 0;
    int bytes = 3;
    for (int i = 0; i < 4; ++i) {
      const int value = sextet(quartet[i]);
      if (value < 0 && !(quartet[i] == '=' && i >= 2)) return false;
      if (quartet[i] == '=') bytes = std::min(bytes, i - 1);
      bits = (bits << 6) | uint32_t(std::max(value, 0));
    }
    for (int i = 0; i < bytes; ++i) pending_ += char((bits >> (16 - 8 * i)) & 0xff);
    return true;
  }

  std::string_view data_;
  bool base64_;
  size_t pos_ = 0;
  std::string pending_;  ///< decoded, not yet taken
  size_t taken_ = 0;
};

/// The element types of DataArray's `type`.
struct ElementType {
  std::string_view name;
  int bytes;
  enum Kind { Signed, Unsigned, Real } kind;
};
constexpr ElementType kTypes[] = {
    {"Int8", 1, ElementType::Signed},  {"UInt8", 1, ElementType::Unsigned},
    {"Int16", 2, ElementType::Signed}, {"UInt16", 2, ElementType::Unsigned},
    {"Int32", 4, ElementType::Signed}, {"UInt32", 4, ElementType::Unsigned},
    {"Int64", 8, ElementType::Signed}, {"UInt64", 8, ElementType::Unsigned},
    {"Float32", 4, ElementType::Real}, {"Float64", 8, ElementType::Real}};

class XmlPolyDataReader {
 public:
  XmlPolyDataReader(const std::string& path, std::string_view bytes, double scale)
      : path_(path), bytes_(bytes), scale_(scale), tags_(path, xmlPart(bytes)) {}

  VtkPolyData read() {
    collectElements();
    if (pieces_.empty()) tags_.fail(0, "expected a <Piece> inside <PolyData>");
    for (size_t p = 0; p < pieces_.size(); ++p) readPiece(p);
    return std::move(data_);
  }

 private:
  /// The XML text: up to the raw bytes of AppendedData, which may hold anything.
  static std::string_view xmlPart(std::string_view bytes) {
    const size_t appended = bytes.find("<AppendedData");
    return appended == std::string_view::npos ? bytes : bytes.substr(0, appended);
  }

  [[noreturn]] void failArray(const ArrayElement& array, const std::string& what) const {
    throw InputError(path_,
                     "line " + std::to_string(array.line) + " (DataArray \"" +
                         array.attributes.get("Name", "") + "\" of " + array.section + ")",
                     what);
  }

  void collectElements() {
    std::vector<std::string> sections;
    bool sawFile = false;
    auto open = [&](const std::string& name, const Attributes& attributes, size_t start,
                    size_t contentBegin, bool selfClosing) {
      if (name == "VTKFile") {
        sawFile = true;
        readFileAttributes(attributes, start);
      } else if (name == "Piece") {
        pieces_.push_back({attributes, tags_.lineAt(start), arrays_.size(), arrays_.size()});
      } else if (name == "DataArray") {
        // Outside a Piece (FieldData of the whole data set): kept for nesting, never used.
        const size_t piece = pieces_.empty() ? SIZE_MAX : pieces_.size() - 1;
        ArrayElement array{sections.empty() ? "" : sections.back(),
                           piece,
                           attributes,
                           contentBegin,
                           contentBegin,
                           tags_.lineAt(start)};
        requireOwnOffset(array, start);
        arrays_.push_back(std::move(array));
        if (piece != SIZE_MAX) pieces_[piece].endArray = arrays_.size();
        if (selfClosing) return;
      }
      if (!selfClosing) sections.push_back(name);
    };
    auto close = [&](const std::string& name, size_t start) {
      sections.pop_back();
      if (name == "DataArray") arrays_.back().end = start;
    };
    tags_.scan(open, close, bytes_.find("<AppendedData") != std::string_view::npos);
    if (!sawFile) tags_.fail(0, "expected a <VTKFile type=\"PolyData\"> element");
    findAppendedData();
  }

  /// Refuses an appended DataArray at the offset of an earlier one: VTK writes each array's data
  /// once, and a file whose arrays share it would be read again and again.
  void requireOwnOffset(const ArrayElement& array, size_t start) {
    if (array.attributes.get("format") != "appended") return;
    const auto [earlier, added] = offsets_.emplace(array.attributes.get("offset"), array.line);
    if (!added)
      tags_.fail(start, "expected each appended DataArray at its own offset; offset " +
                            earlier->first + " is also that of the DataArray on line " +
                            std::to_string(earlier->second));
  }

  void readFileAttributes(const Attributes& attributes, size_t start) {
    const std::string type = attributes.get("type");
    if (type != "PolyData")
      tags_.fail(start, "expected VTKFile type=\"PolyData\" (a .vtp), found \"" + type + "\"");
    const std::string order = attributes.get("byte_order", "LittleEndian");
    if (order != "LittleEndian" && order != "BigEndian")
      tags_.fail(start, "expected byte_order LittleEndian or BigEndian, found \"" + order + "\"");
    bigEndian_ = order == "BigEndian";
    const std::string header = attributes.get("header_type", "UInt32");
    if (header != "UInt32" && header != "UInt64")
      tags_.fail(start, "expected header_type UInt32 or UInt64, found \"" + header + "\"");
    headerBytes_ = header == "UInt64" ? 8 : 4;
    const std::string compressor = attributes.get("compressor");
    if (!compressor.empty() && compressor != "vtkZLibDataCompressor")
      compressorError_ =
          "expected no compressor or vtkZLibDataCompressor, found \"" + compressor + "\"";
    compressed_ = !compressor.empty();
  }

  void findAppendedData() {
    const size_t tag = bytes_.find("<AppendedData");
    if (tag == std::string_view::npos) return;
    const size_t close = bytes_.find('>', tag);
    const size_t underscore = bytes_.find('_', close == std::string_view::npos ? tag : close);
    if (close == std::string_view::npos || underscore == std::string_view::npos)
      tags_.fail(tag, "expected <AppendedData encoding=\"raw\"> followed by '_' and the data");
    const std::string_view tagText = bytes_.substr(tag, close - tag);
    appendedBase64_ = tagText.find("\"base64\"") != std::string_view::npos;
    if (!appendedBase64_ && tagText.find("\"raw\"") == std::string_view::npos)
      tags_.fail(tag, "expected AppendedData encoding=\"raw\" or encoding=\"base64\"");
    appended_ = bytes_.substr(underscore + 1);
    haveAppended_ = true;
  }

  uint64_t count(const Piece& piece, const std::string& key) const {
    const std::string text = piece.attributes.get(key, "0");
    uint64_t value = 0;
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (text.empty() || error != std::errc() || end != text.data() + text.size() ||
        value > UINT32_MAX)
      throw InputError(
          path_, "line " + std::to_string(piece.line),
          "expected Piece " + key + " to be an integer from 0 to 2^32-1, found \"" + text + "\"");
    return value;
  }

  /// The DataArrays of piece `p`.
  std::span<const ArrayElement> arraysOf(size_t p) const {
    return std::span(arrays_).subspan(pieces_[p].firstArray,
                                      pieces_[p].endArray - pieces_[p].firstArray);
  }

  const ArrayElement* find(size_t piece, const std::string& section, const std::string& name) {
    for (const ArrayElement& array : arraysOf(piece))
      if (array.piece == piece && array.section == section &&
          (name.empty() || array.attributes.get("Name") == name))
        return &array;
    return nullptr;
  }

  /// Counts `count` values of `array` against kMaxValues before they are read.
  void spend(const ArrayElement& array, uint64_t count) {
    if (count > kMaxValues - valuesRead_)
      failArray(array, "declares " + std::to_string(count) + " values, beyond the " +
                           std::to_string(kMaxValues) + " one file may hold in all (" +
                           std::to_string(valuesRead_) + " read before it)");
    valuesRead_ += count;
  }

  void readPiece(size_t p) {
    const Piece& piece = pieces_[p];
    const uint64_t points = count(piece, "NumberOfPoints");
    const size_t base = data_.points.size();
    if (points > 0) {
      const ArrayElement* array = find(p, "Points", "");
      if (!array)
        throw InputError(
            path_, "line " + std::to_string(piece.line),
            "expected a <Points> DataArray for NumberOfPoints=" + std::to_string(points));
      if (array->attributes.get("NumberOfComponents", "1") != "3")
        failArray(*array, "expected NumberOfComponents=\"3\" (x, y, z)");
      const std::vector<double> xyz = reals(*array, 3 * points);
      if (base + points > UINT32_MAX) failArray(*array, "expected at most 2^32-1 points in all");
      for (uint64_t i = 0; i < points; ++i) {
        const btVector3 point(btScalar(xyz[3 * i] * scale_), btScalar(xyz[3 * i + 1] * scale_),
                              btScalar(xyz[3 * i + 2] * scale_));
        if (!std::isfinite(point.x()) || !std::isfinite(point.y()) || !std::isfinite(point.z()))
          failArray(*array, "point " + std::to_string(i) + ": expected finite coordinates");
        data_.points.push_back(point);
      }
    }
    for (const char* section : {"Polys", "Strips", "Lines"}) {
      const std::string key = std::string("NumberOf") + section;
      const uint64_t cells = count(piece, key);
      if (cells > 0) readCells(p, section, cells, base, size_t(points));
    }
    readPointData(p, points);
  }

  /// The piece's PointData arrays appended to those of the pieces before it; an array some
  /// piece lacks is dropped.
  void readPointData(size_t p, uint64_t points) {
    std::vector<PointArray> arrays;
    for (const ArrayElement& array : arraysOf(p)) {
      if (array.piece != p || array.section != "PointData") continue;
      const std::string components = array.attributes.get("NumberOfComponents", "1");
      int n = 0;
      const auto [end, error] =
          std::from_chars(components.data(), components.data() + components.size(), n);
      if (error != std::errc() || end != components.data() + components.size() || n < 1 || n > 16)
        failArray(array, "expected NumberOfComponents from 1 to 16, found \"" + components + "\"");
      PointArray read{array.attributes.get("Name"), n, {}};
      for (double value : reals(array, uint64_t(n) * points)) read.values.push_back(float(value));
      arrays.push_back(std::move(read));
    }
    if (p == 0) {
      data_.pointData = std::move(arrays);
      return;
    }
    std::unordered_map<std::string, const PointArray*> byName;
    for (const PointArray& array : arrays) byName.emplace(array.name, &array);
    std::erase_if(data_.pointData, [&](PointArray& kept) {
      const auto same = byName.find(kept.name);
      if (same == byName.end() || same->second->components != kept.components) return true;
      kept.values.insert(kept.values.end(), same->second->values.begin(),
                         same->second->values.end());
      return false;
    });
  }

  void readCells(size_t p, const std::string& section, uint64_t cells, size_t base, size_t points) {
    const ArrayElement* offsetArray = find(p, section, "offsets");
    const ArrayElement* connectivityArray = find(p, section, "connectivity");
    if (!offsetArray || !connectivityArray)
      throw InputError(path_, "line " + std::to_string(pieces_[p].line),
                       "expected <" + section +
                           "> with DataArrays \"connectivity\" and \"offsets\" for " +
                           std::to_string(cells) + " cells");
    const std::vector<int64_t> offsets = integers(*offsetArray, cells);
    int64_t previous = 0;
    for (uint64_t c = 0; c < cells; ++c) {
      if (offsets[c] < previous)
        failArray(*offsetArray, "offset " + std::to_string(c) + ": expected at least " +
                                    std::to_string(previous) + ", found " +
                                    std::to_string(offsets[c]));
      previous = offsets[c];
    }
    const std::vector<int64_t> connectivity = integers(*connectivityArray, uint64_t(previous));
    int64_t begin = 0;
    for (uint64_t c = 0; c < cells; ++c) {
      cell_.clear();
      for (int64_t k = begin; k < offsets[c]; ++k) {
        if (connectivity[size_t(k)] < 0 || uint64_t(connectivity[size_t(k)]) >= points)
          failArray(*connectivityArray, section + " cell " + std::to_string(c) +
                                            ": expected a point index from 0 to " +
                                            std::to_string(points) + "-1, found " +
                                            std::to_string(connectivity[size_t(k)]));
        cell_.push_back(uint32_t(base + size_t(connectivity[size_t(k)])));
      }
      begin = offsets[c];
      addCell(section, c, connectivityArray->line);
    }
  }

  void addCell(const std::string& section, uint64_t cell, size_t line) {
    const std::string origin =
        section + " cell " + std::to_string(cell) + " (line " + std::to_string(line) + ")";
    if (section == "Lines") {
      auto& lines = data_.lines;
      if (lines.indices.size() + cell_.size() > UINT32_MAX)
        throw InputError(path_, origin, "expected fewer Lines points");
      lines.indices.insert(lines.indices.end(), cell_.begin(), cell_.end());
      lines.offsets.push_back(uint32_t(lines.indices.size()));
      lines.origins.push_back(origin);
    } else if (cell_.size() < 3) {
      data_.warnings.push_back(origin + " has " + std::to_string(cell_.size()) +
                               " points, expected at least 3; skipped");
    } else if (section == "Polys") {
      appendPolygon(data_.triangles, cell_);
    } else {
      appendStrip(data_.triangles, cell_);
    }
  }

  const ElementType& typeOf(const ArrayElement& array, bool integerOnly) const {
    const std::string name = array.attributes.get("type");
    for (const ElementType& type : kTypes)
      if (type.name == name && (!integerOnly || type.kind != ElementType::Real)) return type;
    failArray(array, std::string("expected type ") +
                         (integerOnly ? "Int8 ... UInt64" : "Float32, Float64, Int8 ... UInt64") +
                         ", found \"" + name + "\"");
  }

  /// The array's `count` values as doubles (any type) or integers (integer types only).
  std::vector<double> reals(const ArrayElement& array, uint64_t count) {
    const ElementType& type = typeOf(array, false);
    std::vector<double> values;
    if (array.attributes.get("format") == "ascii") {
      forEachToken(array, count, [&](std::string_view token) {
        double value;
        if (!parseReal(token, value)) failArray(array, "expected a number, found " + quoted(token));
        values.push_back(value);
      });
      return values;
    }
    const std::string raw = binary(array, count, type);
    for (uint64_t i = 0; i < count; ++i) values.push_back(decodeReal(raw, i, type));
    return values;
  }

  std::vector<int64_t> integers(const ArrayElement& array, uint64_t count) {
    const ElementType& type = typeOf(array, true);
    std::vector<int64_t> values;
    if (array.attributes.get("format") == "ascii") {
      forEachToken(array, count, [&](std::string_view token) {
        int64_t value = 0;
        const auto [end, error] = std::from_chars(token.data(), token.data() + token.size(), value);
        if (error != std::errc() || end != token.data() + token.size())
          failArray(array, "expected an integer, found " + quoted(token));
        values.push_back(value);
      });
      return values;
    }
    const std::string raw = binary(array, count, type);
    for (uint64_t i = 0; i < count; ++i) values.push_back(decodeInteger(raw, i, type));
    return values;
  }

  template <typename Each>
  void forEachToken(const ArrayElement& array, uint64_t count, Each&& each) {
    const std::string_view text = bytes_.substr(array.begin, array.end - array.begin);
    if (count > (text.size() + 1) / 2)
      failArray(array, "expected " + std::to_string(count) + " values, but its text holds only " +
                           std::to_string(text.size()) + " bytes");
    spend(array, count);
    uint64_t found = 0;
    for (size_t at = 0; at < text.size();) {
      while (at < text.size() && isBlank(text[at])) ++at;
      const size_t start = at;
      while (at < text.size() && !isBlank(text[at])) ++at;
      if (at == start) break;
      if (++found > count) break;
      each(text.substr(start, at - start));
    }
    if (found != count)
      failArray(array, "expected " + std::to_string(count) + " values, found " +
                           (found > count ? "more" : std::to_string(found)));
  }

  /// The array's bytes (count values of `type`), from inline base64 or appended data, through
  /// the header (a byte count, or the zlib block table) and inflated when compressed.
  std::string binary(const ArrayElement& array, uint64_t count, const ElementType& type) {
    const std::string format = array.attributes.get("format");
    if (format != "binary" && format != "appended")
      failArray(array, "expected format ascii, binary or appended, found \"" + format + "\"");
    if (!compressorError_.empty()) failArray(array, compressorError_);
    ByteSource source = sourceOf(array, format == "appended");
    const uint64_t possible = (compressed_ ? kMaxInflation : 1) * source.available();
    if (count > possible / uint64_t(type.bytes))
      failArray(array, "expected " + std::to_string(count) +
                           " values, but the data left can hold " +
                           std::to_string(possible / uint64_t(type.bytes)) + " at most");
    spend(array, count);
    const uint64_t expected = count * uint64_t(type.bytes);
    std::string out;
    if (!compressed_) {
      const uint64_t size = headerWord(array, source);
      if (size != expected)
        failArray(array, "expected " + std::to_string(expected) + " bytes (" +
                             std::to_string(count) + " values), the header says " +
                             std::to_string(size));
      if (!source.take(size, out))
        failArray(array, "expected " + std::to_string(size) + " bytes of data, found " +
                             std::to_string(source.available()) + " (truncated?)");
      return out;
    }
    return inflate(array, source, expected);
  }

  ByteSource sourceOf(const ArrayElement& array, bool appended) {
    if (!appended) return ByteSource(bytes_.substr(array.begin, array.end - array.begin), true);
    if (!haveAppended_) failArray(array, "expected an <AppendedData> section for format appended");
    const std::string text = array.attributes.get("offset");
    uint64_t offset = 0;
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), offset);
    if (text.empty() || error != std::errc() || end != text.data() + text.size() ||
        offset > appended_.size())
      failArray(array, "expected an offset from 0 to " + std::to_string(appended_.size()) +
                           " into the appended data, found \"" + text + "\"");
    return ByteSource(appended_.substr(offset), appendedBase64_);
  }

  uint64_t headerWord(const ArrayElement& array, ByteSource& source) {
    std::string word;
    if (!source.take(uint64_t(headerBytes_), word))
      failArray(array, "expected a " + std::to_string(8 * headerBytes_) +
                           "-bit header, found the end of the data");
    return unsignedValue(word, 0, headerBytes_);
  }

  /// vtkZLibDataCompressor: [blocks, block size, last block size, compressed sizes...], then
  /// the compressed blocks one after another.
  std::string inflate(const ArrayElement& array, ByteSource& source, uint64_t expected) {
    const uint64_t blocks = headerWord(array, source);
    const uint64_t blockSize = headerWord(array, source);
    const uint64_t lastSize = headerWord(array, source);
    if (blocks > source.available() / uint64_t(headerBytes_))
      failArray(array, "expected at most " +
                           std::to_string(source.available() / uint64_t(headerBytes_)) +
                           " compressed blocks in the data left, the header says " +
                           std::to_string(blocks));
    const uint64_t last = lastSize == 0 ? blockSize : lastSize;
    // VTK writes its block size (32768 by default) even when one smaller block holds it all.
    const bool fits = blocks == 0 || (last <= blockSize && (blocks == 1 || blockSize <= expected) &&
                                      blocks - 1 <= expected / std::max<uint64_t>(blockSize, 1));
    const uint64_t total = !fits || blocks == 0 ? 0 : (blocks - 1) * blockSize + last;
    if (!fits || total != expected)
      failArray(array, "expected " + std::to_string(expected) +
                           " bytes once inflated, the compression header says " +
                           std::to_string(blocks) + " blocks of " + std::to_string(blockSize) +
                           " (last " + std::to_string(last) + ")");
    std::vector<uint64_t> sizes(blocks);
    uint64_t compressedTotal = 0;
    for (uint64_t& size : sizes) {
      size = headerWord(array, source);
      compressedTotal += std::min(size, source.available() + 1);
    }
    if (compressedTotal > source.available() || total > kMaxInflation * compressedTotal + 64)
      failArray(array, "expected " + std::to_string(compressedTotal) +
                           " bytes of compressed blocks inflating to " + std::to_string(total) +
                           ", found " + std::to_string(source.available()) + " bytes");
    std::string out(total, '\0'), block;
    uint64_t at = 0;
    for (uint64_t b = 0; b < blocks; ++b) {
      if (!source.take(sizes[b], block))
        failArray(array, "compressed block " + std::to_string(b) + ": expected " +
                             std::to_string(sizes[b]) + " bytes, found the end of the data");
      uLongf length = uLongf(b + 1 == blocks ? last : blockSize);
      const uLongf wanted = length;
      const int status =
          uncompress(reinterpret_cast<Bytef*>(out.data() + at), &length,
                     reinterpret_cast<const Bytef*>(block.data()), uLong(block.size()));
      if (status != Z_OK || length != wanted)
        failArray(array, "compressed block " + std::to_string(b) + " of " + std::to_string(blocks) +
                             ": expected zlib data inflating to " + std::to_string(wanted) +
                             " bytes (zlib: " +
                             (status == Z_OK ? "short" : std::string(zError(status))) + ")");
      at += wanted;
    }
    return out;
  }

  uint64_t unsignedValue(const std::string& raw, uint64_t index, int bytes) const {
    uint64_t value = 0;
    for (int i = 0; i < bytes; ++i) {
      const int at = bigEndian_ ? i : bytes - 1 - i;
      value = (value << 8) |
              static_cast<unsigned char>(raw[size_t(index) * size_t(bytes) + size_t(at)]);
    }
    return value;
  }

  double decodeReal(const std::string& raw, uint64_t index, const ElementType& type) const {
    const uint64_t bits = unsignedValue(raw, index, type.bytes);
    if (type.kind == ElementType::Real)
      return type.bytes == 4 ? double(std::bit_cast<float>(uint32_t(bits)))
                             : std::bit_cast<double>(bits);
    return double(decodeInteger(raw, index, type));
  }

  int64_t decodeInteger(const std::string& raw, uint64_t index, const ElementType& type) const {
    const uint64_t bits = unsignedValue(raw, index, type.bytes);
    if (type.kind == ElementType::Unsigned)
      return bits > uint64_t(INT64_MAX) ? INT64_MAX : int64_t(bits);
    const int unused = 64 - 8 * type.bytes;
    return int64_t(bits << unused) >> unused;
  }

  const std::string& path_;
  std::string_view bytes_;
  double scale_;
  TagScanner tags_;
  std::vector<Piece> pieces_;
  std::vector<ArrayElement> arrays_;
  bool bigEndian_ = false, compressed_ = false, haveAppended_ = false, appendedBase64_ = false;
  std::string compressorError_;
  int headerBytes_ = 4;
  std::string_view appended_;
  VtkPolyData data_;
  std::vector<uint32_t> cell_;
  uint64_t valuesRead_ = 0;                          ///< values of the arrays read so far (spend())
  std::unordered_map<std::string, size_t> offsets_;  ///< appended offsets seen, with their line
};

}  // namespace

bool looksLikeVtkXml(std::string_view bytes) {
  const size_t start = bytes.find_first_not_of(" \t\r\n\xef\xbb\xbf");
  if (start == std::string_view::npos) return false;
  const std::string_view head = bytes.substr(start, 512);
  return (head.substr(0, 5) == "<?xml" || head.substr(0, 8) == "<VTKFile") &&
         head.find("VTKFile") != std::string_view::npos;
}

VtkPolyData readVtkXmlPolyData(const std::string& path, std::string_view bytes, double scale) {
  return XmlPolyDataReader(path, bytes, scale).read();
}

const MeshFormatRegistration registration(vtkFormat<readVtkXmlPolyData>("VTK XML", ".vtp", "Lines",
                                                                        looksLikeVtkXml));

}  // namespace fibremss::meshio
