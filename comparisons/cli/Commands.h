#pragma once
// Each subcommand of the fibremss tool lives in its own file and registers itself here.
#include <CLI/CLI.hpp>

namespace fibremss::cli {

void addScenesCommand(CLI::App& app);     ///< `fibremss scenes`: list and export built-in scenes
void addCheckCommand(CLI::App& app);      ///< `fibremss check`: prepare a scene, print statistics
void addRunCommand(CLI::App& app);        ///< `fibremss run`: simulate a scene, write frames
void addCompareCommand(CLI::App& app);    ///< `fibremss compare`: all methods side by side
void addMergeCommand(CLI::App& app);      ///< `fibremss merge`: merge summaries into one report
void addFibresCommand(CLI::App& app);     ///< `fibremss fibres`: fibres from a muscle surface
void addStabilityCommand(CLI::App& app);  ///< `fibremss stability`: hard-case stability matrix
void addViewCommand(CLI::App& app);       ///< `fibremss view`: the interactive viewer

}  // namespace fibremss::cli
