#include "fibremss/CompareReport.h"

#include <sys/utsname.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <tuple>

#include "FrameWriter.h"
#include "ReportScaling.h"
#include "ReportVerdict.h"
#include "SummaryFields.h"
#include "fibremss/Analytic.h"
#include "fibremss/Error.h"
#include "fibremss/InputFiles.h"
#include "fibremss/Methods.h"
#include "fibremss/MuscleMetrics.h"
#include "fibremss/Output.h"
#include "fibremss/PlotLayout.h"
#include "fibremss/Stability.h"

namespace fibremss {
namespace {

/// A number for tables: "—" where null, otherwise 3 significant digits.
std::string cell(const nlohmann::json& value) {
  if (!value.is_number()) return "—";
  char text[32];
  std::snprintf(text, sizeof text, "%.3g", value.get<double>());
  return text;
}

std::string field(const nlohmann::json& run, const char* key) {
  auto it = run.find(key);
  return it == run.end() ? "—" : cell(*it);
}

std::string joined(const nlohmann::json& list, const char* separator) {
  std::string out;
  if (!list.is_array()) return out;
  for (const auto& item : list) {
    if (!out.empty()) out += separator;
    out += item.is_string() ? item.get<std::string>() : item.dump();
  }
  return out;
}

/// " (k/N poses)" when the run's RMS `rms` ("rms_to_reference", "rms_to_self_reference")
/// covers k of its N poses, k < N (the reference or the run failed or stopped early); ""
/// otherwise or for summaries without counts.
std::string coverage(const nlohmann::json& run, const std::string& rms) {
  const double covered = number(run, (rms + "_poses").c_str()), poses = number(run, "poses");
  if (!std::isfinite(number(run, (rms + "_mm").c_str())) || !(covered >= 0) || !(covered < poses)) {
    return "";
  }
  return " (" + cell(covered) + "/" + cell(poses) + " poses)";
}

/// A paragraph for report.md when some RMS to the reference covers fewer poses than its run:
/// which runs, and where the reference stopped. Empty when every RMS covers all poses.
std::string referenceCoverageNote(const nlohmann::json& runs) {
  std::string list;
  for (const auto& run : runs) {
    const std::string poses = coverage(run, "rms_to_reference");
    if (!poses.empty()) list += (list.empty() ? "" : ", ") + text(run, "method") + poses;
  }
  if (list.empty()) return "";
  std::string why;
  for (const auto& run : runs) {
    if (runRole(run) == MethodRole::Reference && run.value("failed_step", -1) >= 0) {
      why = " ccx did not solve the reference's pose " + cell(number(run, "failed_step")) +
            " (report.md, Reference); later poses have no reference.";
    } else if (runRole(run) == MethodRole::Reference && run.value("excluded_from", -1) >= 0) {
      why = " The reference excludes the poses from " + cell(number(run, "excluded_from")) +
            " on (" + text(run, "exclusion") + "); they are no ccx failure and count in no RMS.";
    }
  }
  return "\n**RMS to the reference covers fewer poses than the runs** (poses 0 to k−1 of N "
         "only): " +
         list + "." + why +
         " Read those RMS values (and their points in the plot) as that many poses' error, not "
         "the whole motion's.\n";
}

/// "reference: k/N poses (the others: no continuum equilibrium, …)" for the plot of a reference
/// whose own poses are excluded (its continuum cut; a gate's cut is the gate's); "" otherwise.
std::string referencePosesLabel(const nlohmann::json& reference) {
  int solved = 0, poses = 0, excluded = 0;
  for (const auto& pose : reference.value("poses", nlohmann::json::array())) {
    ++poses;
    solved += pose.value("solved", false) ? 1 : 0;
    excluded += pose.value("excluded", std::string()).empty() ? 0 : 1;
  }
  if (excluded == 0) return "";
  return "reference: " + std::to_string(solved) + "/" + std::to_string(poses) +
         " poses (the others: no continuum equilibrium, the bones close across the muscle)";
}

/// gnuplot string literal.
std::string quoted(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

/// Runs a plot script (kept beside the plots, writing their final names) so that an interrupted
/// or failed gnuplot leaves no half plot: gnuplot writes `<plot>.partial` files, renamed to
/// the final names only once it succeeded.
void runGnuplot(const std::string& script, const std::string& scriptPath,
                const std::vector<std::string>& plots) {
  writeFileAtomically(scriptPath, script);
  std::string partialScript = script;
  for (const std::string& plot : plots) {
    const std::string from = quoted(plot), to = quoted(plot + ".partial");
    for (size_t at = 0; (at = partialScript.find(from, at)) != std::string::npos; at += to.size())
      partialScript.replace(at, from.size(), to);
  }
  const std::string partialPath = scriptPath + ".partial";
  writeFileAtomically(partialPath, partialScript);
  const std::string command = "gnuplot " + quoted(partialPath) + " 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) throw std::runtime_error("cannot run gnuplot (is gnuplot installed?)");
  std::string output;
  char buffer[256];
  while (std::fgets(buffer, sizeof buffer, pipe)) output += buffer;
  const int status = pclose(pipe);
  std::filesystem::remove(partialPath);
  if (status != 0) {
    for (const std::string& plot : plots) std::filesystem::remove(plot + ".partial");
    throw std::runtime_error("gnuplot failed on " + scriptPath + " (exit " +
                             std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) +
                             "): " + output);
  }
  for (const std::string& plot : plots) std::filesystem::rename(plot + ".partial", plot);
}

/// Sets both terminals in turn: the same plot as PNG and SVG.
std::string bothTerminals(const std::string& stem, const std::string& body) {
  return "set terminal pngcairo size 1000,650 noenhanced font 'DejaVu Sans,10'\nset output " +
         quoted(stem + ".png") + "\n" + body +
         "set terminal svg size 1000,650 noenhanced font 'DejaVu Sans,10'\nset output " +
         quoted(stem + ".svg") + "\n" + body + "unset output\n";
}

/// An analytic case's error measure per run: |volume change − exact| [percentage points].
constexpr const char* kExactErrorKey = "volume_error_to_exact_pct";

/// The error axis: RMS to the CalculiX reference where some run has one, else to the
/// self-reference.
const char* errorKey(const nlohmann::json& runs) {
  for (const auto& run : runs)
    if (number(run, "rms_to_reference_mm") > 0) return "rms_to_reference_mm";
  return "rms_to_self_reference_mm";
}

/// The line of the speed–error plot a run belongs to: its method family and the knob its
/// variant turns ("" for the family's default run, which joins every line of its family;
/// a variant with other overrides is a line of its own).
std::pair<std::string, std::string> frontOf(const std::string& method) {
  const size_t colon = method.find(':');
  const std::string family = method.substr(0, colon);
  if (colon == std::string::npos) return {family, ""};
  const std::string variant = method.substr(colon + 1);
  if (const Method* own = findMethod(family); own && variant.find('+') == std::string::npos)
    for (const std::string& knob : own->knobs)
      if (variant.rfind(knob + "=", 0) == 0) return {family, knob};
  return {method, ""};
}

std::string threadsText(const nlohmann::json& run) {
  const int threads = run.value("threads", 0);
  return threads == 1  ? "1 thread"
         : threads > 1 ? std::to_string(threads) + " threads"
                       : "threads not recorded";
}

/// A point of a front: ms per pose, error, its label (the run's variant, or its method where it
/// has none: the legend names the family) and the poses its RMS covers (" (k/N poses)" or "").
struct FrontPoint {
  double ms = 0, error = 0;
  std::string label, coverage;
  bool operator<(const FrontPoint& o) const {
    return std::tie(ms, error, label) < std::tie(o.ms, o.error, o.label);
  }
  bool operator==(const FrontPoint& o) const {
    return ms == o.ms && error == o.error && label == o.label;
  }
};

/// Lines of the plot: title → points, sorted by ms.
std::map<std::string, std::vector<FrontPoint>> frontLines(const nlohmann::json& runs,
                                                          const char* key) {
  std::map<std::string, std::set<std::string>> knobs;  // family → knobs swept
  for (const auto& run : runs) {
    const auto [family, knob] = frontOf(text(run, "method"));
    if (!knob.empty()) knobs[family].insert(knob);
  }
  std::map<std::string, std::vector<FrontPoint>> lines;
  for (const auto& run : runs) {
    const double ms = number(run, "ms_per_step"), error = number(run, key);
    const std::string method = text(run, "method");
    if (!(ms > 0) || !(error > 0) || roleOf(method) == MethodRole::Reference) continue;
    const auto [family, knob] = frontOf(method);
    const std::string rms(key);  // "rms_to_..._mm" has a pose count, other errors none
    const bool counted = rms.size() > 3 && rms.compare(rms.size() - 3, 3, "_mm") == 0;
    const size_t colon = method.find(':');
    const FrontPoint point{ms, error,
                           colon == std::string::npos ? method : method.substr(colon + 1),
                           counted ? coverage(run, rms.substr(0, rms.size() - 3)) : ""};
    std::set<std::string> joins = knob.empty() ? knobs[family] : std::set<std::string>{knob};
    if (joins.empty()) joins.insert("");
    for (const std::string& j : joins) {
      const std::string title =
          family + (j.empty() ? "" : " (" + j + ")") + ", " + threadsText(run);
      lines[title].push_back(point);
    }
  }
  for (auto& [title, points] : lines) std::sort(points.begin(), points.end());
  return lines;
}

/// What a speed–error figure shows besides its fronts: title, y label, the reference's gate
/// spread as a grey band (0: none) and notes centred along the top (text, colour).
struct FigureText {
  std::string title, ylabel;
  double band = 0;
  std::string bandLabel;
  std::vector<std::pair<std::string, std::string>> notes;
};

/// Each distinct point once, labelled with its coverage unless every point has the same one,
/// which is then added to `notes` instead.
std::vector<FrontPoint> labelledPoints(const std::map<std::string, std::vector<FrontPoint>>& lines,
                                       std::vector<std::pair<std::string, std::string>>& notes) {
  std::vector<FrontPoint> points;
  for (const auto& [title, line] : lines) points.insert(points.end(), line.begin(), line.end());
  std::sort(points.begin(), points.end());
  points.erase(std::unique(points.begin(), points.end()), points.end());
  const bool same = std::all_of(points.begin(), points.end(), [&](const FrontPoint& p) {
    return p.coverage == points.front().coverage;
  });
  if (same && !points.empty() && !points.front().coverage.empty())
    notes.emplace_back("every point's RMS" + points.front().coverage, "#606060");
  for (FrontPoint& p : points)
    if (!same) p.label += p.coverage;
  return points;
}

/// The gnuplot line setting a label.
std::string labelCommand(int number, const PlotLabel& label, const std::string& style) {
  char at[64];
  std::snprintf(at, sizeof at, " at graph %.4f, graph %.4f %s", label.x, label.y, label.justify);
  return "set label " + std::to_string(number) + " " + quoted(label.text) + at + " " + style +
         " front\n";
}

/// A thin grey line from a point to its label's near edge (a label set a row or more away).
std::string leaderCommand(int number, const LabelledPoint& point, const PlotLabel& label) {
  const double edge = label.y > point.y ? label.box.bottom : label.box.top;
  char text[128];
  std::snprintf(text, sizeof text,
                "set arrow %d from graph %.4f, graph %.4f to graph %.4f, graph %.4f nohead lw 0.5 "
                "lc rgb '#909090' back\n",
                number, point.x, point.y, point.x, edge);
  return text;
}

/// A log axis' range and its tics (logTics).
std::string axisCommands(const char* axis, const LogRange& range) {
  std::string tics;
  for (const double v : logTics(range)) {
    char value[32];
    std::snprintf(value, sizeof value, "%g", v);
    tics += (tics.empty() ? "" : ", ") + std::string(value);
  }
  char text[96];
  std::snprintf(text, sizeof text, "set %srange [%.6g:%.6g]\nset format %s '%%g'\n", axis,
                range.low, range.high, axis);
  return text + std::string("set ") + axis + "tics (" + tics + ")\n";
}

/// The notes, centred one under the other along the top (labels 1, 2, ...), and their boxes.
std::string noteCommands(const std::vector<std::pair<std::string, std::string>>& notes,
                         std::vector<PlotBox>& taken) {
  std::string commands;
  for (size_t n = 0; n < notes.size(); ++n) {
    const double at = 0.965 - 0.05 * static_cast<double>(n);
    const PlotLabel label{notes[n].first, 0.5, at, "center",
                          labelBox(notes[n].first, 0.5, at, "center")};
    taken.push_back(label.box);
    commands +=
        labelCommand(static_cast<int>(n + 1), label, "font ',8' tc rgb '" + notes[n].second + "'");
  }
  return commands;
}

/// The grey band up to `band` [the y axis' unit] with its label just above it, and its box.
std::string bandCommands(double band, const std::string& text, const LogRange& y,
                         std::vector<PlotBox>& taken) {
  const PlotBox size = labelBox(text, 0.01, 0, "left");
  const double at = y.fraction(band) + 0.6 * (size.top - size.bottom);
  const PlotLabel label{text, 0.01, at, "left", labelBox(text, 0.01, at, "left")};
  taken.push_back(label.box);
  char rect[96];
  std::snprintf(rect, sizeof rect, "set object 1 rect from graph 0, graph 0 to graph 1, first %.6g",
                band);
  return rect + std::string(" fc rgb '#dddddd' fs solid 0.6 noborder behind\n") +
         labelCommand(9, label, "font ',8' tc rgb '#606060'");
}

/// The fronts as data blocks ($line0 ...) and the plot command drawing them, one line per
/// title; `joined` gets each line's points in graph fractions.
std::pair<std::string, std::string> frontData(
    const std::map<std::string, std::vector<FrontPoint>>& lines, const LogRange& x,
    const LogRange& y, std::vector<std::vector<LabelledPoint>>& joined) {
  std::ostringstream data, plot;
  int index = 0;
  for (const auto& [title, line] : lines) {
    auto& drawn = joined.emplace_back();
    data << "$line" << index << " << EOD\n";
    for (const FrontPoint& p : line) {
      data << p.ms << " " << p.error << "\n";
      drawn.push_back({x.fraction(p.ms), y.fraction(p.error), ""});
    }
    data << "EOD\n";
    plot << (index ? ", " : "plot ") << "$line" << index
         << " using 1:2 with linespoints pt 7 ps 1.2 lw 2 lc " << index + 1 << " title "
         << quoted(title);
    ++index;
  }
  return {data.str(), plot.str() + "\n"};
}

/// A speed–error figure: the gnuplot data blocks and the body drawing its axes (explicit log
/// ranges over the points and the band), notes, band and fronts, every point's label placed
/// where it covers nothing else (placeLabels).
std::pair<std::string, std::string> frontFigure(const nlohmann::json& runs, const char* key,
                                                const FigureText& figure) {
  const auto lines = frontLines(runs, key);
  std::string body = "set title " + quoted(figure.title) +
                     "\nset xlabel 'ms per pose (median wall time, log)'\nset ylabel " +
                     quoted(figure.ylabel) +
                     "\nset logscale xy\nset grid\nset key outside below center font ',9'\n";
  auto notes = figure.notes;
  const std::vector<FrontPoint> points = labelledPoints(lines, notes);
  std::vector<PlotBox> taken;
  body += noteCommands(notes, taken);
  if (lines.empty())
    return {"", body +
                    "set xrange [0.1:1000]\nset yrange [0.01:100]\nset label 99 'no run has "
                    "both a time and an error' at graph 0.5,0.5 center\nplot 1/0 notitle\n"
                    "unset label\n"};
  std::vector<double> ms, errors{figure.band};
  for (const FrontPoint& p : points) ms.push_back(p.ms), errors.push_back(p.error);
  // Room along the top for the notes.
  const LogRange x = logRangeOver(ms, 0.08, 0.08),
                 y = logRangeOver(errors, 0.08, 0.1 + 0.06 * static_cast<double>(notes.size()));
  body += axisCommands("x", x) + axisCommands("y", y);
  if (figure.band > 0) body += bandCommands(figure.band, figure.bandLabel, y, taken);
  std::vector<std::vector<LabelledPoint>> joined;
  const auto [data, plot] = frontData(lines, x, y, joined);
  std::vector<LabelledPoint> marks;
  for (const FrontPoint& p : points)
    marks.push_back({x.fraction(p.ms), y.fraction(p.error), p.label});
  const std::vector<PlotLabel> labels = placeLabels(marks, joined, taken);
  for (size_t n = 0; n < labels.size(); ++n) {
    body += labelCommand(static_cast<int>(n) + 10, labels[n], "font ',8'");
    if (labels[n].leader) body += leaderCommand(static_cast<int>(n) + 1, marks[n], labels[n]);
  }
  return {data, body + plot + "unset label\nunset object\nunset arrow\n"};
}

/// The reference's gate spread [mm]: the larger of what one level finer and halved increments
/// move it (both judged against the methods' spread); NaN where neither was computed.
double gateSpreadMm(const nlohmann::json& gates) {
  const double finer = number(gates, "refinement_mm"), increments = number(gates, "increments_mm");
  if (std::isnan(finer)) return increments;
  return std::isnan(increments) ? finer : std::max(finer, increments);
}

/// FibreMSS's own runs (`fibremss` and its variants): without a reference the error axis is the
/// distance to FibreMSS's self-reference, its convergence, which ranks no other method.
nlohmann::json fibreRunsOnly(const nlohmann::json& runs) {
  nlohmann::json fibre = nlohmann::json::array();
  for (const auto& run : runs) {
    const std::string method = text(run, "method");
    if (method.substr(0, method.find(':')) == "fibremss") fibre.push_back(run);
  }
  return fibre;
}

/// The notes on the reference along the top of the speed–error plot: a gate that fails (red),
/// gates not computed, the poses ranked where ccx stopped the reference or a muscle, poses
/// excluded.
std::vector<std::pair<std::string, std::string>> referenceNotes(const nlohmann::json& summary) {
  std::vector<std::pair<std::string, std::string>> notes;
  if (!summary.contains("reference")) return notes;
  const nlohmann::json gates = summary["reference"].value("gates", nlohmann::json::object());
  const ReferenceGates judged = gatesFromJson(gates);
  if (!judged.passed())
    notes.emplace_back(judged.whyNotPassed() + ": no ranking (report.md, Reference)",
                       judged.failed() ? "#b00000" : "#606060");
  else if (!judged.stopped.empty() || !judged.limited.empty())
    notes.emplace_back(judged.rankedPosesText(), "#606060");
  if (const std::string cut = referencePosesLabel(summary["reference"]); !cut.empty())
    notes.emplace_back(cut, "#606060");
  return notes;
}

std::string speedVsErrorScript(const nlohmann::json& summary, const std::string& stem) {
  const nlohmann::json& runs = summary["runs"];
  const char* key = errorKey(runs);
  const bool reference = std::string(key) == "rms_to_reference_mm";
  FigureText figure;
  figure.title = reference ? "Speed against error: one line per method (its cost knob swept)"
                           : "FibreMSS's convergence, not accuracy: no CalculiX reference";
  figure.ylabel = reference ? "RMS surface distance to the CalculiX reference [mm] (log)"
                            : "RMS distance to FibreMSS's self-reference [mm] (log)";
  const nlohmann::json gates =
      summary.value("reference", nlohmann::json::object()).value("gates", nlohmann::json::object());
  if (reference) figure.notes = referenceNotes(summary);
  if (reference && gateSpreadMm(gates) > 0) {
    figure.band = gateSpreadMm(gates);
    figure.bandLabel = "reference's gate spread (one level finer, increments halved)";
  }
  const auto [data, body] = frontFigure(reference ? runs : fibreRunsOnly(runs), key, figure);
  return data + bothTerminals(stem, body);
}

/// An analytic case's fronts: each method's volume change off the exact answer against its
/// cost (no reference involved).
std::string exactErrorScript(const nlohmann::json& runs, const std::string& stem) {
  FigureText figure;
  figure.title = "Speed against error to the exact answer (analytic case: no reference needed)";
  figure.ylabel = "|volume change - exact| [percentage points] (log)";
  const auto [data, body] = frontFigure(runs, kExactErrorKey, figure);
  return data + bothTerminals(stem, body);
}

std::string penetrationScript(const nlohmann::json& runs, const std::string& stem) {
  std::map<std::string, std::map<double, double>> byMethod;  // method → step_deg → max mm
  for (const auto& run : runs) {
    const double step = number(run, "step_deg"), depth = number(run, "max_penetration_mm");
    if (std::isfinite(step) && std::isfinite(depth)) byMethod[text(run, "method")][step] = depth;
  }
  std::string blocks;
  std::ostringstream plot;
  int index = 0;
  for (const auto& [method, points] : byMethod) {
    blocks += "$m" + std::to_string(index) + " << EOD\n";
    for (const auto& [step, depth] : points) {
      blocks += std::to_string(step) + " " + std::to_string(depth) + "\n";
    }
    blocks += "EOD\n";
    plot << (index ? ", " : "plot ") << "$m" << index << " using 1:2 with linespoints pt 7 title "
         << quoted(method);
    ++index;
  }
  std::string body =
      "set title 'Hip sweep: deepest muscle surface vertex in a bone against the step size'\n"
      "set xlabel 'step_deg [degrees per pose]'\nset ylabel 'max penetration [mm]'\n"
      "set grid\nset key top left\nset offsets graph 0.05, graph 0.05, graph 0.1, 0\n" +
      plot.str() + "\n";
  return blocks + bothTerminals(stem, body);
}

bool anySweep(const nlohmann::json& runs) {
  for (const auto& run : runs) {
    if (std::isfinite(number(run, "step_deg"))) return true;
  }
  return false;
}

/// Each run's own settings (the integrator field: solver, substeps, iterations, added mass).
std::string runSettings(const nlohmann::json& runs) {
  std::ostringstream out;
  out << "\nSettings of these runs (from the runs themselves):\n\n";
  for (const auto& run : runs) {
    out << "- " << text(run, "method") << ": " << text(run, "integrator");
    const Method* method = methodOf(text(run, "method"));
    const double steps = number(run, "steps");
    if (method && method->iterationsPerPose && steps > 0)
      out << ", " << cell(number(run, "iterations") / steps) << " iterations per pose";
    out << "\n";
  }
  return out.str();
}

std::string describeMethods() {
  std::string out = R"(## How each method was measured

Every method runs the same prepared scene (the same particles, springs, fixed particles and
surfaces) over every pose of the scene's motion, one step per pose, and is measured by the
same code (`Measures.h`):

- **ms_per_step**: median wall time of one step (bones moved, solver run, surfaces made);
  **ms_per_iteration**: ms_per_step divided by the iterations of a step (FibreMSS: solver
  iterations; btSoftBody: world substeps × position iterations; FEM: world substeps);
  **ms_per_time_step**: one step of simulated time dt (FibreMSS: an iteration; btSoftBody and
  FEM: a world substep).
- **max/mean_penetration_mm**: depth of the muscle surface vertices inside the bones' true
  triangle meshes (signed distance in each bone's rest frame), max over all steps; mean over
  the penetrating vertices of all steps.
- **volume_change_pct**: volume of the deformed surfaces against rest at the last step (all
  muscles together). **spring_deviation_ratio**: Σ|l − L0| / Σ L0 over the springs at the last
  step (spring models only).
- **rms_to_reference_mm / rms_to_self_reference_mm**: root mean square distance of corresponding
  surface vertices to the CalculiX reference / the self-reference run at the same pose, over all
  poses both reached (a failed pose counts in neither, nor in the penetration).
  **shape_rms_to_reference_mm**: the same poses, each surface vertex's distance to the other
  surface (nearest point, both ways, per muscle), so sliding along the surface is not counted.
  **worst muscle**: the muscle with the largest vertex RMS to the reference. **nan / exploded**: a
  non-finite position, or a spring (FEM: tetrahedron edge) beyond 3× its rest length and longer
  than it by more than its muscle's mean rest length (FibreMSS's guard rule, `springExploded`).
  **peak_memory_mb**: peak resident set of the process after the run (getrusage; it includes
  every run before it in the same process).
- **residual** (every FibreMSS run, after each pose): the net force of the springs, volume terms
  and loads on each free particle (a particle the last collision response pushed keeps only the
  part a frictionless contact cannot hold), as RMS and largest over the particles in N and as
  the equivalent displacement |r|/k (k: Σ k/3 of its springs plus its volume terms'), the
  worst pose's; 0 at an equilibrium whatever the iteration's speed.

Methods:

)";
  for (const Method& method : methods()) out += method.description;
  return out +
         R"(- **calculix** (the reference, not a method): each muscle's static equilibrium per pose by
  CalculiX on a tetgen mesh of its prepared surface (report section "Reference").
- **name:knob=N**: a point of that method's front (its cost knob set to N).
)";
}

/// Seed 004 Table 1 beside ours: parts as rows, resolutions as columns (ascending; the first
/// default FibreMSS run on thigh13 of each resolution in the thesis' table).
std::string table1(const nlohmann::json& runs) {
  std::map<int, const nlohmann::json*> columns;  // resolution → run
  for (const auto& run : runs) {
    double thesis[4];
    const int resolution = static_cast<int>(number(run, "resolution"));
    if (text(run, "method") == "fibremss" && text(run, "scene").rfind("thigh13", 0) == 0 &&
        thesisTable1(resolution, thesis)) {
      columns.emplace(resolution, &run);
    }
  }
  if (columns.empty()) return "";
  std::ostringstream out;
  out << "\n## The thesis' timings (seed 004 Table 1)\n\n"
      << "Seed 004 Table 1 is the FibreMSS thesis' table of seconds for 500 solver iterations "
         "on thigh13 per part (spring forces and integration, muscle and bone collision "
         "detection), measured on a Core2Duo 1.86 GHz. Each cell: ours on this machine / the "
         "thesis' (ratio = thesis / ours, how many times faster).\n\n| part |";
  for (const auto& [resolution, run] : columns) out << " resolution " << resolution << " |";
  out << "\n|---|";
  for (size_t c = 0; c < columns.size(); ++c) out << "---|";
  out << "\n";
  const char* parts[4] = {"MSS", "muscle CD", "bone CD", "total"};
  for (int p = 0; p < 4; ++p) {
    out << "| " << parts[p] << " |";
    for (const auto& [resolution, run] : columns) {
      double thesis[4];
      thesisTable1(resolution, thesis);
      const auto& timing = run->value("timing", nlohmann::json::object());
      const double perIteration[4] = {number(timing, "mss"), number(timing, "muscle_cd"),
                                      number(timing, "bone_cd"), number(*run, "ms_per_iteration")};
      const double ours = perIteration[p] * 0.5;  // ms per iteration × 500 / 1000
      char entry[80];
      std::snprintf(entry, sizeof entry, " %.3g / %.2f (%.3g×) |", ours, thesis[p],
                    ours > 0 ? thesis[p] / ours : NAN);
      out << entry;
    }
    out << "\n";
  }
  out << "| particles |";
  for (const auto& [resolution, run] : columns) out << " " << run->value("particles", 0) << " |";
  out << "\n\nFibreMSS parts are medians per iteration × 500; total is the median ms per "
         "iteration × 500 (it includes the response and the output). Run one `fibremss compare "
         "thigh13 --set resolution=R` per resolution and `fibremss merge` them for all four "
         "columns (comparisons/README.md).\n";
  return out.str();
}

/// Each method family's best rankable run (over `rankedPoses`, rankable) by `key` (ascending),
/// for the ranking.
std::vector<std::pair<double, const nlohmann::json*>> bestPerFamily(const nlohmann::json& runs,
                                                                    const char* key,
                                                                    int rankedPoses = 0) {
  std::map<std::string, std::pair<double, const nlohmann::json*>> best;
  for (const auto& run : runs) {
    const double error = number(run, key);
    const std::string method = text(run, "method");
    if (!std::isfinite(error) || roleOf(method) == MethodRole::Reference ||
        !rankable(run, rankedPoses))
      continue;
    const std::string family = method.substr(0, method.find(':'));
    auto [it, added] = best.try_emplace(family, error, &run);
    if (!added && error < it->second.first) it->second = {error, &run};
  }
  std::vector<std::pair<double, const nlohmann::json*>> ranked;
  for (const auto& [family, entry] : best) ranked.push_back(entry);
  std::sort(ranked.begin(), ranked.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  return ranked;
}

/// The reference's poses for report.md: a line per pose ccx did not solve (those from where it
/// stopped the reference and those past a continuum cut are said once, in the gates' lines),
/// then "Poses solved: k/N" and how many of the others were excluded or not solved.
std::string referencePoses(const nlohmann::json& reference, const ReferenceGates& gates) {
  std::ostringstream out;
  int solved = 0, poses = 0, excluded = 0, stopped = 0;
  for (const auto& pose : reference.value("poses", nlohmann::json::array())) {
    ++poses;
    if (pose.value("solved", false))
      ++solved;
    else if (!pose.value("excluded", std::string()).empty())
      ++excluded;
    else if (!gates.stopped.empty())
      ++stopped;
    else
      out << "- pose " << poses - 1 << " not solved: " << pose.value("failure", std::string())
          << "\n";
  }
  out << "Poses solved: " << solved << "/" << poses;
  if (excluded > 0) out << " (" << excluded << " excluded: no continuum equilibrium, see below)";
  if (stopped > 0)
    out << " (" << stopped << " not solved: ccx stopped at pose " << gates.solvedPoses
        << ", see below)";
  return out.str();
}

/// The "Reference" section: what the reference is, its poses, gates, and the ranking or why
/// there is none.
std::string referenceSection(const nlohmann::json& summary) {
  std::ostringstream out;
  out << "\n## Reference\n\n";
  if (!summary.contains("reference")) {
    out << "No CalculiX reference in this report (`--no-reference`, or merged from several "
           "comparisons whose references differ): RMS columns are to the self-reference where "
           "there is one, and no ranking is reported.\n";
    return out.str();
  }
  const nlohmann::json& reference = summary["reference"];
  if (reference.value("missing", false)) {
    out << "**No reference**: it was to be taken from the cache only (`--reference-cached-only`) "
           "and the cache has none for this scene and these settings (key "
        << reference.value("key", std::string())
        << "). `fibremss reference` with this comparison's scene and `--set` options computes "
           "it (with its gates) into the cache, where the next comparison finds it. No RMS to "
           "it, no gates, no ranking.\n";
    return out.str();
  }
  out << reference.value("description", std::string()) << ".\n\n";
  if (reference.value("methods_without_muscle_contact", false))
    out << "**One problem for all:** the scene collides its muscles with each other and the "
           "reference does not, so every method below ran without muscle–muscle contact (`"
        << kNoMuscleContact << "`; btSoftBody without soft–soft collision).\n\n";
  const ReferenceGates gates = gatesFromJson(reference.value("gates", nlohmann::json::object()));
  out << referencePoses(reference, gates) << " ("
      << (reference.value("from_cache", false) ? "from the cache" : "solved by this run") << ", "
      << cell(reference.value("seconds", nlohmann::json())) << " s of tetgen and ccx; "
      << reference.value("newton_iterations", 0) << " Newton iterations in "
      << reference.value("increments", 0) << " increments; cache key "
      << reference.value("key", std::string()) << ").\n\nGates:\n\n";
  for (const std::string& line : gateLines(gates)) out << "- " << line << "\n";
  const char* key = "rms_to_reference_mm";
  if (!gates.passed()) {
    out << "\n**No ranking** by RMS: " << whyNoReferenceRanking(summary) << "."
        << (bestPerFamily(summary["runs"], kExactErrorKey).empty()
                ? ""
                : " This is an analytic case: the methods are ranked by the exact answer below.")
        << "\n";
    return out.str();
  }
  out << "\n**Ranking** by each method's best RMS to the reference over the runs that finished "
         "every pose it covers"
      << rankedPosesNote(reference) << " (the plot shows what each point costs):\n\n";
  int rank = 0;
  for (const auto& [error, run] : bestPerFamily(summary["runs"], key, rankedPoses(reference)))
    out << ++rank << ". " << text(*run, "method") << ": " << cell(error) << " mm at "
        << cell(number(*run, "ms_per_step")) << " ms per pose (" << threadsText(*run) << ")\n";
  return out.str();
}

/// A run's force residual at its worst pose: "RMS / max mm (RMS / max N), pose k"; "—" where
/// it was not measured (not FibreMSS).
std::string residualCell(const nlohmann::json& run) {
  if (!std::isfinite(number(run, "residual_rms_mm"))) return "—";
  return field(run, "residual_rms_mm") + " / " + field(run, "residual_max_mm") + " mm (" +
         field(run, "residual_rms_n") + " / " + field(run, "residual_max_n") + " N), pose " +
         field(run, "residual_worst_pose");
}

/// A run's farthest muscle from the equilibrium run: "name RMS over the poses; name at pose k
/// RMS" [mm]; "—" where it was not measured (summaries before the per-muscle distances).
std::string worstMuscleCell(const nlohmann::json& run) {
  const nlohmann::json worst = run.value("worst_muscle_pose_to_equilibrium", nlohmann::json());
  if (!std::isfinite(number(run, "worst_muscle_rms_to_equilibrium_mm")) || !worst.is_object())
    return "—";
  return text(run, "worst_muscle_to_equilibrium") + " " +
         field(run, "worst_muscle_rms_to_equilibrium_mm") + "; " + text(worst, "muscle") +
         " at pose " + field(worst, "pose") + " " + field(worst, "rms_mm");
}

/// " (pose k)", k the run's worst pose to the equilibrium run; "" where not recorded.
std::string poseOf(const nlohmann::json& run) {
  const double pose = number(run, "worst_pose_to_equilibrium");
  return pose >= 0 ? " (pose " + cell(pose) + ")" : "";
}

/// The time-to-accuracy figure: every run measured against an "equilibrium" run, its worst pose's
/// RMS to that equilibrium and ms per pose, and the fastest run whose every pose is within
/// kEquilibriumAccuracyMm. Empty without an equilibrium run.
std::string equilibriumReport(const nlohmann::json& runs) {
  std::string rows, fastest;
  double fastestMs = INFINITY;
  for (const auto& run : runs) {
    const double worst = number(run, "worst_pose_rms_to_equilibrium_mm");
    const std::string method = text(run, "method");
    if (!std::isfinite(worst) || roleOf(method) == MethodRole::Equilibrium) continue;
    const double ms = number(run, "ms_per_step");
    rows += "| " + method + " | " + cell(number(run, "threads")) + " | " +
            field(run, "iterations") + " | " + cell(ms) + " | " +
            field(run, "rms_to_equilibrium_mm") + " | " + cell(worst) + poseOf(run) + " | " +
            worstMuscleCell(run) + " | " + residualCell(run) + " |\n";
    if (worst <= kEquilibriumAccuracyMm && ms < fastestMs && solvesEquilibriumModel(run))
      fastestMs = ms, fastest = method;
  }
  if (rows.empty()) return "";
  std::string unconverged;
  for (const auto& run : runs) {
    if (runRole(run) != MethodRole::Equilibrium) continue;
    unconverged = " Its residual (worst pose): " + residualCell(run) + ".";
    if (number(run, "unconverged_poses") > 0)
      unconverged += " **" + cell(number(run, "unconverged_poses")) +
                     " pose(s) of the equilibrium run reached its iteration cap unconverged**: "
                     "distances to them are distances to an unconverged state.";
  }
  char bound[32];
  std::snprintf(bound, sizeof bound, "%.2g mm", kEquilibriumAccuracyMm);
  return "\n## Distance to equilibrium\n\nThe `equilibrium` run is FibreMSS's projective solver "
         "at every pose until its force residual's RMS equivalent displacement falls below 1e-5 "
         "mm (from the previous pose's equilibrium)." +
         unconverged +
         " Per run: the RMS of the surface vertices to it over all poses, the worst pose's "
         "RMS, the farthest muscle (its RMS over all poses; the muscle and pose with the largest "
         "single RMS; `muscles_to_equilibrium` in summary.json has every muscle and pose), and "
         "the run's own residual.\n\n| method | threads | iterations | ms/pose | RMS to "
         "equilibrium [mm] | worst pose [mm] | worst muscle [mm] | residual RMS / max [mm] (N), "
         "worst pose |\n|---|---|---|---|---|---|---|---|\n" +
         rows +
         "\nA btSoftBody or FEM row is the distance between its model and FibreMSS's converged "
         "one, an error of neither. Time to accuracy (FibreMSS's own convergence, not its "
         "accuracy: a run of the equilibrium run's model with every pose within " +
         bound + " RMS of it): " +
         (fastest.empty() ? std::string("no run reached it")
                          : "**" + cell(fastestMs) + " ms per pose** (" + fastest + ")") +
         ". Sweep the iterations (`--methods equilibrium,fibremss:iterations=20,"
         "fibremss:iterations=40,...`) for the front.\n";
}

/// summary.json's "btsoftbody_ratio": every softBodyRatios entry.
nlohmann::json softBodyRatioJson(const nlohmann::json& runs) {
  nlohmann::json list = nlohmann::json::array();
  for (const SoftBodyRatio& ratio : softBodyRatios(runs)) list.push_back(ratio.toJson());
  return list;
}

}  // namespace

nlohmann::json machineJson() {
  std::ifstream cpuinfo("/proc/cpuinfo");
  std::string line, model = "unknown";
  int cores = 0;
  while (std::getline(cpuinfo, line)) {
    if (line.rfind("processor", 0) == 0) ++cores;
    if (line.rfind("model name", 0) == 0 && model == "unknown") {
      model = line.substr(line.find(':') + 1);
      model.erase(0, model.find_first_not_of(' '));
    }
  }
  utsname name{};
  std::string os = uname(&name) == 0 ? std::string(name.sysname) + " " + name.release : "";
  return {{"cpu", model}, {"cores", cores}, {"os", os}};
}

namespace {

/// The scene overrides a run ran with: the comparison's, then a FibreMSS variant's own
/// (`fibremss:resolution=10`), each replacing an earlier one of its key.
std::vector<std::string> runOverrides(const Comparison& comparison, const std::string& method) {
  std::vector<std::string> overrides = comparison.overrides;
  if (!method.starts_with("fibremss:")) return overrides;
  for (const std::string& part : parseMethod(method).overrides) {
    const std::string key = part.substr(0, part.find('=') + 1);
    std::erase_if(overrides, [&](const std::string& given) { return given.starts_with(key); });
    overrides.push_back(part);
  }
  return overrides;
}

/// The resolution the run's overrides set last, else the comparison's.
int runResolution(const Comparison& comparison, const std::vector<std::string>& overrides) {
  int resolution = comparison.resolution;
  for (const std::string& part : overrides)
    if (part.starts_with("resolution=")) resolution = std::atoi(part.c_str() + 11);
  return resolution;
}

}  // namespace

nlohmann::json summaryJson(const Comparison& comparison, const std::string& command) {
  nlohmann::json runs = nlohmann::json::array();
  for (const RunMetrics& run : comparison.runs) {
    nlohmann::json object = toJson(run);
    const std::vector<std::string> overrides = runOverrides(comparison, run.method);
    object["scene_overrides"] = overrides;
    object["resolution"] = runResolution(comparison, overrides);
    object["step_deg"] = std::isfinite(comparison.stepDeg) ? nlohmann::json(comparison.stepDeg)
                                                           : nlohmann::json(nullptr);
    runs.push_back(std::move(object));
  }
  nlohmann::json ratios = softBodyRatioJson(runs);
  nlohmann::json summary = {{"scene", comparison.scene},
                            {"machine", machineJson()},
                            {"command", command},
                            {"btsoftbody_ratio", std::move(ratios)},
                            {"runs", std::move(runs)}};
  if (comparison.reference) summary["reference"] = referenceJson(*comparison.reference);
  if (comparison.muscleContactOff) summary["reference"]["methods_without_muscle_contact"] = true;
  return summary;
}

namespace {

/// Whether `value` has the JSON type of `expected`, a field of toJson(RunMetrics{}): numbers
/// (null: NaN) for numbers and nulls, the same type otherwise, arrays of numbers or nulls.
bool sameKind(const nlohmann::json& value, const nlohmann::json& expected) {
  auto numeric = [](const nlohmann::json& v) { return v.is_number() || v.is_null(); };
  if (numeric(expected)) return numeric(value);
  if (expected.is_array())
    return value.is_array() && std::all_of(value.begin(), value.end(), numeric);
  return value.type() == expected.type();
}

void checkRunFields(const nlohmann::json& run, const nlohmann::json& expected,
                    const std::string& source, const std::string& path);

/// Throws InputError naming the field of a run's `muscles` list (MuscleMetrics.h) whose type
/// toJson(MuscleResults) would not write: objects of its fields, numbers per bone.
void checkMuscles(const nlohmann::json& muscles, const std::string& source,
                  const std::string& path) {
  if (!muscles.is_array()) throw InputError(source, path, "expected an array of muscle objects");
  const nlohmann::json expected = toJson(MuscleResults{});
  for (size_t m = 0; m < muscles.size(); ++m) {
    const std::string at = path + "[" + std::to_string(m) + "]";
    checkRunFields(muscles[m], expected, source, at);
    for (const char* perBone : {"max_penetration_mm", "fixed_particles"}) {
      const nlohmann::json values = muscles[m].value(perBone, nlohmann::json::object());
      for (const auto& [bone, value] : values.items())
        if (!value.is_number() && !value.is_null())
          throw InputError(source, at + "." + perBone + "." + bone, "expected a number");
    }
  }
}

/// Throws InputError naming the field of a run's `series` rows (MuscleMetrics.h) whose type
/// seriesJson would not write.
void checkSeries(const nlohmann::json& series, const std::string& source, const std::string& path) {
  if (!series.is_array()) throw InputError(source, path, "expected an array of series rows");
  const nlohmann::json expected = seriesJson({SeriesRow{}}).at(0);
  for (size_t r = 0; r < series.size(); ++r)
    checkRunFields(series[r], expected, source, path + "[" + std::to_string(r) + "]");
}

/// Throws InputError naming the field of a run's `analytic` (null: the scene has no exact
/// answer; else AnalyticMetrics' fields and its `contact` rows) whose type toJson would not
/// write.
void checkAnalytic(const nlohmann::json& analytic, const std::string& source,
                   const std::string& path) {
  if (analytic.is_null()) return;
  RunMetrics filled;  // toJson(RunMetrics{}) writes null for "analytic": its fields from one
  filled.analytic.type = "cylinder-stretch";
  filled.analytic.contact.emplace_back();
  nlohmann::json expected = toJson(filled)["analytic"];
  const nlohmann::json row = expected["contact"].at(0);
  expected.erase("contact");
  checkRunFields(analytic, expected, source, path);
  const auto contact = analytic.find("contact");
  if (contact == analytic.end()) return;
  if (!contact->is_array())
    throw InputError(source, path + ".contact", "expected an array of contact rows");
  for (size_t r = 0; r < contact->size(); ++r)
    checkRunFields((*contact)[r], row, source, path + ".contact[" + std::to_string(r) + "]");
}

/// Throws InputError naming `path.key` for a field of a run whose type toJson would not write.
void checkRunFields(const nlohmann::json& run, const nlohmann::json& expected,
                    const std::string& source, const std::string& path) {
  if (!run.is_object()) throw InputError(source, path, "expected a run object {...}");
  for (auto it = expected.begin(); it != expected.end(); ++it) {
    const auto found = run.find(it.key());
    if (found == run.end()) continue;  // missing keys keep their defaults
    if (it.key() == "muscles")
      checkMuscles(*found, source, path + ".muscles");
    else if (it.key() == "series")
      checkSeries(*found, source, path + ".series");
    else if (it.key() == "analytic")
      checkAnalytic(*found, source, path + ".analytic");
    else if (it->is_object())
      checkRunFields(*found, *it, source, path + "." + it.key());
    else if (!sameKind(*found, *it))
      throw InputError(source, path + "." + it.key(),
                       std::string("expected a ") + it->type_name() +
                           " as `fibremss compare` "
                           "writes it, got " +
                           found->dump().substr(0, 60));
  }
  const auto overrides = run.find("scene_overrides");
  if (overrides != run.end() &&
      !(overrides->is_array() &&
        std::all_of(overrides->begin(), overrides->end(),
                    [](const nlohmann::json& o) { return o.is_string(); })))
    throw InputError(source, path + ".scene_overrides", "expected an array of strings");
}

}  // namespace

nlohmann::json mergeSummaries(const std::vector<nlohmann::json>& summaries,
                              const std::vector<std::string>& sources) {
  const nlohmann::json expected = toJson(RunMetrics{});
  nlohmann::json runs = nlohmann::json::array(), commands = nlohmann::json::array();
  std::set<std::string> scenes;
  nlohmann::json machine;
  for (size_t i = 0; i < summaries.size(); ++i) {
    const auto& summary = summaries[i];
    if (!summary.is_object() || !summary.contains("runs") || !summary["runs"].is_array()) {
      throw InputError(i < sources.size() ? sources[i] : "summary", "runs",
                       "a summary.json written by `fibremss compare` (an object with \"runs\")");
    }
    const std::string source = i < sources.size() ? sources[i] : "summary";
    for (size_t r = 0; r < summary["runs"].size(); ++r) {
      checkRunFields(summary["runs"][r], expected, source, "runs[" + std::to_string(r) + "]");
      runs.push_back(summary["runs"][r]);
    }
    if (summary.contains("scene") && summary["scene"].is_string()) {
      scenes.insert(summary["scene"].get<std::string>());
    }
    if (summary.contains("command")) commands.push_back(summary["command"]);
    if (machine.is_null() && summary.contains("machine")) machine = summary["machine"];
    const nlohmann::json fields = machine.is_null() ? nlohmann::json::object() : machine;
    if (!fields.is_object() || !fields.value("cpu", nlohmann::json("")).is_string() ||
        !fields.value("os", nlohmann::json("")).is_string() ||
        !fields.value("cores", nlohmann::json(0)).is_number())
      throw InputError(source, "machine",
                       "expected {\"cpu\": text, \"cores\": number, \"os\": text}");
  }
  if (runs.empty())
    throw InputError(sources.empty() ? "merge" : sources.front(), "runs",
                     "no runs in any of the summaries; expected summary.json files written by "
                     "`fibremss compare`");
  std::string scene;
  for (const std::string& s : scenes) scene += (scene.empty() ? "" : ", ") + s;
  nlohmann::json merged = {{"scene", scene},
                           {"machine", machine},
                           {"command", commands},
                           {"btsoftbody_ratio", softBodyRatioJson(runs)},
                           {"runs", runs}};
  // One reference's gates hold for its own runs only: kept when a single summary has one.
  const auto withReference =
      std::count_if(summaries.begin(), summaries.end(),
                    [](const nlohmann::json& s) { return s.contains("reference"); });
  for (const auto& summary : summaries)
    if (withReference == 1 && summary.contains("reference"))
      merged["reference"] = summary["reference"];
  return merged;
}

nlohmann::json readSummary(const std::string& path) {
  std::filesystem::path file(path);
  if (std::filesystem::is_directory(file)) file /= "summary.json";
  nlohmann::json summary = nlohmann::json::parse(readJsonText(file.string()), nullptr, false);
  if (summary.is_discarded()) throw InputError(file.string(), "", "not valid JSON");
  return summary;
}

bool thesisTable1(int resolution, double seconds[4]) {
  static const std::map<int, std::array<double, 4>> table = {{20, {18.66, 8.15, 30.03, 56.84}},
                                                             {40, {39.97, 13.50, 37.43, 90.9}},
                                                             {60, {60.53, 24.00, 56.03, 140.56}},
                                                             {80, {80.70, 29.53, 67.10, 177.33}}};
  auto it = table.find(resolution);
  if (it == table.end()) return false;
  for (int i = 0; i < 4; ++i) seconds[i] = it->second[i];
  return true;
}

/// A run's heading: its method, plus its scene overrides when it has any.
std::string runLabel(const nlohmann::json& run) {
  std::string label = text(run, "method");
  const std::string overrides = joined(run.value("scene_overrides", nlohmann::json::array()), " ");
  if (!overrides.empty()) label += " (" + overrides + ")";
  return label;
}

/// The runs with an RMS to the reference per pose (the reference itself left out).
std::vector<const nlohmann::json*> runsAgainstReference(const nlohmann::json& runs) {
  std::vector<const nlohmann::json*> shown;
  for (const auto& run : runs) {
    const nlohmann::json& perPose = run.value("rms_to_reference_per_pose_mm", nlohmann::json());
    if (runRole(run) != MethodRole::Reference && perPose.is_array() && !perPose.empty())
      shown.push_back(&run);
  }
  return shown;
}

/// Rows of each run's RMS to the reference per pose.
std::string referencePerPoseTable(const std::vector<const nlohmann::json*>& shown) {
  size_t poses = 0;
  for (const nlohmann::json* run : shown)
    poses = std::max(poses, (*run)["rms_to_reference_per_pose_mm"].size());
  std::ostringstream out;
  out << "| run |";
  for (size_t p = 0; p < poses; ++p) out << " pose " << p << " |";
  out << "\n|---|";
  for (size_t p = 0; p < poses; ++p) out << "---|";
  for (const nlohmann::json* run : shown) {
    const nlohmann::json& perPose = (*run)["rms_to_reference_per_pose_mm"];
    out << "\n| " << runLabel(*run) << " |";
    for (size_t p = 0; p < poses; ++p)
      out << " " << (p < perPose.size() ? cell(perPose[p]) : "—") << " |";
  }
  return out.str() + "\n";
}

/// Rows of each muscle's RMS to the reference over the poses, a column per run; a muscle over
/// fewer poses than the first run's (one the gates limit: ReferenceGates::limited) says which.
std::string referencePerMuscleTable(const std::vector<const nlohmann::json*>& shown) {
  const nlohmann::json& first = shown.front()->value("muscles_to_reference", nlohmann::json());
  const size_t poses = (*shown.front())["rms_to_reference_per_pose_mm"].size();
  const auto over = [&](const nlohmann::json& muscle) {
    const size_t own = muscle.value("per_pose_mm", nlohmann::json::array()).size();
    if (own >= poses) return std::string();
    return own == 0 ? std::string(" (no pose)") : " (poses 0\u2013" + std::to_string(own - 1) + ")";
  };
  std::ostringstream out;
  out << "| muscle |";
  for (const nlohmann::json* run : shown) out << " " << runLabel(*run) << " |";
  out << "\n|---|";
  for (size_t r = 0; r < shown.size(); ++r) out << "---|";
  for (size_t m = 0; m < first.size(); ++m) {
    out << "\n| " << first[m].value("muscle", std::string()) << over(first[m]) << " |";
    for (const nlohmann::json* run : shown) {
      const nlohmann::json& muscles = run->value("muscles_to_reference", nlohmann::json());
      out << " " << (m < muscles.size() ? field(muscles[m], "rms_mm") : "—") << " |";
    }
  }
  return out.str() + "\n";
}

/// Where each run's error to the reference lies: per pose and, with more than one muscle, per
/// muscle ("" without a reference).
std::string referenceBreakdown(const nlohmann::json& runs) {
  const std::vector<const nlohmann::json*> shown = runsAgainstReference(runs);
  if (shown.empty()) return "";
  std::string out =
      "\n## RMS to the reference per pose and per muscle\n\nEach run's surface vertex RMS to "
      "the CalculiX reference [mm] at each pose both reached (— where either did not):\n\n" +
      referencePerPoseTable(shown);
  const nlohmann::json& muscles = shown.front()->value("muscles_to_reference", nlohmann::json());
  if (muscles.is_array() && muscles.size() > 1)
    out +=
        "\nPer muscle, over those poses (a muscle the reference's gates cover over fewer "
        "says which) [mm]:\n\n" +
        referencePerMuscleTable(shown);
  return out;
}

/// Per run that measured its muscles (FibreMSS), the per-muscle table: the worst muscle shows.
std::string perMuscleReport(const nlohmann::json& runs) {
  std::string out;
  for (const auto& run : runs) {
    const nlohmann::json& list = run.value("muscles", nlohmann::json::array());
    if (!list.is_array() || list.empty()) continue;
    std::vector<MuscleResults> muscles;
    for (const auto& muscle : list) muscles.push_back(muscleResultsFromJson(muscle));
    if (out.empty())
      out =
          "\n## Per muscle\n\nVolume change of each muscle at the last step and its worst "
          "step, the deepest surface vertex in each bone's true mesh over all steps, particles "
          "fixed per bone, mean fibre length, the largest spring stretch l/L0, step attempts "
          "the numerical guard rolled back, and freezes.\n";
    out += "\n### " + runLabel(run) + "\n\n" + muscleTable(muscles);
  }
  return out;
}

std::string reportMarkdown(const nlohmann::json& summary, const std::vector<std::string>& plots) {
  std::ostringstream out;
  const nlohmann::json& runs = summary["runs"];
  out << "# FibreMSS comparison: " << summary.value("scene", std::string("?")) << "\n\n"
      << verdictSection(summary) << "\n";
  const nlohmann::json& machine = summary.value("machine", nlohmann::json::object());
  out << "- Machine: " << (machine.is_object() ? machine.value("cpu", std::string("?")) : "?")
      << ", " << (machine.is_object() ? machine.value("cores", 0) : 0) << " logical cores, "
      << (machine.is_object() ? machine.value("os", std::string("")) : "") << "\n";
  const nlohmann::json& command = summary.value("command", nlohmann::json());
  if (command.is_string()) {
    out << "- Command: `" << command.get<std::string>() << "`\n";
  } else if (command.is_array()) {
    out << "- Merged from:\n";
    for (const auto& c : command)
      out << "  - `" << (c.is_string() ? c.get<std::string>() : c.dump()) << "`\n";
  }
  out << "\n## Runs\n\n"
      << "| method | threads | scene | overrides | particles/nodes | springs/links/tets | steps | "
         "ms/step | ms/iteration | max pen. [mm] | mean pen. [mm] | volume [%] | RMS to ref. [mm] "
         "| shape RMS to ref. [mm] | worst muscle [mm] | RMS to self-ref. [mm] (FibreMSS's "
         "convergence) | spring dev. | "
         "residual RMS / max [mm] (N), worst pose | failed | peak MB | wall [s] |\n"
      << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& run : runs) {
    std::string failed = "no";
    if (run.value("nan", false)) failed = "NaN";
    if (run.value("exploded", false)) failed = "exploded";
    if (failed != "no") failed += " at step " + std::to_string(run.value("failed_step", -1));
    if (run.value("interrupted", false)) failed = "stopped (time budget)";
    if (runRole(run) == MethodRole::Reference && run.value("failed_step", -1) >= 0)
      failed = "ccx did not solve pose " + std::to_string(run.value("failed_step", -1));
    else if (runRole(run) == MethodRole::Reference && run.value("excluded_from", -1) >= 0)
      failed = "no (poses from " + std::to_string(run.value("excluded_from", -1)) +
               " excluded: no continuum equilibrium)";
    const std::string worst = text(run, "worst_muscle");
    out << "| " << text(run, "method") << " | " << field(run, "threads") << " | "
        << text(run, "scene") << " | "
        << joined(run.value("scene_overrides", nlohmann::json::array()), " ") << " | "
        << run.value("particles", 0) << " | " << run.value("springs", 0) << " | "
        << run.value("steps", 0) << " | " << field(run, "ms_per_step") << " | "
        << field(run, "ms_per_iteration") << " | " << field(run, "max_penetration_mm") << " | "
        << field(run, "mean_penetration_mm") << " | " << field(run, "volume_change_pct") << " | "
        << field(run, "rms_to_reference_mm") << coverage(run, "rms_to_reference") << " | "
        << field(run, "shape_rms_to_reference_mm") << " | "
        << (worst.empty() ? "—" : worst + " " + field(run, "worst_muscle_rms_mm")) << " | "
        << field(run, "rms_to_self_reference_mm") << coverage(run, "rms_to_self_reference") << " | "
        << field(run, "spring_deviation_ratio") << " | " << residualCell(run) << " | " << failed
        << " | " << field(run, "peak_memory_mb") << " | " << field(run, "wall_seconds") << " |\n";
  }
  out << "\n— : does not apply or was not measured (e.g. no reference to compare with). The "
         "calculix row is the reference itself (ms/step: its tetgen and ccx time per pose, "
         "iterations: Newton iterations). RMS to self-ref. is the distance to FibreMSS's own run "
         "at dt/8: FibreMSS's convergence, not any method's accuracy.\n"
      << errorDecomposition(summary) << referenceBreakdown(runs) << perMuscleReport(runs)
      << softBodyRatioReport(runs) << analyticReport(runs) << equilibriumReport(runs);
  const std::string coverageNote = referenceCoverageNote(runs);
  for (const std::string& plot : plots) {
    if (plot.size() > 4 && plot.substr(plot.size() - 4) == ".png") {
      out << "\n![" << plot << "](" << plot << ")\n";
      if (plot.rfind("speed_vs_error", 0) == 0) out << coverageNote;
    }
  }
  out << referenceSection(summary) << exactRanking(runs) << table1(runs) << integratorsReport(runs)
      << scalingReport(runs) << "\n"
      << describeMethods() << runSettings(runs);
  return out.str();
}

std::vector<std::string> writeComparison(const nlohmann::json& summary, const std::string& outDir) {
  std::filesystem::create_directories(outDir);
  const std::filesystem::path dir = std::filesystem::absolute(outDir);
  std::vector<std::string> written;
  writeFileAtomically((dir / "summary.json").string(), summary.dump(2) + "\n");
  written.push_back("summary.json");
  // Per FibreMSS run, its per-step series as `fibremss run` writes it.
  for (size_t r = 0; r < summary["runs"].size(); ++r) {
    const nlohmann::json& run = summary["runs"][r];
    const std::vector<SeriesRow> series = seriesFromJson(run.value("series", nlohmann::json()));
    if (series.empty()) continue;
    const std::string name =
        "series_" + std::to_string(r) + "_" + fileSafe(run.value("method", "")) + ".csv";
    writeFileAtomically((dir / name).string(), seriesCsv(series));
    written.push_back(name);
  }

  std::vector<std::string> plots;
  const nlohmann::json& runs = summary["runs"];
  const auto plot = [&](const std::string& name, const std::string& script) {
    const std::string stem = (dir / name).string();
    runGnuplot(script, stem + ".gp", {stem + ".png", stem + ".svg"});
    plots.push_back(name + ".png");
    plots.push_back(name + ".svg");
  };
  plot("speed_vs_error", speedVsErrorScript(summary, (dir / "speed_vs_error").string()));
  if (!bestPerFamily(runs, kExactErrorKey).empty())
    plot("exact_error_vs_ms", exactErrorScript(runs, (dir / "exact_error_vs_ms").string()));
  if (anySweep(runs))
    plot("penetration_vs_step", penetrationScript(runs, (dir / "penetration_vs_step").string()));
  writeFileAtomically((dir / "report.md").string(), reportMarkdown(summary, plots));
  written.push_back("report.md");
  written.insert(written.end(), plots.begin(), plots.end());
  return written;
}

}  // namespace fibremss
