// stability.json and stability.md of `fibremss stability`.
#include <cmath>
#include <cstdio>
#include <sstream>

#include "fibremss/Stability.h"

namespace fibremss {
namespace {

/// A number with 3 significant digits.
std::string number(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g", value);
  return text;
}

/// null for NaN and inf (JSON has neither).
nlohmann::json finiteOrNull(double value) {
  return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
}

/// "ok", "nan@3", "exploded@3", "energy@7", "timeout@12", "unavailable", "error".
std::string cellText(const StabilityCell& cell) {
  std::string text = toString(cell.outcome);
  if (cell.failedStep >= 0 && cell.outcome != CellOutcome::Ok) {
    text += '@';
    text += std::to_string(cell.failedStep);
  }
  return text;
}

std::string stableStepText(const StableStep& step) {
  if (!step.available) return "unavailable";
  std::string text = (step.capped ? "≥ " : "") + number(step.dt) + " s";
  if (!step.found) text += " (unstable even there; the lowest tried)";
  return text;
}

nlohmann::json caseJson(const StabilityCase& c) {
  return {{"label", c.label},
          {"scene", c.scene},
          {"overrides", c.overrides},
          {"kappa_factor", c.kappaFactor}};
}

}  // namespace

nlohmann::json stabilityJson(const StabilityMatrix& matrix, const StabilityOptions& options) {
  nlohmann::json cases = nlohmann::json::array(), steps = nlohmann::json::array(),
                 cells = nlohmann::json::array();
  for (const StabilityCase& c : matrix.cases) cases.push_back(caseJson(c));
  nlohmann::json calibrationCases = nlohmann::json::array();
  for (const StabilityCase& c : options.calibration) calibrationCases.push_back(caseJson(c));
  for (const StableStep& s : matrix.stableSteps) {
    steps.push_back({{"integrator", s.integrator},
                     {"available", s.available},
                     {"dt", s.dt},
                     {"capped", s.capped},
                     {"found", s.found},
                     {"probes", s.probes},
                     {"limited_by", s.limitedBy}});
  }
  for (const StabilityCell& cell : matrix.cells) {
    nlohmann::json energy = nlohmann::json::array();
    for (double e : cell.kineticEnergy) energy.push_back(finiteOrNull(e));
    cells.push_back({{"case", cell.caseLabel},
                     {"integrator", cell.integrator},
                     {"dt_factor", cell.dtFactor},
                     {"dt", cell.dt},
                     {"outcome", toString(cell.outcome)},
                     {"failed_step", cell.failedStep},
                     {"steps", cell.steps},
                     {"iterations", cell.iterations},
                     {"energy_ratio", finiteOrNull(cell.energyRatio)},
                     {"ms_per_iteration", finiteOrNull(cell.msPerIteration)},
                     {"wall_seconds", cell.wallSeconds},
                     {"message", cell.message},
                     {"kinetic_energy", energy}});
  }
  return {{"overrides", matrix.overrides},
          {"calibration",
           {{"cases", calibrationCases},
            {"steps", options.calibrationSteps},
            {"noise", options.calibrationNoise},
            {"low", options.calibrationLow},
            {"high", options.calibrationHigh},
            {"ratio", options.calibrationRatio}}},
          {"criteria",
           {{"energy_growth", options.energyGrowth},
            {"energy_floor_speed", options.energyFloorSpeed},
            {"cell_seconds", options.cellSeconds},
            {"spring_limit", 3}}},
          {"dt_factors", matrix.dtFactors},
          {"cases", cases},
          {"stable_steps", steps},
          {"cells", cells},
          {"seconds", matrix.seconds},
          {"interrupted", matrix.interrupted}};
}

std::string stabilityMarkdown(const StabilityMatrix& matrix, const StabilityOptions& options) {
  std::ostringstream out;
  out << "# FibreMSS hard-case stability matrix\n\n";
  std::string overrides;
  for (const std::string& o : matrix.overrides) overrides += " --set " + o;
  out << "Every case with" << (overrides.empty() ? " its own settings" : overrides)
      << ", a fixed time step (`--set time_step=fixed --set dt=...`) of each integrator's stable "
         "step × the factor, the numerical guard set to report only (`--set on_failure=report`); "
      << number(matrix.seconds) << " s in all.\n\n";
  if (matrix.interrupted)
    out << "**Interrupted** (Ctrl-C): " << matrix.cells.size() << " cells run, the last one "
        << "stopped where it was (`interrupted`); cells not run show `—`.\n\n";

  out << "## Stable steps\n\n"
      << "Measured, not derived: the largest fixed dt at which each of `"
      << calibrationLabels(options) << "`, its first pose held for " << options.calibrationSteps
      << " steps and its free particles displaced by up to "
      << number(options.calibrationNoise * 1000)
      << " mm at the start, ends without NaN/inf and without a spring beyond 3× its rest length "
         "(the integrator's numerical limit on that spring network, free of the motion; the "
         "smallest of the cases' steps, so that ×1 is stable on each case's own network); "
         "geometric bisection between "
      << number(options.calibrationLow) << " and " << number(options.calibrationHigh)
      << " s down to a ratio of " << number(options.calibrationRatio)
      << " (≥: stable at the largest dt tried). The cells then run the whole motion at a "
         "multiple of it; with a fixed iteration count per pose, dt also sets how fast the "
         "motion is in simulated time.\n\n"
      << "| integrator | stable step | set by | probes |\n|---|---|---|---|\n";
  for (const StableStep& step : matrix.stableSteps)
    out << "| " << step.integrator << " | " << stableStepText(step) << " | "
        << (step.available && !step.capped ? step.limitedBy : "—") << " | " << step.probes
        << " |\n";

  out << "\n## Matrix\n\nRows: cases; columns: integrator × factor on its stable step. "
         "`ok`: stable; `nan@S`, `exploded@S`, `energy@S`: failed at step S (the pose index from "
         "0); `timeout@S`: not finished within "
      << number(options.cellSeconds)
      << " s (S steps done); `unavailable`: the integrator is not implemented; `interrupted`: "
         "stopped by the user, no verdict.\n\n| case |";
  for (const StableStep& step : matrix.stableSteps)
    for (double factor : matrix.dtFactors)
      out << " " << step.integrator << " ×" << number(factor) << " |";
  out << "\n|---|";
  for (size_t i = 0; i < matrix.stableSteps.size() * matrix.dtFactors.size(); ++i) out << "---|";
  out << "\n";
  size_t index = 0;
  for (const StabilityCase& c : matrix.cases) {
    out << "| " << c.label << " |";
    for (size_t i = 0; i < matrix.stableSteps.size() * matrix.dtFactors.size(); ++i, ++index)
      out << " " << (index < matrix.cells.size() ? cellText(matrix.cells[index]) : "—") << " |";
    out << "\n";
  }

  out << "\n## Criteria\n\n"
      << "A run is stable when all of these hold over every step of the scene's motion:\n\n"
      << "- no NaN or inf in any particle or surface vertex (`nan`);\n"
      << "- no spring beyond 3× its rest length at the last iteration of a step (`exploded`);\n"
      << "- kinetic energy bounded (`energy`): with E(s) = ½·M·v̄(s)², M the mass of the free "
         "particles and v̄(s) their mean speed in the last iteration of step s (mean "
         "displacement / dt), the largest E of the last quarter of the steps must not exceed "
      << number(options.energyGrowth)
      << " × the largest E of the steps before it (driven scenes ramp their energy up while "
         "the motion builds; energy that peaks and settles passes) + ½·M·("
      << number(options.energyFloorSpeed * 1000)
      << " mm/s)² (the floor keeps a run that starts at rest from failing on noise), unless E "
         "comes back after its last step above that limit to at most the largest E before the "
         "last quarter (a transient, such as a projective solve's late catch-up at a pose's "
         "end);\n"
      << "- the run finishes within " << number(options.cellSeconds)
      << " s of wall time (`timeout`).\n";
  return out.str();
}

}  // namespace fibremss
