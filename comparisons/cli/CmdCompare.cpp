// PLACEHOLDER until the owning work lands: replaced by the real `fibremss compare`.
#include "Commands.h"

void fibremss::cli::addCompareCommand(CLI::App& app) { app.add_subcommand("compare", "(not built yet)"); }
