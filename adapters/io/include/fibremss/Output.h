#pragma once
// Output files: written whole or not at all (a temporary name, then rename), in formats
// ParaView opens (VTK XML PolyData and a .pvd collection).
#include <LinearMath/btVector3.h>

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace fibremss {

/// Writes `content` to `path` through a temporary file and a rename; throws std::runtime_error
/// (with the path) when it cannot. Creates missing parent directories.
void writeFileAtomically(const std::string& path, std::string_view content);

/// Points with optional vertices, polylines and triangles, and per-point data arrays.
struct PolyData {
  std::vector<btVector3> points;                   ///< point coordinates
  bool pointsAsVertices = false;                   ///< emit every point as a vertex cell
  std::vector<uint32_t> lineIndices;               ///< polylines: point indices, CSR
  std::vector<uint32_t> lineOffsets{0};            ///< polyline i: [offsets[i], offsets[i+1])
  std::vector<std::array<uint32_t, 3>> triangles;  ///< triangle cells
  std::vector<std::pair<std::string, std::vector<float>>> pointScalars;  ///< named arrays
};

/// Writes a .vtp (VTK XML PolyData, ASCII) file atomically.
void writeVtp(const std::string& path, const PolyData& data);

/// A ParaView .pvd collection of time steps and parts.
class PvdCollection {
 public:
  /// Adds a dataset file (path relative to the .pvd) at `time` as part `part`.
  void add(double time, const std::string& file, int part = 0);
  /// Writes the collection atomically; may be called repeatedly as frames are added.
  void write(const std::string& path) const;

 private:
  struct Entry {
    double time;
    std::string file;
    int part;
  };
  std::vector<Entry> entries_;
};

}  // namespace fibremss
