#pragma once
// Internal to the loaders: the raw readers behind loadSurface()/loadFibres() and the helpers
// they share. Readers throw InputError naming file, line or byte offset, and what was expected.
#include <LinearMath/btVector3.h>

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "fibremss/Geometry.h"
#include "fibremss/InputFiles.h"
#include "fibremss/MeshIO.h"
#include "fibremss/VtkFiles.h"

namespace fibremss::meshio {

/// Polylines as point indices (CSR) with a human-readable origin per polyline for messages.
struct IndexPolylines {
  std::vector<uint32_t> indices;     ///< point indices, polyline after polyline
  std::vector<uint32_t> offsets{0};  ///< polyline i: [offsets[i], offsets[i+1])
  std::vector<std::string> origins;  ///< e.g. "LINES cell 4 (line 57)", one per polyline

  size_t size() const { return offsets.size() - 1; }
};

/// What the legacy VTK reader found: points, triangles from POLYGONS and TRIANGLE_STRIPS,
/// and the LINES cells.
struct VtkPolyData {
  std::vector<btVector3> points;                   ///< scaled point coordinates
  std::vector<std::array<uint32_t, 3>> triangles;  ///< fan-triangulated polygons and strips
  IndexPolylines lines;                            ///< LINES cells, unchained
  std::vector<std::string> warnings;               ///< cells skipped (fewer than 3 points, ...)
  std::vector<PointArray> pointData;  ///< VTK XML only: the PointData arrays every piece has
};

/// Points and `l` polylines of an OBJ file.
struct ObjPolylines {
  std::vector<btVector3> points;  ///< scaled `v` coordinates
  IndexPolylines lines;           ///< `l` elements, unchained
};

/// True when the bytes start like a legacy VTK file ("# vtk DataFile Version").
bool looksLikeLegacyVtk(std::string_view bytes);

/// Legacy VTK POLYDATA, ASCII or BINARY (big-endian), classic or 5.1 OFFSETS layout.
VtkPolyData readLegacyVtk(const std::string& path, std::string_view bytes, double scale);

/// True when the bytes start like a VTK XML file ("<?xml" or "<VTKFile", naming VTKFile).
bool looksLikeVtkXml(std::string_view bytes);

/// VTK XML PolyData (.vtp): Points, Polys, Strips and Lines of every Piece; DataArrays in
/// ascii, binary (base64, optionally vtkZLibDataCompressor blocks) or appended (raw or base64)
/// format, UInt32 or UInt64 headers, either byte order.
VtkPolyData readVtkXmlPolyData(const std::string& path, std::string_view bytes, double scale);

/// Appends a polygon's fan triangles (`cell` has at least 3 points).
void appendPolygon(std::vector<std::array<uint32_t, 3>>& triangles,
                   const std::vector<uint32_t>& cell);

/// Appends a triangle strip's triangles, every second one reversed to keep one orientation.
void appendStrip(std::vector<std::array<uint32_t, 3>>& triangles,
                 const std::vector<uint32_t>& cell);

/// OBJ `v` and `l` statements (other statements are ignored, unknown ones are errors).
ObjPolylines readObjPolylines(const std::string& path, std::string_view bytes, double scale);

/// A surface through assimp: all meshes merged, triangulated, identical vertices joined.
TriangleMesh readAssimpSurface(const std::string& path, double scale);

/// A surface as a format's reader gives it.
struct SurfaceRead {
  TriangleMesh mesh;                  ///< points [m] and triangles as read
  std::vector<std::string> warnings;  ///< what the reader skipped, each naming no file
};

/// One mesh file format loadSurface() and loadFibres() read. Each reader's source registers its
/// formats with a namespace-scope MeshFormatRegistration as the library loads; the dispatch and
/// the messages listing the accepted formats read the registrations, so that adding a format is
/// its reader's source.
struct MeshFormat {
  const char* name = "";                     ///< its name in messages ("legacy VTK")
  std::vector<std::string> extensions = {};  ///< the extensions naming it, lower case (".vtk")
  const char* fibreElements = "";            ///< what holds its fibres, for messages ("LINES")
  /// True when a file's first kSignatureBytes bytes are of this format; null: it is known by
  /// its extension alone.
  bool (*recognises)(std::string_view head) = nullptr;
  /// Reads a surface in metres; null: the format holds no surfaces.
  SurfaceRead (*readSurface)(const std::string& path, double scale) = nullptr;
  /// Reads fibres in metres, chained (chainPolylines) but not validated; null: none.
  FibreSet (*readFibres)(const std::string& path, double scale) = nullptr;
  /// Reads the surfaces no other format claims (assimp's); at most one format is.
  bool fallback = false;
};

/// The bytes MeshFormat::recognises is given: the file's first ones.
constexpr size_t kSignatureBytes = 512;

/// Adds `format` to the formats meshFormatFor() chooses from. An extension registered twice, or
/// a second fallback, stops the program as it loads.
class MeshFormatRegistration {
 public:
  explicit MeshFormatRegistration(MeshFormat format);
};

/// What a mesh file is read for.
enum class MeshUse { Surface, Fibres };

/// The format that reads `path` for `use`: a format with a signature named by the extension,
/// else one whose signature the file's first bytes match, else one named by the extension, else
/// the fallback; null for none. Throws InputError when the file cannot be opened.
const MeshFormat* meshFormatFor(const std::string& path, MeshUse use);

/// The formats fibres are read from, for a message: "legacy VTK (.vtk, LINES), ... or OBJ (...)".
std::string fibreFormatList();

/// The formats surfaces are read from, for a message: "legacy VTK, VTK XML, OBJ, STL, ...".
std::string surfaceFormatList();

/// The file's extension in lower case, with its dot ("" for none).
std::string lowerExtension(const std::string& path);

/// A VTK reader's surface: its triangles (InputError naming `path` for none) and warnings.
SurfaceRead vtkSurface(const std::string& path, VtkPolyData&& data);

/// A VTK reader's fibres: its lines cells chained (InputError naming `path` for none).
FibreSet vtkFibres(const std::string& path, const VtkPolyData& data);

/// The entry of a VTK format whose reader `read` parses a file's bytes.
template <VtkPolyData (*read)(const std::string& path, std::string_view bytes, double scale)>
MeshFormat vtkFormat(const char* name, const char* extension, const char* fibreElements,
                     bool (*recognises)(std::string_view head)) {
  return {.name = name,
          .extensions = {extension},
          .fibreElements = fibreElements,
          .recognises = recognises,
          .readSurface =
              [](const std::string& path, double scale) {
                return vtkSurface(path, read(path, readInputFile(path, "a mesh"), scale));
              },
          .readFibres =
              [](const std::string& path, double scale) {
                return vtkFibres(path, read(path, readInputFile(path, "a mesh"), scale));
              }};
}

/// Fibres from polylines: a polyline that starts at the point where the previous one ended
/// continues it (files that store fibres as two-point segments). Throws InputError for empty
/// and single-point polylines, naming their origin.
FibreSet chainPolylines(const std::string& path, const std::vector<btVector3>& points,
                        const IndexPolylines& lines);

/// One use of an edge by a triangle; `forward` when the triangle runs from the lower index.
struct EdgeUse {
  uint64_t key;       ///< lower vertex index << 32 | higher vertex index
  uint32_t triangle;  ///< the triangle using the edge
  bool forward;       ///< the triangle runs the edge from the lower index to the higher
};

/// The edges of every triangle without a repeated vertex, sorted by key then triangle.
std::vector<EdgeUse> sortedEdgeUses(const TriangleMesh& mesh);

/// Turns triangles over so that every edge shared by exactly two triangles is run in opposite
/// directions; each connected part keeps the orientation most of its triangles have, and a
/// closed part is then turned outward. Parts that cannot be oriented (Moebius-like) are left
/// as they are and counted in `nonOrientableParts`. Returns the number of triangles turned.
size_t orientConsistently(TriangleMesh& mesh, size_t& nonOrientableParts);

/// Welds vertices within repair.weld of an earlier one (dropping the triangles that leaves
/// degenerate or repeated, and any repeated triangle), then closes each loop of at most
/// repair.fillHoles open edges; the counts go into `report`.
void repairSurface(TriangleMesh& mesh, const SurfaceRepair& repair, MeshReport& report);

/// Throws InputError unless `scale` is a positive finite number.
void requireScale(const std::string& path, double scale);

/// Throws InputError for structurally broken sets, empty, single-point, zero-length fibres and
/// non-finite points, naming the fibre.
void validateFibres(const FibreSet& fibres, const std::string& source);

/// Parses the whole of `text` as a number as C's strtod would (a leading '+' allowed; too
/// small rounds to 0, too large becomes infinity); false when it is not a number.
bool parseReal(std::string_view text, double& value);

/// `text` quoted for a message: printable ASCII kept, other bytes as \xNN, long text cut.
std::string quoted(std::string_view text);

}  // namespace fibremss::meshio
