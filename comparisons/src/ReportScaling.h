#pragma once
// The scaling table of report.md (issue 6), internal to the comparisons library.
#include <nlohmann/json.hpp>
#include <string>

namespace fibremss {

/// A markdown section: every plain FibreMSS run of the summary (method "fibremss" or a
/// "fibremss:threads=N" variant) by scene, resolution and thread count, with per-part ms per
/// iteration, the collision share, the speed-up over one thread, the cost per particle, the
/// btSoftBody run of the same scene and resolution per simulated step, and the peak resident
/// set. Empty when fewer than two such runs exist (nothing scales).
std::string scalingReport(const nlohmann::json& runs);

}  // namespace fibremss
