#include "ReportVerdict.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>
#include <tuple>
#include <vector>

#include "SummaryFields.h"
#include "TextList.h"
#include "fibremss/Methods.h"
#include "fibremss/SolverSettings.h"

namespace fibremss {
namespace {

/// 3 significant digits, "—" where not finite.
std::string cell(double value) {
  if (!std::isfinite(value)) return "—";
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.3g", value);
  return buffer;
}

std::string familyOf(const nlohmann::json& run) {
  const std::string method = text(run, "method");
  return method.substr(0, method.find(':'));
}

/// One accuracy measure: what it is called and the error it reads off a run (NaN: not measured).
struct Measure {
  std::string name, unit;
  double (*error)(const nlohmann::json& run);
};

const nlohmann::json& analyticOf(const nlohmann::json& run) {
  static const nlohmann::json none = nlohmann::json::object();
  const auto it = run.find("analytic");
  return it != run.end() && it->is_object() ? *it : none;
}

/// |measured − exact| of an analytic figure ("poisson_ratio": its "exact_poisson_ratio").
double offExact(const nlohmann::json& run, const std::string& key) {
  const nlohmann::json& a = analyticOf(run);
  return std::abs(number(a, key.c_str()) - number(a, ("exact_" + key).c_str()));
}

/// The analytic case whose exact answer ranks the runs ("cylinder-stretch", "cylinder-twist"),
/// "" for another scene.
std::string caseType(const nlohmann::json& runs) {
  for (const auto& run : runs) {
    const std::string type = text(analyticOf(run), "type");
    if (type == "cylinder-stretch" || type == "cylinder-twist") return type;
  }
  return "";
}

/// The measures of an analytic case (caseType), none for "".
std::vector<Measure> exactMeasures(const std::string& type) {
  const Measure volume{"volume off exact", " points",
                       [](const nlohmann::json& r) { return offExact(r, "volume_change_pct"); }};
  if (type == "cylinder-stretch")
    return {{"effective ν off exact", "",
             [](const nlohmann::json& r) { return offExact(r, "poisson_ratio"); }},
            volume};
  if (type == "cylinder-twist")
    return {{"section profile off exact", "°",
             [](const nlohmann::json& r) { return number(analyticOf(r), "rotation_error_deg"); }},
            {"mid radius off exact", " r0",
             [](const nlohmann::json& r) { return offExact(r, "mid_radius_ratio"); }},
            volume};
  return {};
}

const Measure kReferenceMeasure{"RMS to the reference", " mm", [](const nlohmann::json& r) {
                                  return number(r, "rms_to_reference_mm");
                                }};

/// A run placed on every measure: its errors, its worst place and the sum of its places (1: the
/// smallest error of the runs compared).
struct Placed {
  const nlohmann::json* run = nullptr;
  std::vector<double> errors;
  int worst = 0, sum = 0;
  bool operator<(const Placed& o) const { return std::tie(worst, sum) < std::tie(o.worst, o.sum); }
};

/// Every rankable method run with all the measures (rankable over `rankedPoses`), placed on each.
std::vector<Placed> placedRuns(const nlohmann::json& runs, const std::vector<Measure>& measures,
                               int rankedPoses = 0) {
  std::vector<Placed> placed;
  for (const auto& run : runs) {
    Placed p{&run, {}};
    for (const Measure& m : measures) p.errors.push_back(m.error(run));
    const bool measured =
        std::all_of(p.errors.begin(), p.errors.end(), [](double e) { return std::isfinite(e); });
    if (measured && rankable(run, rankedPoses) && runRole(run) != MethodRole::Reference)
      placed.push_back(p);
  }
  for (Placed& p : placed)
    for (size_t m = 0; m < measures.size(); ++m) {
      const int place =
          1 + static_cast<int>(std::count_if(placed.begin(), placed.end(), [&](const Placed& o) {
            return o.errors[m] < p.errors[m];
          }));
      p.worst = std::max(p.worst, place);
      p.sum += place;
    }
  return placed;
}

/// Each method family's best placed run, best first.
std::vector<Placed> rankedFamilies(const std::vector<Placed>& placed) {
  std::map<std::string, Placed> best;
  for (const Placed& p : placed) {
    auto [it, added] = best.try_emplace(familyOf(*p.run), p);
    if (!added && p < it->second) it->second = p;
  }
  std::vector<Placed> ranked;
  for (const auto& [family, p] : best) ranked.push_back(p);
  std::stable_sort(ranked.begin(), ranked.end());
  return ranked;
}

/// The runs no other run beats on speed and every measure at once (none both faster or as fast
/// and at least as accurate on all, better on one), fastest first.
std::vector<Placed> speedFront(const std::vector<Placed>& placed) {
  const auto beats = [](const Placed& a, const Placed& b) {
    const double msA = number(*a.run, "ms_per_step"), msB = number(*b.run, "ms_per_step");
    bool better = msA < msB;
    for (size_t m = 0; m < a.errors.size(); ++m) {
      if (a.errors[m] > b.errors[m]) return false;
      better = better || a.errors[m] < b.errors[m];
    }
    return msA <= msB && better;
  };
  std::vector<Placed> front;
  for (const Placed& p : placed)
    if (std::isfinite(number(*p.run, "ms_per_step")) &&
        std::none_of(placed.begin(), placed.end(), [&](const Placed& o) { return beats(o, p); }))
      front.push_back(p);
  std::sort(front.begin(), front.end(), [](const Placed& a, const Placed& b) {
    return number(*a.run, "ms_per_step") < number(*b.run, "ms_per_step");
  });
  return front;
}

/// "ν off exact 0.001, volume off exact 0.417 points".
std::string errorsText(const std::vector<Measure>& measures, const std::vector<double>& errors) {
  std::string out;
  for (size_t m = 0; m < measures.size(); ++m)
    out += (m ? ", " : "") + measures[m].name + " " + cell(errors[m]) + measures[m].unit;
  return out;
}

std::string msText(const nlohmann::json& run) {
  return cell(number(run, "ms_per_step")) + " ms per pose";
}

/// Two lines of the verdict on one basis: the most accurate run and the speed–accuracy front.
std::string verdictOn(const std::string& basis, const nlohmann::json& runs,
                      const std::vector<Measure>& measures, int rankedPoses = 0) {
  const std::vector<Placed> placed = placedRuns(runs, measures, rankedPoses);
  if (placed.empty())
    return "- **" + basis + "**: no run finished every pose with all its measures.\n";
  const Placed best = rankedFamilies(placed).front();
  std::string front;
  for (const Placed& p : speedFront(placed))
    appendItem(front, text(*p.run, "method") + " (" + msText(*p.run) + ", " +
                          errorsText(measures, p.errors) + ")");
  return "- **" + basis + "**: most accurate **" + text(*best.run, "method") + "** (" +
         errorsText(measures, best.errors) + ", " + msText(*best.run) +
         ").\n- Most accurate per millisecond (no other run is as fast and at least as accurate "
         "on every measure), fastest first: " +
         front + ".\n";
}

/// "effective ν off exact and volume off exact".
std::string measureNames(const std::vector<Measure>& measures) {
  std::string out;
  for (size_t m = 0; m < measures.size(); ++m)
    out += (m == 0 ? "" : m + 1 == measures.size() ? " and " : ", ") + measures[m].name;
  return out;
}

const nlohmann::json* runWithRole(const nlohmann::json& runs, MethodRole role) {
  for (const auto& run : runs)
    if (runRole(run) == role) return &run;
  return nullptr;
}

/// A term's cell: its value [mm], else "— " and why.
std::string termCell(double value, const std::string& why) {
  return std::isfinite(value) ? cell(value) : "— " + why;
}

/// What the decomposition's rows share: the converged run of FibreMSS's model, its run at dt/8
/// (either may be missing) and why there is no reference ("" when there is one).
struct Basis {
  const nlohmann::json* equilibrium = nullptr;
  const nlohmann::json* selfReference = nullptr;
  std::string noReference;
};

/// Why a term needs the `equilibrium` run, with the dt/8 self-reference's figure where it has one.
std::string noEquilibrium(double selfReferenceMm, const std::string& what) {
  return "(no `equilibrium` run" +
         (std::isfinite(selfReferenceMm) ? "; " + what + " " + cell(selfReferenceMm) : "") + ")";
}

/// One row of the decomposition: total, model, solver and discretisation terms of `run`.
std::string decompositionRow(const nlohmann::json& run, const Basis& basis) {
  const bool ours = solvesEquilibriumModel(run), fibre = familyOf(run) == "fibremss";
  const std::string other = fibre ? "(another model: its variant changes what is solved)"
                                  : "(no converged run of this method's model)";
  const std::string noReference = "(" + basis.noReference + ")";
  const double selfMm =
      basis.selfReference ? number(*basis.selfReference, "rms_to_reference_mm") : NAN;
  const std::string model = !basis.noReference.empty() ? noReference
                            : !ours                    ? other
                            : !basis.equilibrium
                                ? noEquilibrium(selfMm, "the dt/8 self-reference's")
                                : "(the equilibrium run has no RMS to the reference)";
  const std::string solver =
      !ours ? other
      : !basis.equilibrium
          ? noEquilibrium(number(run, "rms_to_self_reference_mm"), "to the dt/8 self-reference")
          : "(no shared pose)";
  const double modelMm = ours && basis.equilibrium && basis.noReference.empty()
                             ? number(*basis.equilibrium, "rms_to_reference_mm")
                             : NAN;
  const double solverMm = ours && basis.equilibrium ? number(run, "rms_to_equilibrium_mm") : NAN;
  return "| " + text(run, "method") + " | " + cell(number(run, "ms_per_step")) + " | " +
         termCell(number(run, "rms_to_reference_mm"),
                  basis.noReference.empty() ? "(no shared pose)" : noReference) +
         " | " + termCell(modelMm, model) + " | " + termCell(solverMm, solver) + " | " +
         termCell(number(run, "rms_to_finer_resolution_mm"),
                  fibre ? "(no run at twice its resolution)" : "(its resolution is not swept)") +
         " |\n";
}

/// A `fibremss:` variant's key ("iterations", "simulation.iterations", "model.damping") is a
/// solver setting: solverSettings() names the keys of the "simulation" and "model" sections bare.
bool solverSetting(const std::string& key) {
  const size_t dot = key.find('.');
  const std::string section = dot == std::string::npos ? "" : key.substr(0, dot);
  const std::string bare =
      section == "simulation" || section == "model" ? key.substr(dot + 1) : key;
  return std::ranges::find(solverSettings(), bare) != solverSettings().end();
}

}  // namespace

int rankedPoses(const nlohmann::json& reference) {
  return gatesFromJson(reference.value("gates", nlohmann::json::object())).rankedPoses();
}

std::string rankedPosesNote(const nlohmann::json& reference) {
  const std::string text =
      gatesFromJson(reference.value("gates", nlohmann::json::object())).rankedPosesText();
  return text.empty() ? "" : "; " + text;
}

ReferenceGates gatesFromJson(const nlohmann::json& gates) {
  ReferenceGates g;
  g.returnMm = number(gates, "return_mm");
  g.returnNotApplicable = gates.value("return_not_applicable", std::string());
  g.refinementMm = number(gates, "refinement_mm");
  g.refinedBy = gates.value("refined_by", std::string());
  g.incrementsMm = number(gates, "increments_mm");
  g.incrementsScale = number(gates, "increments_scale");
  g.incrementsPerMuscle = gates.value("increments_per_muscle", std::string());
  g.incrementsPoses = gates.value("increments_poses", 0);
  g.attachmentLowMm = number(gates, "attachment_low_mm");
  g.attachmentHighMm = number(gates, "attachment_high_mm");
  g.spreadMm = number(gates, "spread_mm");
  g.poses = gates.value("poses", 0);
  g.refinementPoses = gates.value("refinement_poses", 0);
  g.solvedPoses = gates.value("solved_poses", 0);
  g.attachmentLowPoses = gates.value("attachment_low_poses", 0);
  g.attachmentHighPoses = gates.value("attachment_high_poses", 0);
  g.failures = gates.value("failures", std::string());
  g.statedFailures = gates.value("stated_failures", std::string());
  g.notComputed = gates.value("not_computed", std::string());
  g.stopped = gates.value("stopped", std::string());
  g.gatedPoses = gates.value("gated_poses", -1);
  g.gateStop = gates.value("gate_stop", std::string());
  for (const auto& muscle : gates.value("limited_muscles", nlohmann::json::array()))
    g.limited.push_back({muscle.value("index", size_t{0}), muscle.value("muscle", std::string()),
                         muscle.value("poses", 0), muscle.value("solve", std::string()),
                         muscle.value("why", std::string())});
  g.excluded = gates.value("excluded", std::string());
  return g;
}

std::string whyNoReferenceRanking(const nlohmann::json& summary) {
  if (!summary.contains("reference"))
    return "no CalculiX reference in this report (`--no-reference`, or merged from comparisons "
           "whose references differ)";
  const nlohmann::json& reference = summary["reference"];
  if (reference.value("missing", false))
    return "the CalculiX reference is not in the cache (`--reference-cached-only`; `fibremss "
           "reference` computes it)";
  const ReferenceGates gates = gatesFromJson(reference.value("gates", nlohmann::json::object()));
  if (gates.passed()) return "";
  return gates.whyNotPassed() +
         " (section Reference): the methods' differences are not shown to exceed the "
         "reference's own uncertainty";
}

bool solvesEquilibriumModel(const nlohmann::json& run) {
  const std::string method = text(run, "method"), family = familyOf(run);
  const Method* own = findMethod(family);
  if (!own || !own->solvesFibreModel) return false;
  if (!own->sceneVariants) return true;
  std::istringstream parts(method.size() > family.size() ? method.substr(family.size() + 1) : "");
  for (std::string part; std::getline(parts, part, '+');)
    if (!solverSetting(part.substr(0, part.find('=')))) return false;
  return true;
}

std::string verdictSection(const nlohmann::json& summary) {
  const nlohmann::json& runs = summary["runs"];
  const std::vector<Measure> exact = exactMeasures(caseType(runs));
  const std::string why = whyNoReferenceRanking(summary);
  std::string out = "## Verdict\n\n";
  if (!exact.empty())
    out += verdictOn("Against the exact answer (" + caseType(runs) + ": " + measureNames(exact) +
                         "; no gate needed)",
                     runs, exact);
  if (why.empty())
    out += verdictOn("Against the CalculiX reference (every gate passes" +
                         rankedPosesNote(summary["reference"]) + ")",
                     runs, {kReferenceMeasure}, rankedPoses(summary["reference"]));
  else if (exact.empty())
    out += "**No accuracy ranking on this scene**: " + why +
           ". Nothing is ranked; the distances to FibreMSS's own runs (self-reference, "
           "equilibrium) measure FibreMSS's convergence, not its accuracy.\n";
  else
    out += "- By the CalculiX reference: no ranking, " + why + ".\n";
  return out;
}

std::string errorDecomposition(const nlohmann::json& summary) {
  const nlohmann::json& runs = summary["runs"];
  const bool reference =
      summary.contains("reference") && !summary["reference"].value("missing", false);
  const Basis basis{runWithRole(runs, MethodRole::Equilibrium),
                    runWithRole(runs, MethodRole::SelfReference), reference ? "" : "no reference"};
  std::string rows;
  for (const auto& run : runs)
    if (runRole(run) != MethodRole::Reference) rows += decompositionRow(run, basis);
  if (rows.empty()) return "";
  return "\n## Where each run's error comes from\n\nPer run [mm]: its surface's RMS distance to "
         "the CalculiX reference (the whole error); its model's converged state's (the "
         "`equilibrium` run: FibreMSS's model solved to a force residual below 1e-5 mm) distance "
         "to the reference (the model's error, which no solver setting removes); its distance to "
         "that converged state (the solver's error: iterations, tolerance, time step); and how "
         "far the run at twice its resolution lies from it (the discretisation's share, one "
         "level finer). Distances combine as the sides of a triangle, not as a sum. Against "
         "FibreMSS's own runs "
         "they measure its convergence, not its accuracy.\n\n| run | ms/pose | to the reference "
         "| model: converged state to the reference | solver: to its converged state | "
         "discretisation: to twice its resolution |\n|---|---|---|---|---|---|\n" +
         rows;
}

std::string exactRanking(const nlohmann::json& runs) {
  const std::vector<Measure> measures = exactMeasures(caseType(runs));
  const std::vector<Placed> placed = placedRuns(runs, measures);
  if (measures.empty() || placed.empty()) return "";
  std::ostringstream out;
  out << "\n## Ranking by the exact answer\n\nAn analytic case has an exact answer, so its "
         "methods are ranked against it, not against the CalculiX reference (no gate applies), "
         "on every measure of the case: "
      << measureNames(measures)
      << ". Each method family's best run, by its worst place among the runs over those "
         "measures, then the sum of its places: a run stopped short of its state can keep the "
         "volume and still miss the lateral contraction or the section profile. "
         "`exact_error_vs_ms.png` draws each front's volume error.\n\n";
  int rank = 0;
  for (const Placed& p : rankedFamilies(placed))
    out << ++rank << ". " << text(*p.run, "method") << ": " << errorsText(measures, p.errors)
        << " (worst place " << p.worst << ") at " << msText(*p.run) << "\n";
  for (const auto& run : runs)
    if (runRole(run) == MethodRole::Reference) {
      std::vector<double> errors;
      for (const Measure& m : measures) errors.push_back(m.error(run));
      out << "\nThe CalculiX reference itself: " << errorsText(measures, errors)
          << " (its discretisation and ν).\n";
    }
  return out.str();
}

}  // namespace fibremss
