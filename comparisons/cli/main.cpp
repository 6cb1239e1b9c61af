// The fibremss command-line tool.
#include <exception>
#include <iostream>

#include "Commands.h"
#include "fibremss/Error.h"

int main(int argc, char** argv) {
  CLI::App app{"FibreMSS: fibre-sampled mass-spring muscles with sphere collision for Bullet"};
  app.require_subcommand(1);
  fibremss::cli::addScenesCommand(app);
  fibremss::cli::addCheckCommand(app);
  fibremss::cli::addRunCommand(app);
  fibremss::cli::addCompareCommand(app);
  fibremss::cli::addMergeCommand(app);
  fibremss::cli::addFibresCommand(app);
  fibremss::cli::addStabilityCommand(app);
  fibremss::cli::addViewCommand(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const fibremss::InputError& e) {
    std::cerr << "fibremss: error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "fibremss: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
