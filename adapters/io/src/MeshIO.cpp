// loadSurface() and loadFibres(): the registered format's reader (MeshFormats.cpp), then checks.
#include "fibremss/MeshIO.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <utility>

#include "MeshIOInternal.h"
#include "fibremss/Error.h"
#include "fibremss/InputFiles.h"

namespace fibremss {
namespace meshio {

void requireScale(const std::string& path, double scale) {
  if (!(scale > 0) || !std::isfinite(scale)) {
    throw InputError(path, "scale",
                     "expected a positive finite unit scale, found " + std::to_string(scale));
  }
}

bool parseReal(std::string_view text, double& value) {
  if (text.size() > 1 && text[0] == '+' && text[1] != '-') text.remove_prefix(1);
  const char* end = text.data() + text.size();
  const auto [stop, error] = std::from_chars(text.data(), end, value);
  if (text.empty() || stop != end) return false;
  if (error == std::errc::result_out_of_range) {
    const size_t exponent = text.find_first_of("eE");
    const bool tiny = exponent != std::string_view::npos && exponent + 1 < text.size() &&
                      text[exponent + 1] == '-';
    value = tiny ? 0.0 : std::numeric_limits<double>::infinity();
    return true;
  }
  return error == std::errc();
}

std::string quoted(std::string_view text) {
  constexpr size_t kLongest = 40;
  std::string result = "'";
  for (size_t i = 0; i < std::min(text.size(), kLongest); ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c >= 0x20 && c < 0x7f) {
      result += static_cast<char>(c);
    } else {
      constexpr char kHex[] = "0123456789abcdef";
      result += "\\x";
      result += kHex[c >> 4];
      result += kHex[c & 15];
    }
  }
  if (text.size() > kLongest) result += "...";
  return result + "'";
}

void appendPolygon(std::vector<std::array<uint32_t, 3>>& triangles,
                   const std::vector<uint32_t>& cell) {
  for (size_t k = 1; k + 1 < cell.size(); ++k) triangles.push_back({cell[0], cell[k], cell[k + 1]});
}

void appendStrip(std::vector<std::array<uint32_t, 3>>& triangles,
                 const std::vector<uint32_t>& cell) {
  for (size_t k = 0; k + 2 < cell.size(); ++k) {
    if (k % 2 == 0) {
      triangles.push_back({cell[k], cell[k + 1], cell[k + 2]});
    } else {
      triangles.push_back({cell[k + 1], cell[k], cell[k + 2]});
    }
  }
}

FibreSet chainPolylines(const std::string& path, const std::vector<btVector3>& points,
                        const IndexPolylines& lines) {
  FibreSet fibres;
  uint32_t lastIndex = UINT32_MAX;  // last point index of the fibre being built
  for (size_t line = 0; line < lines.size(); ++line) {
    const uint32_t begin = lines.offsets[line], end = lines.offsets[line + 1];
    if (end - begin < 2) {
      throw InputError(path, lines.origins[line],
                       end == begin ? "empty polyline; expected at least two points per fibre"
                                    : "a single point; expected at least two points per fibre");
    }
    uint32_t first = begin;
    if (lines.indices[begin] == lastIndex) {
      ++first;  // continues the previous polyline: share its end point
    } else if (fibres.points.size() != fibres.offsets.back()) {
      fibres.offsets.push_back(static_cast<uint32_t>(fibres.points.size()));
    }
    for (uint32_t k = first; k < end; ++k) fibres.points.push_back(points[lines.indices[k]]);
    lastIndex = lines.indices[end - 1];
  }
  if (fibres.points.size() != fibres.offsets.back()) {
    fibres.offsets.push_back(static_cast<uint32_t>(fibres.points.size()));
  }
  return fibres;
}

SurfaceRead vtkSurface(const std::string& path, VtkPolyData&& data) {
  if (data.triangles.empty()) {
    throw InputError(path, "",
                     "expected a surface (polygons or triangle strips), found no triangles" +
                         std::string(data.lines.size() > 0 ? " (only lines: fibres?)" : ""));
  }
  return {{std::move(data.points), std::move(data.triangles)}, std::move(data.warnings)};
}

FibreSet vtkFibres(const std::string& path, const VtkPolyData& data) {
  if (data.lines.size() == 0) {
    throw InputError(path, "", "expected fibres as lines cells (LINES, <Lines>), found none");
  }
  return chainPolylines(path, data.points, data.lines);
}

}  // namespace meshio

TriangleMesh loadSurface(const std::string& path, double scale, MeshReport* report,
                         const SurfaceRepair& repair) {
  meshio::requireScale(path, scale);
  requireInputFile(path, "a mesh");  // before the format is chosen by content: a FIFO would block
  const meshio::MeshFormat* format = meshio::meshFormatFor(path, meshio::MeshUse::Surface);
  if (!format) throw InputError(path, "", "expected a surface in " + meshio::surfaceFormatList());
  meshio::SurfaceRead read = format->readSurface(path, scale);
  TriangleMesh mesh = std::move(read.mesh);
  std::vector<std::string> readerWarnings;
  for (const std::string& warning : read.warnings) readerWarnings.push_back(path + ": " + warning);
  MeshReport repaired;
  meshio::repairSurface(mesh, repair, repaired);
  MeshReport checked = checkSurface(mesh, path);
  checked.weldedVertices = repaired.weldedVertices;
  checked.droppedTriangles = repaired.droppedTriangles;
  checked.filledHoles = repaired.filledHoles;
  size_t nonOrientableParts = 0;
  checked.reorientedTriangles = meshio::orientConsistently(mesh, nonOrientableParts);
  if (checked.reorientedTriangles > 0) {
    checked.warnings.push_back(path + ": " + std::to_string(checked.reorientedTriangles) +
                               " triangles turned over so that the orientation is consistent "
                               "and closed parts face outward");
  }
  if (nonOrientableParts > 0) {
    checked.warnings.push_back(path + ": " + std::to_string(nonOrientableParts) +
                               " connected parts cannot be oriented consistently; left as read");
  }
  if (report) {
    readerWarnings.insert(readerWarnings.end(), std::make_move_iterator(checked.warnings.begin()),
                          std::make_move_iterator(checked.warnings.end()));
    checked.warnings = std::move(readerWarnings);
    *report = std::move(checked);
  }
  return mesh;
}

FibreSet loadFibres(const std::string& path, double scale) {
  meshio::requireScale(path, scale);
  requireInputFile(path, "a mesh");
  const meshio::MeshFormat* format = meshio::meshFormatFor(path, meshio::MeshUse::Fibres);
  if (!format) {
    throw InputError(path, "",
                     "expected fibres in " + meshio::fibreFormatList() + ", found the extension " +
                         meshio::quoted(meshio::lowerExtension(path)));
  }
  const FibreSet fibres = format->readFibres(path, scale);
  meshio::validateFibres(fibres, path);
  return fibres;
}

}  // namespace fibremss
