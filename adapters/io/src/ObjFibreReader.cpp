// Fibres from Wavefront OBJ: `v` points and `l` polylines, read line by line so every error
// names its line. Faces, groups, materials and the other OBJ statements are skipped.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <iterator>

#include "MeshIOInternal.h"
#include "fibremss/Error.h"
#include "fibremss/InputFiles.h"

namespace fibremss::meshio {
namespace {

/// OBJ statements that carry nothing fibres need.
constexpr std::string_view kIgnoredStatements[] = {
    "vt",         "vn",        "vp",     "f",      "fo",     "p",      "o",        "g",
    "s",          "mg",        "mtllib", "usemtl", "usemap", "maplib", "cstype",   "deg",
    "bmat",       "step",      "curv",   "curv2",  "surf",   "parm",   "trim",     "hole",
    "scrv",       "sp",        "end",    "con",    "lod",    "bevel",  "c_interp", "d_interp",
    "shadow_obj", "trace_obj", "ctech",  "stech",  "call",   "csh"};

bool isBlank(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

/// Splits one line into whitespace-separated words, dropping a trailing # comment.
void splitWords(std::string_view line, std::vector<std::string_view>& words) {
  words.clear();
  if (const size_t hash = line.find('#'); hash != std::string_view::npos)
    line = line.substr(0, hash);
  size_t pos = 0;
  while (pos < line.size()) {
    while (pos < line.size() && isBlank(line[pos])) ++pos;
    const size_t start = pos;
    while (pos < line.size() && !isBlank(line[pos])) ++pos;
    if (pos > start) words.push_back(line.substr(start, pos - start));
  }
}

/// Throws the InputError of a statement on line `lineNumber` of `path`.
[[noreturn]] void failAt(const std::string& path, size_t lineNumber, const std::string& what) {
  throw InputError(path, "line " + std::to_string(lineNumber), what);
}

/// A `v x y z` statement's point (scaled by `scale`) into result.points.
void readVertex(const std::vector<std::string_view>& words, double scale, const std::string& path,
                size_t lineNumber, ObjPolylines& result) {
  if (words.size() < 4 || words.size() > 7) {
    failAt(path, lineNumber,
           "expected 'v x y z' (three to six numbers), found " + std::to_string(words.size() - 1) +
               " values");
  }
  double xyz[3] = {0, 0, 0};
  for (int axis = 0; axis < 3; ++axis) {
    const std::string_view text = words[static_cast<size_t>(axis) + 1];
    if (!parseReal(text, xyz[axis]) || !std::isfinite(xyz[axis])) {
      failAt(path, lineNumber,
             "vertex " + std::to_string(result.points.size() + 1) +
                 ": expected a finite number, found " + quoted(text));
    }
  }
  const btVector3 point(static_cast<btScalar>(xyz[0] * scale),
                        static_cast<btScalar>(xyz[1] * scale),
                        static_cast<btScalar>(xyz[2] * scale));
  if (!std::isfinite(point.x()) || !std::isfinite(point.y()) || !std::isfinite(point.z())) {
    failAt(path, lineNumber,
           "vertex " + std::to_string(result.points.size() + 1) +
               ": coordinates too large for the simulation's floating-point type");
  }
  result.points.push_back(point);
}

/// `l` vertex references as written, before the vertices are all known.
struct PolylineReferences {
  std::vector<int64_t> references;    ///< as written (1-based or negative)
  std::vector<size_t> lines;          ///< line of each polyline, for messages
  std::vector<size_t> vertexCountAt;  ///< vertices defined when each polyline was read
};

/// An `l` statement's references into `read` and its polyline's offset into result.lines.
void readPolyline(const std::vector<std::string_view>& words, const std::string& path,
                  size_t lineNumber, PolylineReferences& read, ObjPolylines& result) {
  for (size_t w = 1; w < words.size(); ++w) {
    const std::string_view text = words[w].substr(0, words[w].find('/'));
    int64_t value = 0;
    const auto [stop, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (error != std::errc() || stop != text.data() + text.size() || value == 0) {
      failAt(path, lineNumber,
             "expected a vertex reference (1-based, or negative counting back), found " +
                 quoted(words[w]));
    }
    read.references.push_back(value);
  }
  result.lines.offsets.push_back(static_cast<uint32_t>(read.references.size()));
  read.lines.push_back(lineNumber);
  read.vertexCountAt.push_back(result.points.size());
  if (read.references.size() > UINT32_MAX / 2)
    failAt(path, lineNumber, "expected fewer `l` references");
}

/// Resolves the references now that all vertices are known (positive ones may point forward).
void resolveReferences(const PolylineReferences& read, const std::string& path,
                       ObjPolylines& result) {
  result.lines.indices.reserve(read.references.size());
  for (size_t line = 0; line < result.lines.size(); ++line) {
    const std::string where = "line " + std::to_string(read.lines[line]);
    for (uint32_t k = result.lines.offsets[line]; k < result.lines.offsets[line + 1]; ++k) {
      const int64_t reference = read.references[k];
      const int64_t resolved = reference > 0
                                   ? reference - 1
                                   : static_cast<int64_t>(read.vertexCountAt[line]) + reference;
      if (resolved < 0 || resolved >= static_cast<int64_t>(result.points.size())) {
        throw InputError(path, where,
                         "vertex reference " + std::to_string(reference) +
                             " out of range: expected 1 to " +
                             std::to_string(result.points.size()) + " (or -1 to -" +
                             std::to_string(read.vertexCountAt[line]) + " counting back)");
      }
      result.lines.indices.push_back(static_cast<uint32_t>(resolved));
    }
    result.lines.origins.push_back("`l` element on " + where);
  }
}

}  // namespace

ObjPolylines readObjPolylines(const std::string& path, std::string_view bytes, double scale) {
  ObjPolylines result;
  PolylineReferences read;
  std::vector<std::string_view> words;
  size_t lineNumber = 0;
  size_t pos = 0;
  while (pos < bytes.size()) {
    ++lineNumber;
    const size_t end = std::min(bytes.find('\n', pos), bytes.size());
    splitWords(bytes.substr(pos, end - pos), words);
    pos = end + 1;
    if (words.empty()) continue;
    const std::string_view keyword = words.front();
    if (keyword == "v") {
      readVertex(words, scale, path, lineNumber, result);
    } else if (keyword == "l") {
      readPolyline(words, path, lineNumber, read, result);
    } else if (std::ranges::find(kIgnoredStatements, keyword) == std::end(kIgnoredStatements)) {
      failAt(path, lineNumber,
             "expected an OBJ statement (v, l, f, o, g, ...), found " + quoted(keyword));
    }
  }
  if (result.lines.size() == 0) {
    throw InputError(path, "", "expected fibres as OBJ `l` polylines, found none");
  }
  resolveReferences(read, path, result);
  return result;
}

namespace {

const MeshFormatRegistration registration({
    .name = "OBJ",
    .extensions = {".obj"},
    .fibreElements = "`l` polylines",
    .readFibres =
        [](const std::string& path, double scale) {
          const ObjPolylines data = readObjPolylines(path, readInputFile(path, "a mesh"), scale);
          return chainPolylines(path, data.points, data.lines);
        },
});

}  // namespace

}  // namespace fibremss::meshio
