#pragma once
// Internal to the scene loader: bone motions read from OpenSim motion files (.mot / .sto), and
// the splitting of large jumps between poses into sub-poses.
#include <LinearMath/btTransform.h>

#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "SceneFields.h"
#include "fibremss/Geometry.h"
#include "fibremss/Scene.h"

namespace fibremss::scene {

/// The most poses a motion may give, after large jumps are split (simulation steps).
constexpr size_t kMaxPoses = 100000;

/// The table of an OpenSim storage file: a header ending with `endheader`, a line of column
/// names (tab-separated), then one row of numbers per line.
struct MotionTable {
  std::string path;                               ///< the file, for messages
  std::vector<std::string> columns;               ///< column names, as in the file ("time" first)
  std::unordered_map<std::string, size_t> index;  ///< column of each name
  std::vector<double> values;                     ///< row after row, columns.size() values each
  bool inDegrees = true;  ///< the header's inDegrees: angles in degrees, else radians

  size_t rows() const { return columns.empty() ? 0 : values.size() / columns.size(); }
  double at(size_t row, size_t column) const { return values[row * columns.size() + column]; }
  /// The index of a column; throws InputError naming the file and listing the columns.
  size_t column(const std::string& name) const;
};

/// Parses the text of a .mot / .sto file. Throws InputError (file, line, what was expected) for
/// a header without endheader, nRows / nColumns / inDegrees that are missing or not numbers,
/// names or rows whose count differs from nColumns, values that are not numbers, rows that
/// differ from nRows, and times that do not increase.
MotionTable parseMotionTable(const std::string& path, std::string_view text);

/// Reads and parses a .mot / .sto file (see parseMotionTable).
MotionTable readMotionTable(const std::string& path);

/// {"type": "opensim", "file": PATH, "pivot": ..., "coordinates": [{"column", "axis"}, ...],
/// "time": [t0, t1], "every": k}: one pose per row (in the time window, every k-th), the
/// coordinates applied in the listed order about their axes as carried by the rotations before
/// them (body-fixed, as OpenSim's CustomJoint), about the pivot. `file` is already resolved;
/// `result` receives the poses and the coordinates' values [°], `labels` the rows' times [s].
void readOpenSimMotion(Fields& motion, const std::string& file, const btVector3& pivot,
                       BoneMotion& result, std::vector<double>& labels);

/// `motion` about `pivot` instead of the origin: T(pivot) · motion · T(−pivot), so that it
/// keeps `pivot` where its rotation alone would keep the origin.
btTransform turnedAbout(const btTransform& motion, const btVector3& pivot);

/// The rigid motion `fraction` (in [0, 1]) of the way from `from` to `to` along the screw that
/// joins them: rotation about a fixed axis in space while translating along it, so a rotation
/// about a pivot keeps the pivot fixed at every fraction.
btTransform screwInterpolate(const btTransform& from, const btTransform& to, double fraction);

/// Splits every jump between consecutive poses (and from rest to the first pose) in which some
/// bone turns by more than `maxStepDeg` into sub-poses of at most that angle, interpolated along
/// each bone's screw motion; pose labels are interpolated too. Adds a note per split (the
/// largest ones, then a count) to scene.notes. maxStepDeg <= 0: nothing is split.
void splitLargeJumps(LoadedScene& scene, double maxStepDeg);

}  // namespace fibremss::scene
