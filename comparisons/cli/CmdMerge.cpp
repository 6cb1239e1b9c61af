// `fibremss merge DIR...`: the summary.json files of several `compare` runs (e.g. cluster
// cells, one method or one resolution each) merged into one report with plots.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "Commands.h"
#include "Interrupt.h"
#include "fibremss/CompareReport.h"
#include "fibremss/Error.h"
#include "fibremss/Messages.h"
#include "fibremss/Output.h"

namespace fibremss::cli {
namespace {

struct MergeArgs {
  std::vector<std::string> inputs;  ///< directories or summary.json files
  std::string out = "merged";       ///< --out DIR
};

/// Refuses an --out that holds one of the inputs: the merged summary.json would replace it.
void requireOutputBesideInputs(const MergeArgs& args) {
  namespace fs = std::filesystem;
  std::error_code error;
  if (!fs::is_directory(args.out, error)) return;
  for (const std::string& input : args.inputs) {
    const fs::path folder =
        fs::is_directory(input, error) ? fs::path(input) : fs::absolute(input).parent_path();
    if (fs::equivalent(folder, args.out, error))
      throw InputError(args.out, "--out",
                       "holds the input " + input +
                           ", whose summary.json the merge would overwrite; expected another "
                           "directory");
  }
}

void merge(const MergeArgs& args) {
  requireOutputBesideInputs(args);
  std::vector<nlohmann::json> summaries;
  for (const std::string& input : args.inputs) summaries.push_back(readSummary(input));
  const nlohmann::json merged = mergeSummaries(summaries, args.inputs);
  const OutputDirectory locked(args.out);  // a second writer into it is refused
  const InterruptGuard interrupt;
  const std::vector<std::string> files = writeComparisonUnlessInterrupted(merged, args.out);
  std::printf("merged %zu runs from %zu summaries; wrote", merged["runs"].size(), summaries.size());
  for (const std::string& file : files) std::printf(" %s/%s", args.out.c_str(), file.c_str());
  std::printf("\n");
  if (interruptRequested.load()) throw CLI::RuntimeError(interruptExitCode());
}

}  // namespace

std::vector<std::string> writeComparisonUnlessInterrupted(const nlohmann::json& summary,
                                                          const std::string& out) {
  try {
    return writeComparison(summary, out);
  } catch (const std::runtime_error&) {
    if (!interruptRequested.load()) throw;
    printNote("interrupted while plotting; the files written before it are kept in " + out +
              ", report.md is not written");
    throw CLI::RuntimeError(interruptExitCode());
  }
}

void addMergeCommand(CLI::App& app) {
  auto args = std::make_shared<MergeArgs>();
  CLI::App* command = app.add_subcommand(
      "merge",
      "Merge the summary.json files of several `fibremss compare` runs (directories or files) "
      "into one summary.json, report.md and plots in --out.");
  command->add_option("inputs", args->inputs, "compare output directories or summary.json files")
      ->required();
  command->add_option("--out", args->out, "Output directory")->capture_default_str();
  command->callback([args] { merge(*args); });
}

}  // namespace fibremss::cli
