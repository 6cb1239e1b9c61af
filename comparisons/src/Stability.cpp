#include "fibremss/Stability.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <limits>
#include <memory>
#include <type_traits>

#include "fibremss/Error.h"
#include "fibremss/FibreRun.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "fibremss/SceneSystem.h"

namespace fibremss {
namespace {

using Clock = std::chrono::steady_clock;

/// A case loaded and prepared once, run by many cells (preparation does not depend on the
/// integrator or the time step). Calibration probes hold the first pose and add noise.
struct PreparedCase {
  LoadedScene scene;       ///< simulation settings are changed per cell
  PreparedScene prepared;  ///< particles, springs, bones
  double freeMass = 0;     ///< mass of the free particles of all muscles [kg]
};

/// The options' overrides, then the case's own.
std::vector<std::string> caseOverrides(const StabilityCase& stabilityCase,
                                       const StabilityOptions& options) {
  std::vector<std::string> overrides = options.overrides;
  overrides.insert(overrides.end(), stabilityCase.overrides.begin(), stabilityCase.overrides.end());
  return overrides;
}

PreparedCase prepareCase(const StabilityCase& stabilityCase, const StabilityOptions& options,
                         bool calibration = false) {
  PreparedCase result;
  result.scene = loadScene(stabilityCase.scene, caseOverrides(stabilityCase, options));
  if (calibration) {
    result.scene.poseCount = 1;  // every step holds the first pose
    result.scene.simulation.initialNoise = static_cast<btScalar>(options.calibrationNoise);
  }
  for (MuscleInput& muscle : result.scene.muscles)
    muscle.parameters.springs.kappa *= static_cast<btScalar>(stabilityCase.kappaFactor);
  result.prepared = prepareScene(result.scene);
  for (const auto& muscle : result.prepared.muscles)
    result.freeMass += static_cast<double>(muscle->particleMass) *
                       static_cast<double>(muscle->particleCount() - muscle->fixedParticles.size());
  return result;
}

/// Whether the user asked the matrix to stop.
bool cancelled(const StabilityOptions& options) {
  return options.cancel && options.cancel->load();
}

/// A cell's figures and outcome from its run: NaN, exploded, out of its time box
/// (`timedOut`), interrupted, or else its kinetic energy checked for growth (`freeMass` [kg]).
void judgeCell(const RunMetrics& metrics, bool timedOut, double freeMass,
               const StabilityOptions& options, StabilityCell& cell) {
  cell.steps = metrics.steps;
  cell.iterations = metrics.iterations;
  cell.msPerIteration = metrics.msPerIteration;
  cell.wallSeconds = metrics.wallSeconds;
  cell.failedStep = metrics.failedStep;
  if (metrics.nan) {
    cell.outcome = CellOutcome::Nan;
  } else if (metrics.exploded) {
    cell.outcome = CellOutcome::Exploded;
  } else if (metrics.interrupted && timedOut) {
    cell.outcome = CellOutcome::Timeout;
    cell.failedStep = metrics.steps;
    cell.message = "stopped after " + std::to_string(metrics.steps) + " steps (" +
                   std::to_string(options.cellSeconds) + " s box)";
  } else if (metrics.interrupted) {
    cell.outcome = CellOutcome::Interrupted;
    cell.message = "interrupted after " + std::to_string(metrics.steps) + " steps";
  } else {
    const EnergyCheck energy =
        checkEnergy(cell.kineticEnergy, options.energyGrowth,
                    0.5 * freeMass * options.energyFloorSpeed * options.energyFloorSpeed);
    cell.energyRatio = energy.ratio;
    if (!energy.bounded) {
      cell.outcome = CellOutcome::Energy;
      cell.failedStep = energy.growthStep;
    }
  }
}

/// One run of a prepared case; `steps` < 0 runs every pose. Never throws.
StabilityCell runPrepared(PreparedCase& prepared, const std::string& caseLabel,
                          const std::string& integrator, double dt, int steps,
                          const StabilityOptions& options) {
  StabilityCell cell;
  cell.caseLabel = caseLabel;
  cell.integrator = integrator;
  cell.dt = dt;
  Integrator kind{};
  if (!fromString(integrator, kind)) {
    cell.outcome = CellOutcome::Error;
    cell.message = "unknown integrator " + integrator;
    return cell;
  }
  if (!integratorAvailable(kind)) {
    cell.outcome = CellOutcome::Unavailable;
    cell.message = "the solver does not implement " + integrator + " yet";
    return cell;
  }
  MuscleSystemDef& simulation = prepared.scene.simulation;
  simulation.integrator = kind;
  simulation.stepSettings.adaptiveTimeStep = false;
  simulation.stepSettings.timeStep = static_cast<btScalar>(dt);
  // Failures must be seen, not healed by a rollback.
  simulation.onFailure = FailurePolicy::Report;

  std::atomic<bool> stop{false};
  bool timedOut = false;
  FibreRunOptions run;
  run.steps = steps;
  run.frameEvery = 0;
  run.keepPoseSurfaces = false;
  run.cancel = &stop;
  run.interrupt = options.cancel;
  run.progress = [&](const RunProgress& progress) {
    const StepStats& last = *progress.lastStep;
    const double speed =
        last.lastTimeStep > 0 ? static_cast<double>(last.meanDisplacement / last.lastTimeStep) : 0;
    cell.kineticEnergy.push_back(0.5 * prepared.freeMass * speed * speed);
    if (cancelled(options)) {
      stop.store(true);
    } else if (progress.seconds > options.cellSeconds) {
      timedOut = true;
      stop.store(true);
    }
  };
  try {
    // The run first: it is what sets timedOut (an argument's order of evaluation is unspecified).
    const RunMetrics metrics = runFibreMSS(prepared.scene, prepared.prepared, run);
    judgeCell(metrics, timedOut, prepared.freeMass, options, cell);
  } catch (const std::exception& e) {
    cell.outcome = CellOutcome::Error;
    cell.message = e.what();
  }
  return cell;
}

void log(const StabilityOptions& options, const std::string& line) {
  if (options.log) options.log(line);
}

/// "1.5e-05".
std::string seconds(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g", value);
  return text;
}

/// The bisection of findStableStep on one already prepared calibration case.
StableStep calibrate(PreparedCase& prepared, const StabilityCase& calibrationCase,
                     const std::string& integrator, const StabilityOptions& options) {
  StableStep result;
  result.integrator = integrator;
  result.limitedBy = calibrationCase.label;
  Integrator kind{};
  if (!fromString(integrator, kind))
    throw InputError("--integrators", integrator, "unknown integrator");
  result.available = integratorAvailable(kind);
  if (!result.available) return result;
  auto stable = [&](double dt) {
    ++result.probes;
    const StabilityCell cell = runPrepared(prepared, calibrationCase.label, integrator, dt,
                                           options.calibrationSteps, options);
    // Energy is no criterion here: relaxing noise from rest, it grows from zero at any dt.
    return cell.outcome == CellOutcome::Ok || cell.outcome == CellOutcome::Energy;
  };
  double low = options.calibrationLow, high = options.calibrationHigh;
  if (stable(high)) {
    result.dt = high;
    result.capped = true;
    return result;
  }
  if (!stable(low)) {
    result.dt = low;
    result.found = false;
    return result;
  }
  while (high / low > options.calibrationRatio && !cancelled(options)) {
    const double middle = std::sqrt(low * high);
    (stable(middle) ? low : high) = middle;
  }
  result.dt = low;
  return result;
}

/// Every calibration case prepared (first pose held, noise added), in options.calibration order.
std::vector<PreparedCase> prepareCalibration(const StabilityOptions& options) {
  if (options.calibration.empty())
    throw InputError("--calibrate", "", "at least one calibration case is needed");
  std::vector<PreparedCase> prepared;
  for (const StabilityCase& calibrationCase : options.calibration)
    prepared.push_back(prepareCase(calibrationCase, options, true));
  return prepared;
}

/// findStableStep on prepared calibration cases: each case's bisection, the smallest step kept.
StableStep calibrateAll(std::vector<PreparedCase>& prepared, const std::string& integrator,
                        const StabilityOptions& options) {
  StableStep result = calibrate(prepared.front(), options.calibration.front(), integrator, options);
  for (size_t c = 1; c < prepared.size() && result.available && result.found; ++c) {
    if (cancelled(options)) break;
    const StableStep step = calibrate(prepared[c], options.calibration[c], integrator, options);
    result.probes += step.probes;
    result.capped = result.capped && step.capped;
    if (!step.found || step.dt < result.dt) {
      result.dt = step.dt;
      result.found = step.found;
      result.limitedBy = step.limitedBy;
    }
  }
  return result;
}

}  // namespace

const char* toString(CellOutcome outcome) {
  static const char* const names[] = {"ok",      "nan",         "exploded", "energy",
                                      "timeout", "unavailable", "error",    "interrupted"};
  return names[static_cast<size_t>(outcome)];
}

std::vector<std::string> allIntegratorNames() {
  std::vector<std::string> names;
  for (int value = 0; value <= std::numeric_limits<std::underlying_type_t<Integrator>>::max();
       ++value)
    if (const std::string name = toString(static_cast<Integrator>(value)); name != "unknown")
      names.push_back(name);
  return names;
}

bool integratorAvailable(Integrator integrator) {
  MuscleSystemDef def;
  def.integrator = integrator;
  MuscleSystem system(def);
  try {
    system.step();  // an empty system: only the integrator lookup can fail
  } catch (const InputError&) {
    return false;
  }
  return true;
}

std::vector<StabilityCase> defaultHardCases() {
  std::vector<StabilityCase> cases;
  for (int step : {2, 4, 5, 10}) {
    const std::string stepDeg = "step_deg=" + std::to_string(step);
    cases.push_back({"hip-extension " + stepDeg, "hip-extension", {stepDeg}, 1});
  }
  cases.push_back({"pinch", "pinch", {}, 1});
  cases.push_back({"hip-extension kappa x100", "hip-extension", {"step_deg=10"}, 100});
  cases.push_back({"tension-spike", "tension-spike", {}, 1});
  return cases;
}

StabilityCase parseStabilityCase(const std::string& text) {
  StabilityCase result;
  result.label = text;
  std::string rest = text;
  if (const size_t star = rest.find("*kappa="); star != std::string::npos) {
    const std::string factor = rest.substr(star + 7);
    size_t used = 0;
    try {
      result.kappaFactor = std::stod(factor, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != factor.size() || !(result.kappaFactor > 0))
      throw InputError("stability case", text, "'*kappa=' needs a positive number");
    rest = rest.substr(0, star);
  }
  const size_t colon = rest.find(':');
  result.scene = rest.substr(0, colon);
  if (result.scene.empty()) throw InputError("stability case", text, "no scene name");
  if (colon == std::string::npos) return result;
  size_t start = colon + 1;
  while (true) {
    const size_t plus = rest.find('+', start);
    const std::string part = rest.substr(start, plus - start);
    if (part.find('=') == std::string::npos || part.front() == '=')
      throw InputError("stability case", text,
                       "override '" + part + "' is not <key>=<value> (parts joined by '+')");
    result.overrides.push_back(part);
    if (plus == std::string::npos) break;
    start = plus + 1;
  }
  return result;
}

EnergyCheck checkEnergy(std::span<const double> series, double growthFactor, double floor) {
  EnergyCheck result;
  if (series.size() < 2) return result;
  for (size_t i = 0; i < series.size(); ++i)
    if (!std::isfinite(series[i])) {
      result.bounded = false;
      result.growthStep = static_cast<int>(i);
      result.ratio = std::numeric_limits<double>::infinity();
      return result;
    }
  const size_t lastStart = series.size() - (series.size() + 3) / 4;
  const double earlier = *std::max_element(series.begin(), series.begin() + lastStart);
  const double last = *std::max_element(series.begin() + lastStart, series.end());
  result.ratio =
      earlier > 0 ? last / earlier : (last > 0 ? std::numeric_limits<double>::infinity() : 0);
  const double limit = growthFactor * earlier + floor;
  const auto above = [&](double e) { return e > limit; };
  const auto first = std::find_if(series.begin() + lastStart, series.end(), above);
  if (first == series.end()) return result;
  // A rise that falls back to the earlier level and stays within the limit is a transient.
  const auto latest = std::find_if(series.rbegin(), series.rend(), above).base();
  if (std::any_of(latest, series.end(), [&](double e) { return e <= earlier; })) return result;
  result.bounded = false;
  result.growthStep = static_cast<int>(first - series.begin());
  return result;
}

StabilityCell runStabilityCell(const StabilityCase& stabilityCase, const std::string& integrator,
                               double dt, const StabilityOptions& options) {
  try {
    PreparedCase prepared = prepareCase(stabilityCase, options);
    return runPrepared(prepared, stabilityCase.label, integrator, dt, -1, options);
  } catch (const std::exception& e) {
    StabilityCell cell;
    cell.caseLabel = stabilityCase.label;
    cell.integrator = integrator;
    cell.dt = dt;
    cell.outcome = CellOutcome::Error;
    cell.message = e.what();
    return cell;
  }
}

std::string calibrationLabels(const StabilityOptions& options) {
  std::string labels;
  for (const StabilityCase& c : options.calibration)
    labels += (labels.empty() ? "" : ", ") + c.label;
  return labels;
}

namespace {

/// Calibrates each integrator's stable step on options.calibration into matrix.stableSteps,
/// logging each; stops at a cancel.
void calibrateIntegrators(const std::vector<std::string>& integrators,
                          const StabilityOptions& options, StabilityMatrix& matrix) {
  log(options, "calibrating on " + calibrationLabels(options));
  std::vector<PreparedCase> calibration = prepareCalibration(options);
  for (const std::string& integrator : integrators) {
    const StableStep step = calibrateAll(calibration, integrator, options);
    if (cancelled(options)) break;  // its bisection was cut short
    matrix.stableSteps.push_back(step);
    if (!step.available)
      log(options, "  " + integrator + ": unavailable");
    else
      log(options, "  " + integrator + ": stable step " + (step.capped ? ">= " : "") +
                       seconds(step.dt) + " s" + (step.found ? "" : " (none found; lowest)") +
                       " on " + step.limitedBy + " after " + std::to_string(step.probes) +
                       " probes");
  }
}

/// A cell's log line after its number: case, integrator, dt factor and dt, outcome, steps.
std::string cellLine(const StabilityCell& cell, double factor) {
  std::string line = cell.caseLabel + " " + cell.integrator + " x" + seconds(factor) + " (dt " +
                     seconds(cell.dt) + " s): " + toString(cell.outcome);
  if (cell.failedStep >= 0) line += " at step " + std::to_string(cell.failedStep);
  if (cell.outcome != CellOutcome::Unavailable)
    line += ", " + std::to_string(cell.steps) + " steps in " + seconds(cell.wallSeconds) + " s";
  if (cell.outcome == CellOutcome::Error) line += ": " + cell.message;
  return line;
}

}  // namespace

StableStep findStableStep(const std::string& integrator, const StabilityOptions& options) {
  std::vector<PreparedCase> prepared = prepareCalibration(options);
  return calibrateAll(prepared, integrator, options);
}

StabilityCell runCalibrationProbe(const StabilityCase& calibrationCase,
                                  const std::string& integrator, double dt,
                                  const StabilityOptions& options) {
  PreparedCase prepared = prepareCase(calibrationCase, options, true);
  return runPrepared(prepared, calibrationCase.label, integrator, dt, options.calibrationSteps,
                     options);
}

StabilityMatrix runStabilityMatrix(const std::vector<StabilityCase>& cases,
                                   const StabilityOptions& options) {
  // Every scene loads (files, fields, overrides) before any work: bad input is an InputError,
  // not a matrix of error cells after minutes of calibration.
  for (const StabilityCase& calibrationCase : options.calibration)
    loadScene(calibrationCase.scene, caseOverrides(calibrationCase, options));
  for (const StabilityCase& stabilityCase : cases)
    loadScene(stabilityCase.scene, caseOverrides(stabilityCase, options));
  const auto start = Clock::now();
  StabilityMatrix matrix;
  matrix.cases = cases;
  matrix.dtFactors = options.dtFactors;
  matrix.overrides = options.overrides;
  const std::vector<std::string> integrators =
      options.integrators.empty() ? allIntegratorNames() : options.integrators;

  calibrateIntegrators(integrators, options, matrix);

  const size_t total = cases.size() * integrators.size() * options.dtFactors.size();
  size_t done = 0;
  for (const StabilityCase& stabilityCase : cases) {
    if (cancelled(options) || matrix.stableSteps.size() < integrators.size()) break;
    log(options, "case " + stabilityCase.label + ": preparing");
    std::unique_ptr<PreparedCase> prepared;
    std::string failure;
    try {
      prepared = std::make_unique<PreparedCase>(prepareCase(stabilityCase, options));
    } catch (const std::exception& e) {
      failure = e.what();
    }
    for (size_t i = 0; i < integrators.size(); ++i) {
      for (double factor : options.dtFactors) {
        if (cancelled(options)) break;
        const double dt = factor * matrix.stableSteps[i].dt;
        StabilityCell cell;
        if (prepared) {
          cell = runPrepared(*prepared, stabilityCase.label, integrators[i], dt, -1, options);
        } else {
          cell.caseLabel = stabilityCase.label;
          cell.integrator = integrators[i];
          cell.dt = dt;
          cell.outcome = CellOutcome::Error;
          cell.message = failure;
        }
        cell.dtFactor = factor;
        std::string line = "[";
        line +=
            std::to_string(++done) + "/" + std::to_string(total) + "] " + cellLine(cell, factor);
        log(options, line);
        matrix.cells.push_back(std::move(cell));
      }
    }
  }
  matrix.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  matrix.interrupted = cancelled(options);
  if (matrix.interrupted)
    log(options, "interrupted: " + std::to_string(matrix.cells.size()) + " of " +
                     std::to_string(total) + " cells run");
  return matrix;
}

}  // namespace fibremss
