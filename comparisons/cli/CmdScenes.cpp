// PLACEHOLDER until the owning work lands: replaced by the real `fibremss scenes`.
#include "Commands.h"

void fibremss::cli::addScenesCommand(CLI::App& app) { app.add_subcommand("scenes", "(not built yet)"); }
