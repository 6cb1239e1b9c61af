#include "ReportScaling.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

namespace fibremss {
namespace {

double number(const nlohmann::json& object, const char* key) {
  const auto it = object.find(key);
  return it != object.end() && it->is_number() ? it->get<double>() : NAN;
}

std::string text(const nlohmann::json& run, const char* key) {
  return run.value(key, std::string());
}

/// The N of a "threads=N" item, or -1.
int threadsItem(const std::string& item) {
  constexpr const char* kKey = "threads=";
  if (item.rfind(kKey, 0) != 0) return -1;
  return std::atoi(item.c_str() + std::char_traits<char>::length(kKey));
}

/// Whether the run is FibreMSS as configured by the scene, at most with its threads changed.
bool plainFibre(const nlohmann::json& run) {
  const std::string method = text(run, "method");
  if (method == "fibremss") return true;
  if (method.rfind("fibremss:", 0) != 0) return false;
  std::istringstream items(method.substr(9));
  for (std::string item; std::getline(items, item, '+');)
    if (threadsItem(item) < 0) return false;
  return true;
}

/// The solver threads of a run: its variant's or its overrides' "threads=N", else 0 (the
/// machine's hardware threads).
int threadsOf(const nlohmann::json& run) {
  int threads = 0;
  for (const auto& item : run.value("scene_overrides", nlohmann::json::array()))
    if (item.is_string()) threads = std::max(threads, threadsItem(item.get<std::string>()));
  const std::string method = text(run, "method");
  const size_t at = method.find("threads=");
  if (at != std::string::npos) threads = threadsItem(method.substr(at));
  return threads;
}

std::string cell(double value, const char* format = "%.3g") {
  if (!std::isfinite(value)) return "—";
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, format, value);
  return buffer;
}

}  // namespace

std::string scalingReport(const nlohmann::json& runs) {
  struct Row {
    std::string scene;
    int resolution;
    int threads;
    const nlohmann::json* run;
  };
  std::vector<Row> rows;
  for (const auto& run : runs)
    if (plainFibre(run))
      rows.push_back(
          {text(run, "scene"), static_cast<int>(number(run, "resolution")), threadsOf(run), &run});
  if (rows.size() < 2) return "";
  std::stable_sort(rows.begin(), rows.end(), [](const Row& a, const Row& b) {
    return std::tie(a.scene, a.resolution, a.threads) < std::tie(b.scene, b.resolution, b.threads);
  });
  const auto find = [&](const Row& row, auto&& accept) -> const nlohmann::json* {
    for (const auto& run : runs)
      if (text(run, "scene") == row.scene &&
          static_cast<int>(number(run, "resolution")) == row.resolution && accept(run))
        return &run;
    return nullptr;
  };

  std::ostringstream out;
  out << "\n## Scaling: FibreMSS by resolution and threads\n\n"
      << "Medians per iteration [ms]; collision = muscle CD + bone CD + response; ns/particle = "
         "ms/iteration per particle (flat when the cost grows linearly); speed-up = the "
         "1-thread run's ms/iteration over this one's; btSoftBody ratio = its ms per simulated "
         "step over FibreMSS's, same scene and resolution; peak MB = the resident set high-water "
         "mark of the whole process (preparation and earlier runs included). Threads 0 = the "
         "machine's hardware threads.\n\n"
      << "| scene | R | threads | particles | ms/iteration | MSS | muscle CD | bone CD | "
         "response | output | collision | speed-up | ns/particle | btSoftBody ms/step | "
         "FibreMSS ms/step | btSoftBody ratio | peak MB |\n"
      << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const Row& row : rows) {
    const nlohmann::json& run = *row.run;
    const nlohmann::json& timing = run.value("timing", nlohmann::json::object());
    const double iteration = number(run, "ms_per_iteration");
    const double collision =
        number(timing, "muscle_cd") + number(timing, "bone_cd") + number(timing, "response");
    const double particles = number(run, "particles");
    const nlohmann::json* single =
        find(row, [](const nlohmann::json& r) { return plainFibre(r) && threadsOf(r) == 1; });
    const nlohmann::json* softBody =
        find(row, [](const nlohmann::json& r) { return text(r, "method") == "btsoftbody"; });
    const double softBodyStep = softBody ? number(*softBody, "ms_per_step") : NAN;
    const double step = number(run, "ms_per_step");
    out << "| " << row.scene << " | " << row.resolution << " | " << row.threads << " | "
        << cell(particles, "%.0f") << " | " << cell(iteration) << " | "
        << cell(number(timing, "mss")) << " | " << cell(number(timing, "muscle_cd")) << " | "
        << cell(number(timing, "bone_cd")) << " | " << cell(number(timing, "response")) << " | "
        << cell(number(timing, "output")) << " | " << cell(100 * collision / iteration, "%.0f%%")
        << " | " << cell(single ? number(*single, "ms_per_iteration") / iteration : NAN, "%.2f×")
        << " | " << cell(1e6 * iteration / particles) << " | " << cell(softBodyStep) << " | "
        << cell(step) << " | " << cell(softBodyStep / step, "%.1f×") << " | "
        << cell(number(run, "peak_memory_mb"), "%.0f") << " |\n";
  }
  return out.str();
}

}  // namespace fibremss
