#include "ReportScaling.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "SummaryFields.h"
#include "TextList.h"

namespace fibremss {
namespace {

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

/// The solver threads of a run: as recorded by `compare`, else its variant's or its
/// overrides' "threads=N", else 0 (the machine's hardware threads).
int threadsOf(const nlohmann::json& run) {
  if (const double recorded = number(run, "threads"); recorded > 0)
    return static_cast<int>(recorded);
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

/// JSON has no NaN: null for a ratio that could not be taken.
nlohmann::json numberOrNull(double value) {
  return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
}

/// Why a run ended before the last pose of its motion: "" when it did not.
std::string stopReason(const nlohmann::json& run) {
  const std::string who = text(run, "method") + " ";
  if (run.value("interrupted", false))
    return who + "was stopped (time budget) after " + cell(number(run, "steps"), "%.0f") + " poses";
  const std::string step = cell(number(run, "failed_step"), "%.0f");
  if (run.value("nan", false)) return who + "hit NaN at step " + step;
  if (run.value("exploded", false)) return who + "exploded (a link past 3×) at step " + step;
  return "";
}

/// "1 thread", "2 threads"; 0: the machine's hardware threads (not recorded).
std::string threadsText(int threads) {
  if (threads <= 0) return "the machine's hardware threads";
  return std::to_string(threads) + (threads == 1 ? " thread" : " threads");
}

/// `run` (a plain FibreMSS run) against the first btSoftBody run of its scene and resolution.
std::optional<SoftBodyRatio> againstSoftBody(const nlohmann::json& runs,
                                             const nlohmann::json& run) {
  for (const auto& softBody : runs) {
    if (text(softBody, "method") != "btsoftbody" || text(softBody, "scene") != text(run, "scene") ||
        number(softBody, "resolution") != number(run, "resolution"))
      continue;
    SoftBodyRatio r;
    r.scene = text(run, "scene");
    r.resolution = static_cast<int>(number(run, "resolution"));
    r.method = text(run, "method");
    r.threads = threadsOf(run);
    if (const double threads = number(softBody, "threads"); threads > 0)
      r.softBodyThreads = static_cast<int>(threads);
    r.softBodyMsPerStep = number(softBody, "ms_per_step");
    r.ratio = r.softBodyMsPerStep / number(run, "ms_per_step");
    r.timeStepRatio = number(softBody, "ms_per_time_step") / number(run, "ms_per_time_step");
    r.of = std::max(run.value("poses", 0), softBody.value("poses", 0));
    r.poses = std::min({run.value("steps", 0), softBody.value("steps", 0), r.of});
    for (const std::string& reason : {stopReason(run), stopReason(softBody)})
      if (!reason.empty()) appendItem(r.stopped, reason);
    return r;
  }
  return std::nullopt;
}

}  // namespace

std::string SoftBodyRatio::statement() const {
  std::string line = "FibreMSS (" + threadsText(threads) + ") vs btSoftBody (Bullet, " +
                     threadsText(softBodyThreads) + "): " + cell(ratio, "%.1f×") +
                     " per simulated step (one pose), " + cell(timeStepRatio, "%.1f×") +
                     " per time step (a FibreMSS iteration against a Bullet substep) (" + scene +
                     ", resolution " + std::to_string(resolution) + ", " + std::to_string(poses) +
                     "/" + std::to_string(of) + " poses";
  if (poses < of)
    line += (stopped.empty() ? std::string(": ") : ": " + stopped + "; ") +
            "the ratio covers those poses only";
  return line + ")";
}

nlohmann::json SoftBodyRatio::toJson() const {
  return {{"scene", scene},
          {"resolution", resolution},
          {"fibremss_method", method},
          {"fibremss_threads", threads},
          {"btsoftbody_threads", softBodyThreads},
          {"ratio", numberOrNull(ratio)},
          {"time_step_ratio", numberOrNull(timeStepRatio)},
          {"poses", poses},
          {"of", of},
          {"stopped", stopped},
          {"statement", statement()}};
}

std::vector<SoftBodyRatio> softBodyRatios(const nlohmann::json& runs) {
  std::vector<SoftBodyRatio> ratios;
  for (const auto& run : runs)
    if (plainFibre(run))
      if (auto ratio = againstSoftBody(runs, run)) ratios.push_back(std::move(*ratio));
  return ratios;
}

std::string softBodyRatioReport(const nlohmann::json& runs) {
  const std::vector<SoftBodyRatio> ratios = softBodyRatios(runs);
  if (ratios.empty()) return "";
  std::string out =
      "\n## FibreMSS against btSoftBody\n\nMedian wall time per simulated step (one pose) of "
      "btSoftBody over FibreMSS's, the same scene measured in the same run (same particles "
      "and springs, collisions on in both), each with the threads it ran on; and per time step "
      "of simulated time dt, which FibreMSS takes `simulation.iterations` of per pose and "
      "btSoftBody its world substeps:\n\n";
  for (const SoftBodyRatio& ratio : ratios) out += "- " + ratio.statement() + "\n";
  return out;
}

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
         "step (Bullet, one thread) over FibreMSS's on this row's threads, same scene and "
         "resolution, \"(k/N poses)\" when either stopped before the last pose; per time step = "
         "the same for one time step dt (its world substep over FibreMSS's iteration); peak MB = "
         "the resident set high-water mark of the whole process (preparation and earlier runs "
         "included). Threads 0 = the machine's hardware threads (not recorded).\n\n"
      << "| scene | R | threads | particles | ms/iteration | MSS | muscle CD | bone CD | "
         "response | output | collision | speed-up | ns/particle | btSoftBody ms/step | "
         "FibreMSS ms/step | btSoftBody ratio | per time step | peak MB |\n"
      << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const Row& row : rows) {
    const nlohmann::json& run = *row.run;
    const nlohmann::json& timing = run.value("timing", nlohmann::json::object());
    const double iteration = number(run, "ms_per_iteration");
    const double collision =
        number(timing, "muscle_cd") + number(timing, "bone_cd") + number(timing, "response");
    const double particles = number(run, "particles");
    const nlohmann::json* single =
        find(row, [](const nlohmann::json& r) { return plainFibre(r) && threadsOf(r) == 1; });
    const std::optional<SoftBodyRatio> ratio = againstSoftBody(runs, run);
    const double softBodyStep = ratio ? ratio->softBodyMsPerStep : NAN;
    std::string ratioCell = ratio ? cell(ratio->ratio, "%.1f×") : "—";
    if (ratio && ratio->poses < ratio->of)
      ratioCell +=
          " (" + std::to_string(ratio->poses) + "/" + std::to_string(ratio->of) + " poses)";
    const double step = number(run, "ms_per_step");
    out << "| " << row.scene << " | " << row.resolution << " | " << row.threads << " | "
        << cell(particles, "%.0f") << " | " << cell(iteration) << " | "
        << cell(number(timing, "mss")) << " | " << cell(number(timing, "muscle_cd")) << " | "
        << cell(number(timing, "bone_cd")) << " | " << cell(number(timing, "response")) << " | "
        << cell(number(timing, "output")) << " | " << cell(100 * collision / iteration, "%.0f%%")
        << " | " << cell(single ? number(*single, "ms_per_iteration") / iteration : NAN, "%.2f×")
        << " | " << cell(1e6 * iteration / particles) << " | " << cell(softBodyStep) << " | "
        << cell(step) << " | " << ratioCell << " | "
        << cell(ratio ? ratio->timeStepRatio : NAN, "%.0f×") << " | "
        << cell(number(run, "peak_memory_mb"), "%.0f") << " |\n";
  }
  return out.str();
}

}  // namespace fibremss
