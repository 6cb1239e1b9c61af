// loadSurface() and loadFibres(): pick the reader by extension and content, then check.
#include "fibremss/MeshIO.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
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

}  // namespace meshio

namespace {

std::string lowerExtension(const std::string& path) {
  std::string extension = std::filesystem::path(path).extension().string();
  for (char& c : extension) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return extension;
}

enum class VtkKind { None, Legacy, Xml };

/// Legacy VTK (.vtk) or VTK XML PolyData (.vtp) by extension, or by content for files named
/// otherwise.
VtkKind vtkKind(const std::string& path, const std::string& extension) {
  if (extension == ".vtk") return VtkKind::Legacy;
  if (extension == ".vtp") return VtkKind::Xml;
  std::ifstream file(path, std::ios::binary);
  char head[512] = {};
  file.read(head, sizeof head);
  const std::string_view bytes(head, static_cast<size_t>(file.gcount()));
  if (meshio::looksLikeLegacyVtk(bytes)) return VtkKind::Legacy;
  return meshio::looksLikeVtkXml(bytes) ? VtkKind::Xml : VtkKind::None;
}

meshio::VtkPolyData readVtk(VtkKind kind, const std::string& path, const std::string& bytes,
                            double scale) {
  return kind == VtkKind::Legacy ? meshio::readLegacyVtk(path, bytes, scale)
                                 : meshio::readVtkXmlPolyData(path, bytes, scale);
}

}  // namespace

TriangleMesh loadSurface(const std::string& path, double scale, MeshReport* report,
                         const SurfaceRepair& repair) {
  meshio::requireScale(path, scale);
  TriangleMesh mesh;
  std::vector<std::string> readerWarnings;
  requireInputFile(path, "a mesh");  // before vtkKind opens it: a FIFO would block
  if (const VtkKind kind = vtkKind(path, lowerExtension(path)); kind != VtkKind::None) {
    const std::string bytes = readInputFile(path, "a mesh");
    meshio::VtkPolyData data = readVtk(kind, path, bytes, scale);
    if (data.triangles.empty()) {
      throw InputError(path, "",
                       "expected a surface (polygons or triangle strips), found no triangles" +
                           std::string(data.lines.size() > 0 ? " (only lines: fibres?)" : ""));
    }
    mesh.vertices = std::move(data.points);
    mesh.triangles = std::move(data.triangles);
    for (const std::string& warning : data.warnings)
      readerWarnings.push_back(path + ": " + warning);
  } else {
    mesh = meshio::readAssimpSurface(path, scale);
  }
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
  const std::string extension = lowerExtension(path);
  const std::string bytes = readInputFile(path, "a mesh");
  FibreSet fibres;
  if (const VtkKind kind = vtkKind(path, extension); kind != VtkKind::None) {
    const meshio::VtkPolyData data = readVtk(kind, path, bytes, scale);
    if (data.lines.size() == 0) {
      throw InputError(path, "", "expected fibres as lines cells (LINES, <Lines>), found none");
    }
    fibres = meshio::chainPolylines(path, data.points, data.lines);
  } else if (extension == ".obj") {
    const meshio::ObjPolylines data = meshio::readObjPolylines(path, bytes, scale);
    fibres = meshio::chainPolylines(path, data.points, data.lines);
  } else {
    throw InputError(
        path, "",
        "expected fibres in legacy VTK (.vtk, LINES), VTK XML (.vtp, Lines) or OBJ (.obj, "
        "`l` polylines), "
        "found the extension " +
            meshio::quoted(extension));
  }
  meshio::validateFibres(fibres, path);
  return fibres;
}

}  // namespace fibremss
