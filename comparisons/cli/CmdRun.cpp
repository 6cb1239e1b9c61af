// PLACEHOLDER until the owning work lands: replaced by the real `fibremss run`.
#include "Commands.h"

void fibremss::cli::addRunCommand(CLI::App& app) { app.add_subcommand("run", "(not built yet)"); }
