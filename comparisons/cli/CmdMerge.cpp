// PLACEHOLDER until the owning work lands: replaced by the real `fibremss merge`.
#include "Commands.h"

void fibremss::cli::addMergeCommand(CLI::App& app) { app.add_subcommand("merge", "(not built yet)"); }
