// `fibremss stability [CASE...]`: the hard-case stability matrix: each integrator's
// stable step measured, then every case × integrator × multiple of it, each run judged and
// time-boxed; writes stability.json and stability.md. Ctrl-C (SIGTERM) stops within the running
// step and writes both files marked interrupted (exit 130, 143).
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "Commands.h"
#include "Interrupt.h"
#include "Validators.h"
#include "fibremss/Error.h"
#include "fibremss/Output.h"
#include "fibremss/Stability.h"

namespace fibremss::cli {
namespace {

struct StabilityArgs {
  std::vector<std::string> cases;        ///< CASE... (empty: the hard cases)
  std::vector<std::string> overrides;    ///< --set, every case
  std::string out = "stability";         ///< --out DIR
  std::vector<std::string> calibration;  ///< --calibrate CASE,... (empty: the options' default)
  StabilityOptions options;              ///< integrators, factors, boxes
};

/// The key of an override "key=value".
std::string overrideKey(const std::string& text) {
  return text.substr(0, text.find('='));
}

/// Appends the user's --set overrides after the defaults, dropping a default the user sets again
/// (it would be overridden anyway, and the report would print both).
void addOverrides(std::vector<std::string>& defaults, const std::vector<std::string>& user) {
  auto setByUser = [&](const std::string& text) {
    for (const std::string& u : user)
      if (overrideKey(u) == overrideKey(text)) return true;
    return false;
  };
  defaults.erase(std::remove_if(defaults.begin(), defaults.end(), setByUser), defaults.end());
  defaults.insert(defaults.end(), user.begin(), user.end());
}

void stability(StabilityArgs& args) {
  std::vector<StabilityCase> cases;
  for (const std::string& text : args.cases) cases.push_back(parseStabilityCase(text));
  if (cases.empty()) cases = defaultHardCases();
  if (!args.calibration.empty()) {
    args.options.calibration.clear();
    for (const std::string& text : args.calibration)
      args.options.calibration.push_back(parseStabilityCase(text));
  }
  addOverrides(args.options.overrides, args.overrides);
  for (const std::string& name : args.options.integrators) {
    Integrator kind{};
    if (fromString(name, kind)) continue;
    std::string known;
    for (const std::string& each : allIntegratorNames())
      known += (known.empty() ? "" : ", ") + each;
    throw InputError("--integrators", name, "unknown integrator; one of " + known);
  }
  args.options.log = [](const std::string& line) { std::fprintf(stderr, "%s\n", line.c_str()); };
  InterruptGuard interrupt;
  args.options.cancel = &interruptRequested;
  const StabilityMatrix matrix = runStabilityMatrix(cases, args.options);

  // Its cases are validated inside the matrix: nothing is written before, locked to write.
  const OutputDirectory locked(args.out);

  writeFileAtomically(args.out + "/stability.json",
                      stabilityJson(matrix, args.options).dump(1) + "\n");
  const std::string markdown = stabilityMarkdown(matrix, args.options);
  writeFileAtomically(args.out + "/stability.md", markdown);
  std::printf("%s\nwrote %s/stability.json %s/stability.md\n", markdown.c_str(), args.out.c_str(),
              args.out.c_str());
  if (matrix.interrupted) throw CLI::RuntimeError(interruptExitCode());
}

}  // namespace

void addStabilityCommand(CLI::App& app) {
  auto args = std::make_shared<StabilityArgs>();
  CLI::App* command = app.add_subcommand(
      "stability",
      "Hard-case stability matrix: every integrator's stable step measured, then each case at "
      "multiples of it; writes stability.json and stability.md to --out");
  command->footer(
      "CASE: a built-in scene or .json file, optionally with overrides and a stiffness factor: "
      "hip-extension:step_deg=4, hip-extension:step_deg=10*kappa=100. Without CASE: "
      "hip-extension at step_deg 2, 4, 5, 10, pinch, hip-extension with kappa x100, "
      "tension-spike. Failing runs are reported (nan/exploded/energy/timeout with the step), "
      "never fatal. Ctrl-C stops within the running step and writes both files marked "
      "interrupted (exit code 130; 143 for SIGTERM).");
  command->add_option("case", args->cases, "Cases (default: the hard cases)");
  command
      ->add_option("--set", args->overrides,
                   "Override for every case, after the defaults resolution=12 and strain_limit=0 "
                   "(repeatable)")
      ->allow_extra_args(false);
  command
      ->add_option("--integrators", args->options.integrators,
                   "Comma-separated integrators (default: every one)")
      ->delimiter(',');
  command
      ->add_option("--dt-factors", args->options.dtFactors,
                   "Comma-separated multiples of each integrator's stable step")
      ->delimiter(',')
      ->capture_default_str()
      ->check(positiveNumber());
  command
      ->add_option("--calibrate", args->calibration,
                   "Comma-separated cases on which each integrator's stable step is measured, "
                   "the smallest kept (default: hip-extension,pinch,tension-spike)")
      ->delimiter(',');
  command->add_option("--out", args->out, "Output directory")->capture_default_str();
  command
      ->add_option("--cell-seconds", args->options.cellSeconds,
                   "Wall-time box of one run; a run past it stops after its step (timeout)")
      ->capture_default_str()
      ->check(positiveNumber());
  command
      ->add_option("--calibration-steps", args->options.calibrationSteps,
                   "Steps of each stable-step probe")
      ->capture_default_str()
      ->check(positiveInteger());
  command->callback([args] { stability(*args); });
}

}  // namespace fibremss::cli
