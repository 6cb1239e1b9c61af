// The integrators' section of report.md: on sphere-denoise, seed 002 Table 4.27's
// form with 002's figures beside ours; on any scene with several integrators, which runs lie on
// the speed–error Pareto front.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>

#include "SummaryFields.h"
#include "fibremss/Compare.h"
#include "fibremss/Scene.h"
#include "fibremss/Stability.h"

namespace fibremss {
namespace {

/// Seed 002 Table 4.27 (shape denoising of a 3840-vertex sphere, convergence = mean
/// displacement < 1 µm): ms per iteration and seconds to converge, per method.
struct Seed002Row {
  const char* method;  ///< 002's name
  double msPerIteration;
  double seconds;
};

/// 002's row for our integrator name (PBD ↔ 002's Newton–Raphson constraint projection, the
/// closest method it measured; XPBD has none).
bool seed002(const std::string& integrator, Seed002Row& row) {
  static const std::map<std::string, Seed002Row> table = {
      {"explicit-euler", {"Explicit Euler", 3.26, 11.7}},
      {"semi-implicit-euler", {"Semi-implicit Euler", 3.26, 2.7}},
      {"verlet", {"Verlet", 3.11, 2.9}},
      {"rk2", {"Runge-Kutta 2", 6.55, 6.3}},
      {"rk4", {"Runge-Kutta 4", 13.21, 12}},
      {"implicit-midpoint", {"Implicit Midpoint", 4.14, 2.8}},
      {"bdf2", {"BDF (alpha = 1/3)", 4.37, 3}},
      {"implicit-euler", {"Implicit Euler", 5.74, 1.2}},
      {"pbd", {"Newton-Raphson (constraints)", 7.76, 2.4}},
  };
  auto it = table.find(integrator);
  if (it == table.end()) return false;
  row = it->second;
  return true;
}

std::string format(const char* pattern, double value) {
  if (!std::isfinite(value)) return "—";
  char text[32];
  std::snprintf(text, sizeof text, pattern, value);
  return text;
}

bool failed(const nlohmann::json& run) {
  return run.value("nan", false) || run.value("exploded", false) ||
         run.value("failed_step", -1) >= 0;
}

/// The variant's iteration cap: the scene loaded with the run's overrides (NaN when the scene
/// cannot be loaded here, e.g. a file that has moved).
double iterationCap(const nlohmann::json& run) {
  std::vector<std::string> overrides;
  for (const auto& o : run.value("scene_overrides", nlohmann::json::array()))
    if (o.is_string()) overrides.push_back(o.get<std::string>());
  try {
    const MethodSpec spec = parseMethod(text(run, "method"));
    overrides.insert(overrides.end(), spec.overrides.begin(), spec.overrides.end());
    return loadScene(text(run, "scene"), overrides).simulation.stepSettings.iterations;
  } catch (const std::exception&) {
    return NAN;
  }
}

/// The FibreMSS runs (the default and its variants), in the order given.
std::vector<const nlohmann::json*> fibreRuns(const nlohmann::json& runs) {
  std::vector<const nlohmann::json*> result;
  for (const auto& run : runs) {
    const std::string method = text(run, "method");
    if (method == "fibremss" || method.rfind("fibremss:", 0) == 0) result.push_back(&run);
  }
  return result;
}

std::string denoiseTable(const std::vector<const nlohmann::json*>& runs) {
  std::ostringstream out;
  out << "\n## Integrators on sphere-denoise: seed 002 Table 4.27 beside ours\n\n"
      << "002 Table 4.27 (shape denoising of a 3840-vertex sphere with shape-memory and volume "
         "forces, convergence when the mean vertex displacement is below 1 µm; its machine, "
         "its model, its stiffness γ per method). Ours: the same sphere size as FibreMSS "
         "particles and springs, each integrator with the scene's settings, converged when the "
         "mean free-particle displacement of an iteration is below `epsilon` before the "
         "iteration cap. The displacement test depends on dt (a small dt moves little per "
         "iteration), so the spring deviation Σ|l − L0| / ΣL0 left at the end says how much of "
         "the noise each run removed. 002's iterations are its seconds / its ms per iteration. "
         "Compare the ranking, not the absolute times.\n\n"
      << "| integrator | ms/iteration | iterations | wall to converge [s] | converged | stable | "
         "spring deviation left | rank | 002 method | 002 ms/iteration | 002 iterations | 002 "
         "seconds | 002 rank |\n"
      << "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  struct Row {
    std::string integrator;
    const nlohmann::json* run = nullptr;
    bool converged = false, stable = false;
    double seconds = NAN;
    int rank = 0, rank002 = 0;
  };
  std::vector<Row> rows;
  for (const std::string& name : allIntegratorNames()) {
    Row row{name};
    for (const nlohmann::json* run : runs)
      if (text(*run, "integrator") == name && !row.run) row.run = run;
    if (row.run) {
      row.stable = !failed(*row.run) && !row.run->value("interrupted", false);
      row.converged = row.stable && number(*row.run, "iterations") < iterationCap(*row.run);
      row.seconds = number(*row.run, "ms_per_step") / 1000;
    }
    rows.push_back(row);
  }
  // Ranks by seconds to converge among the converged runs (ours) and 002's methods we have.
  auto rankBy = [&rows](auto key, int Row::*rank) {
    std::vector<Row*> order;
    for (Row& row : rows)
      if (std::isfinite(key(row))) order.push_back(&row);
    std::sort(order.begin(), order.end(), [&](Row* a, Row* b) { return key(*a) < key(*b); });
    for (size_t i = 0; i < order.size(); ++i) order[i]->*rank = static_cast<int>(i + 1);
  };
  rankBy([](const Row& r) { return r.converged ? r.seconds : NAN; }, &Row::rank);
  rankBy(
      [](const Row& r) {
        Seed002Row s{};
        return seed002(r.integrator, s) ? s.seconds : NAN;
      },
      &Row::rank002);
  for (const Row& row : rows) {
    Seed002Row s{"—", NAN, NAN};
    seed002(row.integrator, s);
    const nlohmann::json empty = nlohmann::json::object();
    const nlohmann::json& run = row.run ? *row.run : empty;
    out << "| " << row.integrator << " | " << format("%.3g", number(run, "ms_per_iteration"))
        << " | " << format("%.0f", number(run, "iterations")) << " | "
        << (row.converged ? format("%.3g", row.seconds) : "—") << " | "
        << (row.run ? (row.converged ? "yes" : "no") : "not run") << " | "
        << (row.run ? (row.stable ? "yes" : "no") : "—") << " | "
        << format("%.2g", number(run, "spring_deviation_ratio")) << " | "
        << (row.rank ? std::to_string(row.rank) : "—") << " | " << s.method << " | "
        << format("%.3g", s.msPerIteration) << " | "
        << format("%.0f", s.seconds * 1000 / s.msPerIteration) << " | " << format("%.3g", s.seconds)
        << " | " << (row.rank002 ? std::to_string(row.rank002) : "—") << " |\n";
  }
  out << "\n`not run`: no run of that integrator in this comparison (an integrator the solver "
         "does not implement is left out by `--methods integrators`). 002 also measured "
         "multi-resolution and multi-particle variants, not listed.\n";
  return out.str();
}

std::string paretoTable(const std::vector<const nlohmann::json*>& runs) {
  // The error against the CalculiX reference where there is one, else against the self-reference.
  const char* errorKey = "rms_to_reference_mm";
  if (std::none_of(runs.begin(), runs.end(),
                   [](const nlohmann::json* r) { return number(*r, "rms_to_reference_mm") > 0; }))
    errorKey = "rms_to_self_reference_mm";
  const bool convergence = std::string(errorKey) == "rms_to_self_reference_mm";
  std::ostringstream out;
  out << (convergence ? "\n## Integrators: speed against convergence (no reference)\n\n"
                      : "\n## Integrators: speed against error\n\n")
      << "FibreMSS runs by integrator; error = `" << errorKey
      << (convergence ? "` (the distance to FibreMSS's own run at dt/8: its convergence, not "
                        "accuracy)"
                      : "`")
      << ". A run is on the Pareto front when no other stable run is both faster (ms/step) and "
         "closer.\n\n"
      << "| method | integrator | ms/step | ms/iteration | iterations | error [mm] | max pen. [mm] "
         "| failed | Pareto |\n|---|---|---|---|---|---|---|---|---|\n";
  auto usable = [&](const nlohmann::json& r) {
    return !failed(r) && std::isfinite(number(r, "ms_per_step")) &&
           std::isfinite(number(r, errorKey));
  };
  for (const nlohmann::json* run : runs) {
    bool front = usable(*run);
    for (const nlohmann::json* other : runs) {
      if (!front) break;
      if (other == run || !usable(*other)) continue;
      const double ms = number(*other, "ms_per_step"), error = number(*other, errorKey);
      const double myMs = number(*run, "ms_per_step"), myError = number(*run, errorKey);
      if (ms <= myMs && error <= myError && (ms < myMs || error < myError)) front = false;
    }
    out << "| " << text(*run, "method") << " | " << text(*run, "integrator") << " | "
        << format("%.3g", number(*run, "ms_per_step")) << " | "
        << format("%.3g", number(*run, "ms_per_iteration")) << " | "
        << format("%.0f", number(*run, "iterations")) << " | "
        << format("%.3g", number(*run, errorKey)) << " | "
        << format("%.3g", number(*run, "max_penetration_mm")) << " | "
        << (failed(*run) ? "at step " + std::to_string(run->value("failed_step", -1)) : "no")
        << " | " << (front ? "yes" : "") << " |\n";
  }
  return out.str();
}

}  // namespace

std::vector<std::string> expandIntegratorMethods(
    const std::vector<std::string>& methods, const std::function<void(const std::string&)>& log) {
  std::vector<std::string> expanded;
  for (const std::string& method : methods) {
    if (method != "integrators") {
      expanded.push_back(method);
      continue;
    }
    for (const std::string& name : allIntegratorNames()) {
      Integrator kind{};
      fromString(name, kind);
      if (integratorAvailable(kind))
        expanded.push_back("fibremss:integrator=" + name);
      else if (log)
        log("integrators: " + name + " is not implemented yet, left out");
    }
  }
  return expanded;
}

std::string integratorsReport(const nlohmann::json& runs) {
  const std::vector<const nlohmann::json*> fibre = fibreRuns(runs);
  std::vector<std::string> integrators;
  for (const nlohmann::json* run : fibre) integrators.push_back(text(*run, "integrator"));
  std::sort(integrators.begin(), integrators.end());
  const bool several =
      std::unique(integrators.begin(), integrators.end()) - integrators.begin() > 1;
  if (!several) return "";
  const bool denoise = std::any_of(fibre.begin(), fibre.end(), [](const nlohmann::json* run) {
    return text(*run, "scene").rfind("sphere-denoise", 0) == 0;
  });
  return denoise ? denoiseTable(fibre) : paretoTable(fibre);
}

}  // namespace fibremss
