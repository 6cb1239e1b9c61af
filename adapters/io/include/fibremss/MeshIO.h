#pragma once
// Loading surfaces and fibres from files, and the checks every loaded mesh goes through.
#include <string>
#include <vector>

#include "fibremss/Geometry.h"

namespace fibremss {

/// What the checks found that a run can live with (each a sentence naming file and element).
struct MeshReport {
  std::vector<std::string> warnings;  ///< open edges, inconsistent orientation, ...
  size_t openEdges = 0;               ///< edges used by one triangle only
  size_t nonManifoldEdges = 0;        ///< edges used by more than two triangles
  size_t degenerateTriangles = 0;     ///< zero-area or repeated-vertex triangles
  size_t inconsistentEdges = 0;       ///< edges both of whose triangles run the same way
  size_t duplicateTriangles = 0;      ///< triangles over the same three vertices as an earlier one
  size_t unusedVertices = 0;          ///< vertices no triangle uses
  bool insideOut = false;  ///< closed, consistently oriented, negative volume (loadSurface flips)
  size_t reorientedTriangles = 0;  ///< triangles loadSurface turned over (consistent, outward)
  size_t weldedVertices = 0;       ///< vertices the repair merged into a nearby one
  size_t droppedTriangles = 0;     ///< triangles the repair dropped (degenerate or repeated)
  size_t filledHoles = 0;          ///< loops of open edges the repair closed

  /// Every edge shared by exactly two triangles.
  bool closed() const { return openEdges == 0 && nonManifoldEdges == 0; }
};

/// Repairs loadSurface applies before its checks; both off by default.
struct SurfaceRepair {
  double weld = 0;    ///< merge each vertex within this distance of an earlier one into it [m]
  int fillHoles = 0;  ///< close loops of at most this many open edges by a fan of triangles
};

/// Loads a triangle surface in a format of the mesh format registry (src/MeshFormats.cpp: each
/// reader registers its formats, by extension and signature; assimp takes what none claims; an
/// unreadable file's message lists the registered formats). Coordinates are scaled by `scale`
/// (file units to metres). Throws InputError (file, element, expectation) for unreadable input or
/// fatal defects (NaN/inf, out-of-range indices, no triangles); `report` gets the rest. Triangles
/// turned over in the file are turned back so that each connected part is consistently
/// oriented and closed parts face outward (counted in report->reorientedTriangles). `repair`
/// welds vertices (then drops triangles left degenerate or repeated) and closes small holes
/// before the checks.
TriangleMesh loadSurface(const std::string& path, double scale = 1.0, MeshReport* report = nullptr,
                         const SurfaceRepair& repair = {});

/// Loads fibre polylines from a format of the mesh format registry that holds them
/// (src/MeshFormats.cpp; the message for a file none reads lists them, with the elements each
/// holds its fibres in); two-point segments are chained into polylines. Throws InputError for
/// unreadable input, empty or single-point fibres.
FibreSet loadFibres(const std::string& path, double scale = 1.0);

/// Writes fibre polylines as ASCII legacy VTK POLYDATA LINES (one polyline cell per fibre),
/// coordinates divided by `scale` (metres to file units); loadFibres(path, scale) reads them
/// back. Written atomically; throws std::runtime_error when the file cannot be written.
void saveFibresVtk(const std::string& path, const FibreSet& fibres, double scale = 1.0);

/// Checks a surface; throws InputError for fatal defects, returns the warnings.
MeshReport checkSurface(const TriangleMesh& mesh, const std::string& source);

/// Checks fibres against their muscle surface (points outside it beyond `tolerance` metres
/// are warnings naming the fibre); throws InputError for NaN/inf or empty fibres.
std::vector<std::string> checkFibres(const FibreSet& fibres, const TriangleMesh& surface,
                                     const std::string& source, double tolerance);

}  // namespace fibremss
