#pragma once
// Each subcommand of the fibremss tool lives in its own file and registers itself here.
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace fibremss::cli {

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
