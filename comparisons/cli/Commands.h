#pragma once
// Each subcommand of the fibremss tool lives in its own file and registers itself here.
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace fibremss::cli {

/// The exit codes of every subcommand, as `fibremss --help`, README.md and docs/bad-inputs.md
/// state them.
inline constexpr const char* kExitCodes =
    "Exit codes (every subcommand): 0 done, 2 bad input or usage, 3 a run that failed "
    "numerically, 4 a run with on_failure=stop-body that ran every step but froze a muscle on "
    "the way, 130 interrupted by Ctrl-C, 143 by SIGTERM, 1 an internal error "
    "(docs/bad-inputs.md).";

void addScenesCommand(CLI::App& app);     ///< `fibremss scenes`: list and export built-in scenes
void addCheckCommand(CLI::App& app);      ///< `fibremss check`: prepare a scene, print statistics
void addRunCommand(CLI::App& app);        ///< `fibremss run`: simulate a scene, write frames
void addCompareCommand(CLI::App& app);    ///< `fibremss compare`: all methods side by side
void addMergeCommand(CLI::App& app);      ///< `fibremss merge`: merge summaries into one report
void addFibresCommand(CLI::App& app);     ///< `fibremss fibres`: fibres from a muscle surface
void addStabilityCommand(CLI::App& app);  ///< `fibremss stability`: hard-case stability matrix
void addReferenceCommand(CLI::App& app);  ///< `fibremss reference`: the CalculiX reference
void addViewCommand(CLI::App& app);       ///< `fibremss view`: the interactive viewer

/// writeComparison() while an InterruptGuard lives: when a signal stopped it (gnuplot ended
/// with the process group), the command ends with 130 or 143; the plot that was being drawn
/// leaves no partial file, the files written before it stay.
std::vector<std::string> writeComparisonUnlessInterrupted(const nlohmann::json& summary,
                                                          const std::string& out);

}  // namespace fibremss::cli
