// `fibremss merge DIR...`: the summary.json files of several `compare` runs (e.g. cluster
// cells, one method or one resolution each) merged into one report with plots.
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "Commands.h"
#include "fibremss/CompareReport.h"
#include "fibremss/Output.h"

namespace fibremss::cli {
namespace {

struct MergeArgs {
  std::vector<std::string> inputs;  ///< directories or summary.json files
  std::string out = "merged";       ///< --out DIR
};

void merge(const MergeArgs& args) {
  std::vector<nlohmann::json> summaries;
  for (const std::string& input : args.inputs) summaries.push_back(readSummary(input));
  const nlohmann::json merged = mergeSummaries(summaries, args.inputs);
  const OutputDirectory locked(args.out);  // a second writer into it is refused
  const std::vector<std::string> files = writeComparison(merged, args.out);
  std::printf("merged %zu runs from %zu summaries; wrote", merged["runs"].size(), summaries.size());
  for (const std::string& file : files) std::printf(" %s/%s", args.out.c_str(), file.c_str());
  std::printf("\n");
}

}  // namespace

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
