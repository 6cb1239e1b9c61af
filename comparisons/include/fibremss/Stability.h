#pragma once
// The hard-case stability matrix: every integrator on hard cases (fast hip sweeps,
// pinch, stiff muscles, a tension spike) at multiples of its stable time step, each run judged
// by the same criteria and time-boxed. Used by `fibremss stability`.
#include <atomic>
#include <functional>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

#include "fibremss/Parameters.h"

namespace fibremss {

/// One row of the matrix: a scene, its overrides and a stiffness factor.
struct StabilityCase {
  std::string label;                   ///< row label, e.g. "hip-extension step_deg=4"
  std::string scene;                   ///< built-in scene name or .json path
  std::vector<std::string> overrides;  ///< --set overrides of this case
  double kappaFactor = 1;              ///< every muscle's κ multiplied by this (κ ×100 case)
};

/// The default hard cases: hip-extension at step_deg 2, 4, 5 and 10, pinch, hip-extension
/// (step_deg 10) with κ ×100, tension-spike.
std::vector<StabilityCase> defaultHardCases();

/// Parses "SCENE[:key=value[+key=value...]][*kappa=F]" (as `compare --methods` variants);
/// throws InputError when malformed.
StabilityCase parseStabilityCase(const std::string& text);

/// How one run ended.
enum class CellOutcome : uint8_t {
  Ok,           ///< every criterion held over the whole run
  Nan,          ///< a NaN or inf appeared
  Exploded,     ///< a spring beyond 3× its rest length
  Energy,       ///< kinetic energy grew (energyBounded says how)
  Timeout,      ///< the run did not finish within its wall-time box
  Unavailable,  ///< the integrator is not implemented (yet)
  Error,        ///< anything else threw (message kept)
  Interrupted,  ///< stopped by the user (StabilityOptions::cancel): no verdict
};
const char* toString(CellOutcome outcome);

/// The energy criterion: the series is bounded unless a value of its last quarter (the last
/// ceil(n/4) values) exceeds the limit growthFactor × (the largest value before it) + floor and
/// the series does not come back: no value after its last one above the limit is at or below
/// that largest earlier value. Driven scenes ramp their energy up while the motion builds (a hip
/// sweep's muscles start to wrap), so the reference is every step before the last quarter, not
/// only the first quarter: energy that peaks and settles passes, energy still climbing past all
/// before it fails; so does a spike that falls back to the earlier level (a projective solve's
/// late catch-up at a pose's end, docs/decisions.md), not one that stays above it.
/// Series shorter than 2 values are bounded; a non-finite value fails at its index.
struct EnergyCheck {
  bool bounded = true;  ///< no growth
  int growthStep = -1;  ///< first index of the last quarter above the limit (-1 if bounded)
  double ratio = 0;     ///< max(last quarter) / max(before it) (inf when that is 0)
};
EnergyCheck checkEnergy(std::span<const double> series, double growthFactor, double floor);

/// How the matrix runs.
struct StabilityOptions {
  std::vector<std::string> integrators;             ///< names (empty: every integrator)
  std::vector<double> dtFactors{1, 2, 5, 10, 100};  ///< multiples of the stable step
  /// Applied to every case (first). No strain limit: it holds every spring at its limit, so the
  /// matrix's 3x spring check would no longer see an integrator's blow-up (Verlet's stable step
  /// would read 1.91e-4 s instead of 4.53e-5 s).
  std::vector<std::string> overrides{"resolution=12", "strain_limit=0"};
  /// The stable-step cases: an integrator's stable step is the smallest of theirs, so that ×1 is
  /// stable on every case's own network (not only on one scene's: the volume term makes pinch's
  /// and tension-spike's stiffer than hip-extension's).
  std::vector<StabilityCase> calibration{{"hip-extension", "hip-extension", {}, 1},
                                         {"pinch", "pinch", {}, 1},
                                         {"tension-spike", "tension-spike", {}, 1}};
  int calibrationSteps = 3;        ///< steps of each calibration probe
  double calibrationNoise = 1e-4;  ///< probes: free particles displaced up to this at start [m]
  double calibrationLow = 1e-7;    ///< smallest dt tried [s]
  double calibrationHigh = 1e-2;   ///< largest dt tried [s]; stable there: reported as capped
  double calibrationRatio = 1.25;  ///< bisection stops when high / low is below this
  double cellSeconds = 30;         ///< wall-time box of one run (checked after every step)
  double energyGrowth = 10;        ///< EnergyCheck growthFactor
  double energyFloorSpeed = 1e-3;  ///< floor: ½·M·v² at this mean speed [m/s]
  std::function<void(const std::string&)> log;  ///< one progress line (may be empty)
  const std::atomic<bool>* cancel = nullptr;    ///< stop within the current step when true
};

/// One run of one case with one integrator at one dt.
struct StabilityCell {
  std::string caseLabel;                  ///< StabilityCase::label
  std::string integrator;                 ///< integrator name
  double dtFactor = 1;                    ///< multiple of the integrator's stable step
  double dt = 0;                          ///< fixed time step [s]
  CellOutcome outcome = CellOutcome::Ok;  ///< how it ended
  int failedStep = -1;                    ///< step of the failure (-1 if none)
  int steps = 0;                          ///< steps done
  long iterations = 0;                    ///< iterations done
  double energyRatio = 0;                 ///< EnergyCheck::ratio
  double msPerIteration = 0;              ///< median wall time of an iteration
  double wallSeconds = 0;                 ///< whole run, preparation excluded
  std::string message;                    ///< the exception text (Unavailable, Error)
  std::vector<double> kineticEnergy;      ///< per step [J] (see runStabilityCell)
};

/// One integrator's stable step on the calibration cases (the smallest of theirs).
struct StableStep {
  std::string integrator;  ///< integrator name
  bool available = true;   ///< false: not implemented
  double dt = 0;           ///< largest dt found stable on every case [s] (calibrationLow when none)
  bool capped = false;     ///< stable even at calibrationHigh on every case
  bool found = true;       ///< false: unstable even at calibrationLow on some case
  int probes = 0;          ///< runs the bisections made, all cases together
  std::string limitedBy;   ///< label of the case that set dt (the first one with the smallest)
};

/// Runs `stabilityCase` (prepared here) with `integrator` at a fixed `dt`, the guard set to
/// report only (so that failures are seen, not healed), judged by: no NaN/inf, no spring beyond
/// 3× its rest length (the solver's check at the last iteration of every step), kinetic energy
/// bounded (checkEnergy), finished within cellSeconds. The kinetic energy of step s is
/// ½·M·v̄², M the free particles' mass and v̄ their mean speed in the step's last iteration
/// (StepStats::meanDisplacement / lastTimeStep). Never throws: failures are outcomes.
StabilityCell runStabilityCell(const StabilityCase& stabilityCase, const std::string& integrator,
                               double dt, const StabilityOptions& options);

/// The largest stable fixed dt of `integrator` on every case of options.calibration: per case by
/// geometric bisection between calibrationLow and calibrationHigh, then the smallest. A probe
/// holds the case's first pose for calibrationSteps steps, its free particles displaced by up to
/// calibrationNoise at the start, and passes without NaN/inf and without a spring beyond 3× its
/// rest length: the numerical stability limit of the integrator on that spring network, free of
/// the motion (with a fixed iteration count per pose, a small dt makes the motion itself
/// violent).
StableStep findStableStep(const std::string& integrator, const StabilityOptions& options);
/// The calibration cases' labels, comma-separated ("hip-extension, pinch, tension-spike").
std::string calibrationLabels(const StabilityOptions& options);
/// One probe of findStableStep on `calibrationCase` at `dt` (its outcome: ok, nan or exploded
/// with the step).
StabilityCell runCalibrationProbe(const StabilityCase& calibrationCase,
                                  const std::string& integrator, double dt,
                                  const StabilityOptions& options);

/// The whole matrix.
struct StabilityMatrix {
  std::vector<StabilityCase> cases;     ///< rows
  std::vector<double> dtFactors;        ///< column groups' factors
  std::vector<StableStep> stableSteps;  ///< per integrator, in column order
  std::vector<StabilityCell> cells;     ///< case-major, then integrator, then factor
  std::vector<std::string> overrides;   ///< StabilityOptions::overrides
  double seconds = 0;                   ///< wall time of everything
  bool interrupted = false;  ///< stopped by options.cancel: later cells (and steps) not run
};

/// Loads every case's scene first (InputError before any work), then calibrates every
/// integrator and runs every case × integrator × factor. When
/// options.cancel turns true it stops within the running step, at the end of its iteration: that
/// cell is `interrupted`, no
/// later probe or cell runs (integrators not calibrated yet get no stable step) and the matrix
/// says `interrupted`.
StabilityMatrix runStabilityMatrix(const std::vector<StabilityCase>& cases,
                                   const StabilityOptions& options);

/// {"cases", "dt_factors", "stable_steps", "cells", ...}; per-step energies included.
nlohmann::json stabilityJson(const StabilityMatrix& matrix, const StabilityOptions& options);
/// The matrix as markdown: rows cases, columns integrator × factor, cells "ok", "nan@S",
/// "exploded@S", "energy@S", "timeout", "n/a"; the stable steps; the criteria.
std::string stabilityMarkdown(const StabilityMatrix& matrix, const StabilityOptions& options);

/// The names of every integrator the core has, in the order of enum class Integrator.
std::vector<std::string> allIntegratorNames();
/// True when the solver can run `integrator` (a MuscleSystem with it steps without throwing).
bool integratorAvailable(Integrator integrator);

/// `compare --methods` alias: "integrators" becomes one "fibremss:integrator=NAME" variant per
/// integrator the solver has; `log` hears of each one left out (may be empty).
std::vector<std::string> expandIntegratorMethods(
    const std::vector<std::string>& methods, const std::function<void(const std::string&)>& log);

/// report.md's integrators section for a summary's runs (ReportIntegrators.cpp): on
/// sphere-denoise, seed 002 Table 4.27's form with 002's figures beside ours; on other scenes
/// the FibreMSS runs by integrator with their place on the speed–error Pareto front. Empty when
/// the runs hold fewer than two integrators.
std::string integratorsReport(const nlohmann::json& runs);

}  // namespace fibremss
