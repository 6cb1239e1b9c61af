#pragma once
// A run's frames read back (what FrameWriter wrote, or any VTK XML PolyData and .pvd): the
// viewer plays them.
#include <LinearMath/btVector3.h>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace fibremss {

/// A point-data array read from a file, as floats.
struct PointArray {
  std::string name;           ///< its name in the file
  int components = 1;         ///< numbers per point (3 for a vector)
  std::vector<float> values;  ///< point after point, components × points values
};

/// A .vtp file's points, cells and point data.
struct PolyDataFile {
  std::vector<btVector3> points;                   ///< coordinates × the reader's scale
  std::vector<std::array<uint32_t, 3>> triangles;  ///< polygons and strips, fan-triangulated
  std::vector<uint32_t> lineIndices;               ///< polylines: point indices, CSR
  std::vector<uint32_t> lineOffsets{0};            ///< polyline i: [offsets[i], offsets[i+1])
  std::vector<PointArray> pointData;               ///< the PointData arrays every piece has

  /// The array called `name`, or nullptr.
  const PointArray* array(const std::string& name) const;
};

/// Reads a VTK XML PolyData file (points scaled by `scale`; arrays as stored). Throws InputError
/// (file, line, expectation) for a file that is missing, malformed or inconsistent.
PolyDataFile readVtp(const std::string& path, double scale = 1.0);

/// One DataSet entry of a ParaView collection.
struct PvdDataSet {
  double time = 0;   ///< its timestep
  int part = 0;      ///< its part
  std::string file;  ///< its file, as written (relative to the .pvd)
};

/// The DataSet entries of a .pvd collection, in file order. Throws InputError for a file that
/// is missing or no VTKFile type="Collection", or an entry without a file or a number timestep.
std::vector<PvdDataSet> readPvd(const std::string& path);

}  // namespace fibremss
