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

/// Throws InputError when directory `path` could not be created or written: it exists and is
/// no directory or not writable, or its nearest existing ancestor is not writable. Checked
/// without writing anything (so a run can fail before its preparation and write nothing).
void requireWritableDirectory(const std::string& path);

/// An output directory one process writes at a time: created, locked (DIR/.fibremss.lock held
/// with flock while this lives; a second writer gets InputError naming the directory), and
/// cleared of the temporary files (NAME.tmp.PID.N) that a killed writer left in it or its
/// subfolders.
class OutputDirectory {
 public:
  explicit OutputDirectory(const std::string& path);
  ~OutputDirectory();
  OutputDirectory(const OutputDirectory&) = delete;
  OutputDirectory& operator=(const OutputDirectory&) = delete;
  /// Temporary files of earlier writers removed when it was opened.
  size_t removedTemporaries() const { return removed_; }

 private:
  int lock_ = -1;  ///< the lock file's descriptor
  size_t removed_ = 0;
};

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
