#include "SceneTool.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

namespace fibremss {
namespace {

/// The segment `time` lies in: the index of the waypoint that ends it (0 at the start).
size_t segmentOf(const std::vector<double>& times, double time) {
  const auto end = std::lower_bound(times.begin(), times.end(), time);
  return std::min(static_cast<size_t>(end - times.begin()), times.size() - 1);
}

}  // namespace

int ToolScript::ticks() const {
  return times.empty() ? 0 : static_cast<int>(std::lround(times.back() / tickTime));
}

btVector3 ToolScript::position(int tick) const {
  const double time = tick * tickTime;
  const size_t k = segmentOf(times, time);
  if (k == 0 || time >= times[k]) return positions[k];
  const double t = (time - times[k - 1]) / (times[k] - times[k - 1]);
  return positions[k - 1].lerp(positions[k], btScalar(t));
}

const std::string& ToolScript::phase(int tick) const {
  return phases[segmentOf(times, tick * tickTime)];
}

namespace scene {

ToolScript readTool(Fields& tool, double scale) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  ToolScript result;
  result.present = true;
  result.radius = tool.number("radius", 5e-3 / scale, 0, kInf, true) * scale;
  result.tickTime = tool.number("tick_ms", 1, 0, 1000, true) * 1e-3;
  result.wholeEvery = tool.integer("whole_every", 1, 1, 1000000);
  result.regionMargin = tool.number("region_margin_mm", 10, 0, kInf, true) * 1e-3;
  result.regionDrift = tool.number("region_drift_mm", 2, 0, kInf) * 1e-3;
  if (!(result.regionDrift < result.regionMargin))
    tool.fail("region_drift_mm", "expected less than region_margin_mm");
  const Json& path = tool.array("path");
  Json complete = Json::array();
  for (size_t i = 0; i < path.size(); ++i) {
    Fields point(path[i], tool.pathOf("path") + "[" + std::to_string(i) + "]", tool.source());
    const double time = point.number("time_ms", 0, 0, 1e9) * 1e-3;
    if (i == 0 ? time != 0 : !(time > result.times.back()))
      point.fail("time_ms", i == 0 ? "must be 0 at the first waypoint"
                                   : "must be later than the waypoint before");
    result.times.push_back(time);
    result.positions.push_back(point.vector3("position", btVector3(0, 0, 0)) * btScalar(scale));
    result.phases.push_back(point.text("phase", "move", kMaxNameBytes));
    complete.push_back(point.finish());
  }
  if (result.times.empty()) tool.fail("path", "expected at least one waypoint");
  tool.set("path", std::move(complete));
  return result;
}

}  // namespace scene
}  // namespace fibremss
