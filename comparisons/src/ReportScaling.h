#pragma once
// The scaling table of report.md and FibreMSS's speed against the btSoftBody
// baseline, internal to the comparisons library.
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace fibremss {

/// A markdown section: every plain FibreMSS run of the summary (method "fibremss" or a
/// "fibremss:threads=N" variant) by scene, resolution and thread count, with per-part ms per
/// iteration, the collision share, the speed-up over one thread, the cost per particle, the
/// btSoftBody run of the same scene and resolution per simulated step, and the peak resident
/// set. Empty when fewer than two such runs exist (nothing scales).
std::string scalingReport(const nlohmann::json& runs);

/// One plain FibreMSS run against the btSoftBody run of the same scene and resolution: the
/// ratio of their median wall times per simulated step (pose) and per time step (a FibreMSS
/// iteration, a Bullet world substep: the two take different numbers of them to reach a pose),
/// with the threads each used and the poses both simulated (a median covers only the poses its
/// run reached).
struct SoftBodyRatio {
  std::string scene;               ///< scene name
  int resolution = 0;              ///< particles per fibre
  std::string method;              ///< the FibreMSS run's method name
  int threads = 0;                 ///< FibreMSS's solver threads (0: the machine's, not recorded)
  int softBodyThreads = 1;         ///< btSoftBody's (Debian's Bullet has no task scheduler)
  double ratio = NAN;              ///< btSoftBody ms per step ÷ FibreMSS ms per step
  double softBodyMsPerStep = NAN;  ///< btSoftBody's median ms per step (one pose)
  /// btSoftBody ms per world substep ÷ FibreMSS ms per iteration (each one time step dt).
  double timeStepRatio = NAN;
  int poses = 0;                  ///< poses both runs simulated
  int of = 0;                     ///< poses of the motion
  std::string stopped;            ///< why a run ended before the last pose ("" if neither did)
  std::string statement() const;  ///< the ratio in one sentence, thread counts and poses
  nlohmann::json toJson() const;  ///< for summary.json
};

/// The ratio for every plain FibreMSS run that has a btSoftBody run beside it.
std::vector<SoftBodyRatio> softBodyRatios(const nlohmann::json& runs);

/// A markdown section stating every softBodyRatios entry; empty when there is none.
std::string softBodyRatioReport(const nlohmann::json& runs);

}  // namespace fibremss
