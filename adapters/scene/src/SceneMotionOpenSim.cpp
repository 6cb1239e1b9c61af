// OpenSim motion files (.mot / .sto) and bone motions read from them (SceneMotion.h).
#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>

#include "SceneMotion.h"
#include "fibremss/Error.h"
#include "fibremss/InputFiles.h"

namespace fibremss::scene {
namespace {

constexpr double kDegrees = M_PI / 180;
constexpr size_t kMaxColumns = 100000;
/// The largest angle a coordinate may take [°], as a sweep's start_deg and end_deg.
constexpr double kMaxTurnDeg = 3600;

std::string_view trim(std::string_view text) {
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.front())))
    text.remove_prefix(1);
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back())))
    text.remove_suffix(1);
  return text;
}

std::string lower(std::string_view text) {
  std::string result(text);
  for (char& c : result) c = char(std::tolower(static_cast<unsigned char>(c)));
  return result;
}

/// Quoted for a message: at most 40 characters, control bytes as '?'.
std::string quote(std::string_view text) {
  std::string result = "'";
  for (size_t i = 0; i < std::min<size_t>(text.size(), 40); ++i)
    result += std::isprint(static_cast<unsigned char>(text[i])) ? text[i] : '?';
  return result + (text.size() > 40 ? "...'" : "'");
}

/// Splits at tabs when the line has one (names may hold spaces), else at runs of blanks.
std::vector<std::string_view> splitFields(std::string_view line, bool atTabs) {
  std::vector<std::string_view> fields;
  if (atTabs) {
    for (size_t start = 0;;) {
      const size_t tab = line.find('\t', start);
      fields.push_back(trim(line.substr(start, tab == std::string_view::npos ? tab : tab - start)));
      if (tab == std::string_view::npos) break;
      start = tab + 1;
    }
    return fields;
  }
  for (size_t at = 0; at < line.size();) {
    while (at < line.size() && std::isspace(static_cast<unsigned char>(line[at]))) ++at;
    const size_t start = at;
    while (at < line.size() && !std::isspace(static_cast<unsigned char>(line[at]))) ++at;
    if (at > start) fields.push_back(line.substr(start, at - start));
  }
  return fields;
}

bool parseNumber(std::string_view text, double& value) {
  if (text.size() > 1 && text[0] == '+') text.remove_prefix(1);
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  return !text.empty() && error == std::errc() && end == text.data() + text.size() &&
         std::isfinite(value);
}

bool parseCount(std::string_view text, size_t& value) {
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  return !text.empty() && error == std::errc() && end == text.data() + text.size();
}

/// Line by line, counting from 1; a trailing '\r' is dropped.
class LineReader {
 public:
  explicit LineReader(std::string_view text) : text_(text) {}
  bool next(std::string_view& line) {
    if (pos_ >= text_.size()) return false;
    const size_t end = std::min(text_.find('\n', pos_), text_.size());
    line = text_.substr(pos_, end - pos_);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    pos_ = end + 1;
    ++number_;
    return true;
  }
  std::string where() const { return "line " + std::to_string(number_); }

 private:
  std::string_view text_;
  size_t pos_ = 0;
  size_t number_ = 0;
};

/// What the header says; counts are optional (newer .sto files leave them out).
struct Header {
  bool haveRows = false, haveColumns = false, haveDegrees = false;
  size_t rows = 0, columns = 0;
  bool inDegrees = true;
};

/// Reads the header lines up to `endheader`: key=value (and the old "datarows N" form).
Header readHeader(const std::string& path, LineReader& lines) {
  Header header;
  std::string_view line;
  while (lines.next(line)) {
    const std::string_view text = trim(line);
    if (lower(text) == "endheader") return header;
    const size_t equals = text.find('=');
    std::string key = lower(trim(text.substr(0, std::min(equals, text.find(' ')))));
    const std::string_view value =
        trim(equals != std::string_view::npos ? text.substr(equals + 1)
                                              : text.substr(std::min(text.size(), key.size())));
    const bool rows = key == "nrows" || key == "datarows";
    const bool columns = key == "ncolumns" || key == "datacolumns";
    if (rows || columns) {
      size_t& count = rows ? header.rows : header.columns;
      if (!parseCount(value, count))
        throw InputError(path, lines.where(),
                         "expected " + std::string(rows ? "nRows" : "nColumns") +
                             "=N (a non-negative integer), found " + quote(text));
      (rows ? header.haveRows : header.haveColumns) = true;
    } else if (key == "indegrees") {
      const std::string answer = lower(value);
      if (answer != "yes" && answer != "no")
        throw InputError(path, lines.where(),
                         "expected inDegrees=yes or inDegrees=no, found " + quote(text));
      header.inDegrees = answer == "yes";
      header.haveDegrees = true;
    }
  }
  throw InputError(path, lines.where(),
                   "expected a header ending with a line 'endheader' (OpenSim .mot / .sto), "
                   "found the end of the file");
}

/// The angle in `row` of `column`, refused beyond ±kMaxTurnDeg (in the table's unit).
double checkedAngle(const MotionTable& table, size_t row, size_t column) {
  const double angle = table.at(row, column);
  const double limit = table.inDegrees ? kMaxTurnDeg : kMaxTurnDeg * kDegrees;
  if (!(std::abs(angle) <= limit))
    throw InputError(
        table.path, "row " + std::to_string(row + 1) + ", column " + table.columns[column],
        "expected an angle within ±" + std::to_string(int(kMaxTurnDeg)) + "° (ten turns), found " +
            std::to_string(angle) + (table.inDegrees ? "°" : " rad"));
  return angle;
}

}  // namespace

size_t MotionTable::column(const std::string& name) const {
  const auto found = index.find(name);
  if (found != index.end()) return found->second;
  constexpr size_t kListed = 20;
  std::string list;
  for (size_t c = 0; c < std::min(columns.size(), kListed); ++c)
    list += (list.empty() ? "" : ", ") + quote(columns[c]);
  if (columns.size() > kListed)
    list += " and " + std::to_string(columns.size() - kListed) + " more";
  throw InputError(path, "", "has no column " + quote(name) + "; its columns are: " + list);
}

MotionTable parseMotionTable(const std::string& path, std::string_view text) {
  LineReader lines(text);
  const Header header = readHeader(path, lines);
  if (!header.haveDegrees)
    throw InputError(path, "header",
                     "expected inDegrees=yes or inDegrees=no before endheader (are the angles "
                     "in degrees or radians?)");
  MotionTable table;
  table.path = path;
  table.inDegrees = header.inDegrees;
  std::string_view line;
  while (lines.next(line) && trim(line).empty()) {
  }
  if (trim(line).empty())
    throw InputError(path, lines.where(),
                     "expected a line of column names after endheader, found the end of the file");
  for (std::string_view name : splitFields(line, line.find('\t') != std::string_view::npos))
    table.columns.emplace_back(name);
  const size_t width = table.columns.size();
  if (header.haveColumns && width != header.columns)
    throw InputError(path, lines.where(),
                     "expected " + std::to_string(header.columns) +
                         " column names (nColumns), found " + std::to_string(width));
  if (width > kMaxColumns)
    throw InputError(path, lines.where(),
                     "expected at most " + std::to_string(kMaxColumns) + " columns, found " +
                         std::to_string(width));
  if (lower(table.columns.front()) != "time")
    throw InputError(
        path, lines.where(),
        "expected column names starting with 'time', found " + quote(table.columns.front()));
  const std::string namesLine = lines.where();
  for (size_t c = 0; c < width; ++c)
    if (table.columns[c].empty() || !table.index.emplace(table.columns[c], c).second)
      throw InputError(path, namesLine,
                       "expected distinct, non-empty column names; column " +
                           std::to_string(c + 1) + " is " + quote(table.columns[c]));
  while (lines.next(line)) {
    if (trim(line).empty()) continue;
    const std::vector<std::string_view> fields = splitFields(line, false);
    if (fields.size() != width)
      throw InputError(path, lines.where(),
                       "expected " + std::to_string(width) + " values (one per column), found " +
                           std::to_string(fields.size()));
    for (size_t c = 0; c < width; ++c) {
      double value;
      if (!parseNumber(fields[c], value))
        throw InputError(
            path, lines.where(),
            "column " + table.columns[c] + ": expected a finite number, found " + quote(fields[c]));
      table.values.push_back(value);
    }
    const size_t row = table.rows() - 1;
    if (row > 0 && !(table.at(row, 0) > table.at(row - 1, 0)))
      throw InputError(path, lines.where(),
                       "expected the time to increase, found " + std::to_string(table.at(row, 0)) +
                           " after " + std::to_string(table.at(row - 1, 0)));
  }
  if (header.haveRows && table.rows() != header.rows)
    throw InputError(path, lines.where(),
                     "expected " + std::to_string(header.rows) +
                         " rows of numbers (nRows), found " + std::to_string(table.rows()));
  if (table.rows() == 0)
    throw InputError(path, lines.where(), "expected rows of numbers after the column names");
  return table;
}

MotionTable readMotionTable(const std::string& path) {
  return parseMotionTable(
      path, readInputFile(path, "an OpenSim motion table (.mot, .sto)", kMaxTextFileBytes));
}

void readOpenSimMotion(Fields& motion, const std::string& file, const btVector3& pivot,
                       BoneMotion& result, std::vector<double>& labels) {
  const MotionTable table = readMotionTable(file);
  std::vector<btTransform>& poses = result.poses;
  struct Coordinate {
    size_t column;
    btVector3 axis;
  };
  std::vector<Coordinate> coordinates;
  const Json& list = motion.array("coordinates");
  if (list.empty())
    motion.fail("coordinates",
                "expected at least one {\"column\": NAME, \"axis\": [x, y, z]} of " + file);
  Json complete = Json::array();
  for (size_t i = 0; i < list.size(); ++i) {
    Fields coordinate(list[i], motion.pathOf("coordinates") + "[" + std::to_string(i) + "]",
                      motion.source());
    if (!coordinate.has("column")) coordinate.fail("column", "missing: a column name of " + file);
    if (!coordinate.has("axis"))
      coordinate.fail("axis", "missing: the rotation axis [x, y, z] in the scene's frame");
    const std::string name = coordinate.text("column", "");
    const btVector3 axis = coordinate.vector3("axis", btVector3(1, 0, 0));
    if (!(axis.length() > 0)) coordinate.fail("axis", "expected a non-zero rotation axis");
    result.coordinateNames.push_back(name);
    try {
      coordinates.push_back({table.column(name), axis.normalized()});
    } catch (const InputError& e) {
      coordinate.fail("column", e.what());
    }
    complete.push_back(coordinate.finish());
  }
  motion.set("coordinates", std::move(complete));

  const double first = table.at(0, 0), last = table.at(table.rows() - 1, 0);
  double window[2] = {first, last};
  if (const Json* time = motion.raw("time")) {
    if (!time->is_array() || time->size() != 2 || !(*time)[0].is_number() ||
        !(*time)[1].is_number() || (*time)[0].get<double>() > (*time)[1].get<double>())
      motion.fail("time", "expected [t0, t1] with t0 <= t1 [s], got " + describe(*time));
    window[0] = (*time)[0].get<double>();
    window[1] = (*time)[1].get<double>();
  }
  motion.set("time", Json::array({window[0], window[1]}));
  const int every = motion.integer("every", 1, 1, 1000000);
  const double toRadians = table.inDegrees ? kDegrees : 1;
  const double slack = 1e-9 * std::max(1.0, std::abs(last));
  size_t inWindow = 0;
  for (size_t row = 0; row < table.rows(); ++row) {
    const double t = table.at(row, 0);
    if (t < window[0] - slack || t > window[1] + slack || inWindow++ % size_t(every) != 0) continue;
    btQuaternion rotation = btQuaternion::getIdentity();
    std::vector<double>& values = result.coordinates.emplace_back();
    for (const Coordinate& c : coordinates) {
      const double angle = checkedAngle(table, row, c.column) * toRadians;
      rotation *= btQuaternion(c.axis, btScalar(angle));
      values.push_back(angle / kDegrees);
    }
    poses.push_back(turnedAbout(btTransform(rotation), pivot));
    labels.push_back(t);
    if (poses.size() > kMaxPoses)
      motion.fail("every", "gives more than " + std::to_string(kMaxPoses) + " poses");
  }
  if (poses.empty())
    motion.fail("time", "no row of " + file + " lies in [" + std::to_string(window[0]) + ", " +
                            std::to_string(window[1]) + "] s (the file runs from " +
                            std::to_string(first) + " to " + std::to_string(last) + " s)");
}

}  // namespace fibremss::scene
