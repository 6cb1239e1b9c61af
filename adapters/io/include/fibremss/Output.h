#pragma once
// Output files: written whole or not at all (a temporary name, then rename), in formats
// ParaView opens (VTK XML PolyData, binary and zlib-compressed, and a .pvd collection).
#include <LinearMath/btVector3.h>

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace fibremss {

/// Writes `content` to `path` through a temporary file and a rename; creates missing parent
/// directories. When it cannot (a full disk, a file where a directory belongs, a directory with
/// the file's name) it throws InputError naming the path and the system's reason, and leaves
/// neither the temporary nor a half-written file.
void writeFileAtomically(const std::string& path, std::string_view content);

/// Removes the file at `path` a previous writer left (nothing when there is none); InputError
/// naming the path when a directory has its name or it cannot be removed.
void removeOutputFile(const std::string& path);

/// Throws InputError when directory `path` could not be created or written: it exists and is
/// no directory or not writable, or its nearest existing ancestor is not writable. Checked
/// without writing anything (so a run can fail before its preparation and write nothing).
void requireWritableDirectory(const std::string& path);

/// An output directory one process writes at a time: created, locked (DIR/.fibremss.lock held
/// with flock while this lives and removed when it ends; a second writer gets InputError naming
/// the directory; a lock file that is a symbolic link is not followed but refused), and cleared
/// of the temporary files (NAME.tmp.PID.N) that the previous writer, a killed one, left in it or
/// its subfolders: the lock file records each writer's process id, and only temporaries
/// carrying that id are removed.
class OutputDirectory {
 public:
  explicit OutputDirectory(const std::string& path);
  ~OutputDirectory();
  OutputDirectory(const OutputDirectory&) = delete;
  OutputDirectory& operator=(const OutputDirectory&) = delete;
  /// Temporary files of earlier writers removed when it was opened.
  size_t removedTemporaries() const { return removed_; }

 private:
  /// Opens and locks the lock file; false when the file was removed meanwhile (try again).
  bool lockHeld();

  std::string lockPath_;  ///< DIR/.fibremss.lock
  int lock_ = -1;         ///< the lock file's descriptor
  size_t removed_ = 0;
};

/// A named data array: `components` numbers per tuple, tuple after tuple.
struct DataArray {
  std::string name;    ///< array name as ParaView lists it
  int components = 1;  ///< numbers per tuple (3 for a vector)
  /// The values, written as Float32, Float64 or Int32.
  std::variant<std::vector<float>, std::vector<double>, std::vector<int32_t>> values;

  size_t size() const;  ///< number of values (tuples × components)
};

/// Points with optional vertices, polylines and triangles, per-point arrays and field data.
struct PolyData {
  std::vector<btVector3> points;                   ///< point coordinates [any length unit]
  btScalar pointScale = 1;                         ///< file units per point unit (1000: m → mm)
  double pointStep = 0;                            ///< points rounded to it [file units] (0: no)
  bool pointsAsVertices = false;                   ///< emit every point as a vertex cell
  std::vector<uint32_t> lineIndices;               ///< polylines: point indices, CSR
  std::vector<uint32_t> lineOffsets{0};            ///< polyline i: [offsets[i], offsets[i+1])
  std::vector<std::array<uint32_t, 3>> triangles;  ///< triangle cells
  std::vector<DataArray> pointData;                ///< one tuple per point each
  std::vector<DataArray> fieldData;                ///< whole-dataset arrays (e.g. TimeValue)
};

/// The largest power of two not above `limit` (0 for a `limit` of 0): a rounding step whose
/// multiples Float32 holds exactly, with zero low mantissa bits that zlib then compresses.
double powerOfTwoStep(double limit);

/// Rounds every value to the nearest multiple of `step` (nothing when `step` is 0).
void roundToStep(std::vector<float>& values, double step);

/// Writes a .vtp (VTK XML PolyData) file atomically: points as Float32, cells as Int32, every
/// array appended raw and compressed in vtkZLibDataCompressor's blocks (UInt64 headers), as VTK
/// 9 and ParaView 5.11 read it. Throws std::runtime_error for inconsistent data.
void writeVtp(const std::string& path, const PolyData& data);

/// A ParaView .pvd collection of time steps and parts.
class PvdCollection {
 public:
  /// Adds a dataset file (path relative to the .pvd) at `time` as part `part`, its block named
  /// `name` in ParaView (none when empty).
  void add(double time, const std::string& file, int part = 0, const std::string& name = "");
  /// Writes the collection atomically; may be called repeatedly as frames are added.
  void write(const std::string& path) const;

 private:
  struct Entry {
    double time;
    std::string file;
    int part;
    std::string name;
  };
  std::vector<Entry> entries_;
};

}  // namespace fibremss
