#pragma once
// What `compare` and `merge` write: summary.json ({"scene", "machine", "command", "runs"}),
// report.md (every run in one table, how each was measured, the machine, the command, the
// seed 004 Table 1 comparison for thigh13) and speed_vs_error.png/.svg (+ penetration against
// step_deg for sweeps) drawn by gnuplot.
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "fibremss/Compare.h"

namespace fibremss {

/// {"cpu": model name, "cores": logical processors, "os": kernel} from /proc and uname.
nlohmann::json machineJson();

/// The summary of one comparison; each run is toJson(RunMetrics) plus "scene_overrides",
/// "resolution" and "step_deg".
nlohmann::json summaryJson(const Comparison& comparison, const std::string& command);

/// Several summaries as one: runs concatenated, scene names joined, machines and commands
/// listed. Throws InputError naming `sources[i]` when a summary lacks "runs".
nlohmann::json mergeSummaries(const std::vector<nlohmann::json>& summaries,
                              const std::vector<std::string>& sources);

/// Reads a summary.json (or a directory holding one); throws InputError when unreadable.
nlohmann::json readSummary(const std::string& path);

/// The thesis' seconds for 500 iterations (seed 004 Table 1) at resolution 20/40/60/80:
/// {mss, muscle CD, bone CD, total}; false for other resolutions.
bool thesisTable1(int resolution, double seconds[4]);

/// report.md text for a summary (`plots` lists the image files that exist, by name).
std::string reportMarkdown(const nlohmann::json& summary, const std::vector<std::string>& plots);

/// Writes summary.json, report.md and the plots into `outDir` (created if needed). Returns
/// the files written. Throws std::runtime_error when gnuplot fails (its message included).
std::vector<std::string> writeComparison(const nlohmann::json& summary, const std::string& outDir);

}  // namespace fibremss
