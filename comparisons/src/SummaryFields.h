#pragma once
// A summary.json's fields as the reports read them (internal to comparisons/src): a missing or
// mistyped field reads as NaN or "", so that summaries of older versions still read.
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "fibremss/Methods.h"

namespace fibremss {

/// The number at `key` of `object`, or NaN.
inline double number(const nlohmann::json& object, const char* key) {
  const auto it = object.find(key);
  return it != object.end() && it->is_number() ? it->get<double>() : NAN;
}

/// The string at `key` of `object`, or "".
inline std::string text(const nlohmann::json& object, const char* key) {
  const auto it = object.find(key);
  return it != object.end() && it->is_string() ? it->get<std::string>() : "";
}

/// What a summary's run is to the others (roleOf its "method").
inline MethodRole runRole(const nlohmann::json& run) {
  return roleOf(text(run, "method"));
}

/// Whether a run may be ranked: it reached its last pose intact, or it was stopped (its time
/// budget) after every one of the `rankedPoses` a ranking by the reference covers (0: no such
/// ranking), which its RMS to the reference then covers as every other run's does.
inline bool rankable(const nlohmann::json& run, int rankedPoses) {
  if (run.value("nan", false) || run.value("exploded", false)) return false;
  return !run.value("interrupted", false) ||
         (rankedPoses > 0 && number(run, "rms_to_reference_poses") >= rankedPoses);
}

}  // namespace fibremss
