// `fibremss compare SCENE`: the same scene through FibreMSS, its self-reference, the
// btSoftBody baseline and Bullet's FEM, measured the same way against the CalculiX reference;
// writes summary.json, report.md and the speed-against-error plot.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <memory>
#include <optional>
#include <string>

#include "Commands.h"
#include "Interrupt.h"
#include "ProgressLog.h"
#include "ReferenceArgs.h"
#include "SceneArgs.h"
#include "Validators.h"
#include "fibremss/Analytic.h"
#include "fibremss/CompareReport.h"
#include "fibremss/Methods.h"
#include "fibremss/Output.h"
#include "fibremss/Progress.h"
#include "fibremss/Stability.h"

namespace fibremss::cli {
namespace {

struct CompareArgs {
  SceneArgs scene;                   ///< SCENE and --set overrides
  std::vector<std::string> methods;  ///< --methods (default: defaultMethods())
  std::string out;                   ///< --out DIR (default: compare-<scene>)
  CompareOptions options;            ///< baseline and reference settings
};

/// The command line exactly as typed (from /proc), for the report.
std::string commandLine() {
  std::ifstream in("/proc/self/cmdline", std::ios::binary);
  std::string raw((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::string line;
  size_t start = 0;
  for (size_t end; (end = raw.find('\0', start)) != std::string::npos; start = end + 1) {
    std::string arg = raw.substr(start, end - start);
    if (start == 0) arg = "fibremss";  // the program, whatever its path
    if (arg.find_first_of(" \"'$;&|<>*?") != std::string::npos) arg = "'" + arg + "'";
    line += (line.empty() ? "" : " ") + arg;
  }
  return line;
}

/// A table cell: 3 significant digits, "—" for a value that does not apply.
std::string cell(double value) {
  if (std::isnan(value)) return "\u2014";
  char text[32];
  std::snprintf(text, sizeof text, "%.3g", value);
  return text;
}

void printTable(const Comparison& comparison) {
  std::printf("%-28s %10s %10s %10s %10s %10s\n", "method", "ms/step", "max pen mm", "volume %",
              "RMS ref mm", "RMS self mm");
  for (const RunMetrics& run : comparison.runs) {
    // "—" is one column wide but three bytes: printf pads by bytes.
    std::string line = run.method;
    line.resize(std::max<size_t>(line.size(), 28), ' ');
    for (double value : {run.msPerStep, run.maxPenetrationMm, run.volumeChangePct,
                         run.rmsToReferenceMm, run.rmsToSelfReferenceMm}) {
      const std::string text = cell(value);
      const size_t width = std::isnan(value) ? 1 : text.size();
      line.append(width < 10 ? 11 - width : 1, ' ');
      line += text;
    }
    std::printf("%s%s\n", line.c_str(), run.failedStep >= 0 ? "  FAILED" : "");
  }
  if (!comparison.reference || comparison.reference->missing) {
    std::printf("%s: no RMS to it, no gates, no ranking\n",
                comparison.reference ? "no reference (not in the cache; --reference-cached-only)"
                                     : "no reference (--no-reference)");
    return;
  }
  for (const std::string& line : gateLines(comparison.reference->gates))
    std::printf("reference gate: %s\n", line.c_str());
  const ReferenceGates& gates = comparison.reference->gates;
  if (!gates.passed())
    std::printf("%s: no ranking of the methods\n", gates.whyNotPassed().c_str());
  else if (!gates.rankedPosesText().empty())
    std::printf("the methods are %s\n", gates.rankedPosesText().c_str());
}

void compare(CompareArgs& args) {
  if (!args.methods.empty()) args.options.methods = args.methods;
  args.options.methods = expandIntegratorMethods(args.options.methods, [](const std::string& line) {
    std::fprintf(stderr, "%s\n", line.c_str());
  });
  for (const std::string& method : args.options.methods) parseMethod(method);  // fail early

  ProgressLog progress;
  args.options.log = [&](const std::string& line) { progress.line(line); };
  args.options.progress = [&](const MethodProgress& p) {
    progress.update(p.method, p.step, p.steps, p.iterations, p.seconds);
  };
  InterruptGuard interrupt;
  args.options.cancel = &interruptRequested;
  // Locked against a second writer from the start when named, else once the scene names it.
  std::optional<OutputDirectory> locked;
  if (!args.out.empty()) locked.emplace(args.out);
  const Comparison comparison = runComparison(args.scene.scene, args.scene.overrides, args.options);
  progress.finish();

  const std::string out = args.out.empty() ? "compare-" + comparison.scene : args.out;
  if (!locked) locked.emplace(out);
  const nlohmann::json summary = summaryJson(comparison, commandLine());
  const std::vector<std::string> files = writeComparisonUnlessInterrupted(summary, out);

  printTable(comparison);
  for (const RunMetrics& run : comparison.runs)
    if (std::isfinite(run.worstPoseRmsToEquilibriumMm) && run.method != "equilibrium")
      std::printf(
          "%-28s RMS to equilibrium %.3g mm, worst pose %.3g mm (pose %d), worst muscle %s %.3g "
          "mm, worst muscle at a pose %s at pose %d %.3g mm, %.3g ms per pose\n",
          run.method.c_str(), run.rmsToEquilibriumMm, run.worstPoseRmsToEquilibriumMm,
          run.worstPoseToEquilibrium, run.worstMuscleToEquilibrium.c_str(),
          run.worstMuscleRmsToEquilibriumMm, run.worstMusclePoseToEquilibrium.muscle.c_str(),
          run.worstMusclePoseToEquilibrium.pose, run.worstMusclePoseToEquilibrium.rmsMm,
          run.msPerStep);
  for (const RunMetrics& run : comparison.runs)
    if (std::isfinite(run.residualRmsMm))
      std::printf(
          "%-28s residual RMS / max %.3g / %.3g mm (%.3g / %.3g N), worst pose %d%s\n",
          run.method.c_str(), run.residualRmsMm, run.residualMaxMm, run.residualRmsN,
          run.residualMaxN, run.residualWorstPose,
          run.unconvergedPoses > 0
              ? (", " + std::to_string(run.unconvergedPoses) + " pose(s) at the cap").c_str()
              : "");
  for (const RunMetrics& run : comparison.runs)
    if (!run.analytic.type.empty())
      std::printf("%-28s %s\n", run.method.c_str(), analyticLine(run.analytic).c_str());
  std::printf("wrote");
  for (const std::string& file : files) std::printf(" %s/%s", out.c_str(), file.c_str());
  std::printf("\n");
  if (interruptRequested.load()) throw CLI::RuntimeError(interruptExitCode());
}

}  // namespace

void addCompareCommand(CLI::App& app) {
  auto args = std::make_shared<CompareArgs>();
  args->options.methodBudgetSeconds = 60;  // keeps `compare thigh13` within 3 minutes
  CLI::App* command = app.add_subcommand(
      "compare",
      "Run a scene through FibreMSS, its self-reference (dt/8, 8x iterations), the btSoftBody "
      "baseline and Bullet's FEM, measured the same way against the CalculiX static reference "
      "(cached, with its gates); write summary.json, "
      "report.md and speed_vs_error.png/.svg (plus penetration_vs_step for sweeps) to --out.");
  addSceneArgs(*command, args->scene);
  command->add_option("--methods", args->methods, methodsHelp())->delimiter(',');
  command->add_option("--out", args->out, "Output directory (default: compare-<scene>)");
  addOffFlag(*command, "--no-fronts", args->options.fronts,
             "One run per method instead of sweeping each over its cost knob "
             "(fibremss: what ends its iterations, iterations x0.5-x4 or the stop rule's "
             "tolerance x2-x0.25, and resolution x0.5/x2; btsoftbody iterations and fem "
             "substeps x0.5-x2)");
  addOffFlag(*command, "--no-reference", args->options.withReference,
             "Skip the CalculiX reference (no RMS to it, no gates, no ranking)");
  addReferenceArgs(*command, args->options.reference);
  command
      ->add_option("--fem-cells", args->options.fem.mesher.targetCells,
                   "FEM: voxels per muscle (each 6 tetrahedra)")
      ->capture_default_str()
      ->check(positiveInteger());
  command
      ->add_option("--fem-substeps", args->options.fem.substepsPerPose, "FEM: world steps per pose")
      ->capture_default_str()
      ->check(positiveInteger());
  command
      ->add_option("--fem-damping", args->options.fem.damping,
                   "FEM: Neo-Hookean damping [s] (0: none; the solve is implicit in it)")
      ->capture_default_str()
      ->check(nonNegativeNumber());
  command
      ->add_option("--fem-omega-dt", args->options.fem.stableOmegaDt,
                   "FEM: mass scaling limit of a node's omega*dt (0: no mass scaling)")
      ->capture_default_str()
      ->check(nonNegativeNumber());
  command
      ->add_option("--softbody-substeps", args->options.softBody.substepsPerPose,
                   "btSoftBody: world steps per pose (0: the most particles on one fibre / 4)")
      ->capture_default_str()
      ->check(nonNegativeInteger());
  command
      ->add_option("--softbody-iterations", args->options.softBody.positionIterations,
                   "btSoftBody: position solver iterations per world step (0: the most "
                   "particles on one fibre x 2/5)")
      ->capture_default_str()
      ->check(nonNegativeInteger());
  command
      ->add_option("--method-budget", args->options.methodBudgetSeconds,
                   "Seconds of wall time per method; a method past it stops after its current "
                   "step and is reported over the steps it did (0: no limit)")
      ->capture_default_str()
      ->check(nonNegativeNumber());
  command
      ->add_option("--equilibrium-cap", args->options.equilibriumIterations,
                   "The equilibrium method's iteration cap per pose (a pose that reaches it is "
                   "counted as unconverged)")
      ->capture_default_str()
      ->check(positiveInteger());
  command->callback([args] { compare(*args); });
}

}  // namespace fibremss::cli
