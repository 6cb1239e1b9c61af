// PLACEHOLDER until the owning work lands: replaced by the real `fibremss check`.
#include "Commands.h"

void fibremss::cli::addCheckCommand(CLI::App& app) { app.add_subcommand("check", "(not built yet)"); }
