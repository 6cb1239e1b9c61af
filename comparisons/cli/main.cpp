// The fibremss command-line tool. Exit codes: kExitCodes (Commands.h).
#include <LinearMath/btScalar.h>

#include <algorithm>
#include <exception>
#include <iostream>
#include <string>
#include <vector>

#include "Commands.h"
#include "fibremss/Error.h"
#include "fibremss/Kernel.h"
#include "fibremss/Suggest.h"

namespace {

/// Exit code of bad input and of every usage error (CLI11's own codes are 100 and up).
constexpr int kExitBadInput = 2;

/// An error message as printed: at most 2000 characters, however much of the input it quotes.
std::string capped(const std::string& message) {
  constexpr size_t kLimit = 2000;
  if (message.size() <= kLimit) return message;
  return message.substr(0, kLimit) + "... (" + std::to_string(message.size() - kLimit) +
         " more characters)";
}

/// --help and --version print and exit 0; the commands' own exit codes (3, 130) pass through
/// as CLI::RuntimeError; every other parse error is a usage error.
int exitFor(const CLI::App& app, const CLI::ParseError& e) {
  if (e.get_exit_code() == 0 || dynamic_cast<const CLI::RuntimeError*>(&e)) return app.exit(e);
  std::string message = e.what();
  // CLI11 says "--frame-every: At Most 1 required but received 2" of an option given twice.
  const size_t twice = message.find(": At Most 1 required but received");
  if (dynamic_cast<const CLI::ArgumentMismatch*>(&e) && twice != std::string::npos)
    message = message.substr(0, twice) + ": given more than once; give it once";
  std::cerr << "fibremss: error: " << message << "\n"
            << "Run with --help for more information.\n";
  return kExitBadInput;
}

/// The error for a first argument that is no option and no subcommand's name (empty when it is
/// one): the names there are, and the closest.
std::string unknownSubcommand(const CLI::App& app, const std::string& word) {
  if (word.starts_with("-")) return {};
  std::vector<std::string> names;
  for (const CLI::App* command : app.get_subcommands({})) names.push_back(command->get_name());
  if (std::find(names.begin(), names.end(), word) != names.end()) return {};
  std::string list;
  for (const std::string& name : names) list += (list.empty() ? "" : ", ") + name;
  return "unknown subcommand '" + word + "'" + fibremss::didYouMean(word, names) +
         " Subcommands: " + list + ".";
}

/// The table of exit codes ends the help of the tool and of every subcommand, after its own
/// footer.
void addExitCodes(CLI::App& app) {
  app.footer(fibremss::cli::kExitCodes);
  for (CLI::App* command : app.get_subcommands({})) {
    const std::string own = command->get_footer();
    command->footer(own.empty() ? fibremss::cli::kExitCodes
                                : own + "\n\n" + fibremss::cli::kExitCodes);
  }
}

/// What --version prints: FibreMSS's version, Bullet's version and btScalar precision, the
/// spring-force kernel chosen at runtime, the compiler.
std::string versionText() {
  const int bullet = btGetVersion();
#if defined(__clang__)
  const std::string compiler = "clang " __clang_version__;
#elif defined(__GNUC__)
  const std::string compiler = "GCC " __VERSION__;
#else
  const std::string compiler = "unknown";
#endif
  return "fibremss " FIBREMSS_VERSION
         "\n"
         "Bullet " +
         std::to_string(bullet / 100) + "." + std::to_string(bullet % 100) + ", btScalar " +
         (sizeof(btScalar) == sizeof(double) ? "double" : "float") +
         "\n"
         "spring kernel " +
         fibremss::activeSpringKernel() +
         " (chosen at runtime; FIBREMSS_SPRING_KERNEL=scalar|sse2|avx2 picks another)\n"
         "compiler " +
         compiler;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"FibreMSS: fibre-sampled mass-spring muscles with sphere collision for Bullet",
               "fibremss"};
  app.require_subcommand(1);
  app.set_version_flag("--version", versionText,
                       "Print the version, Bullet's version and precision, the SIMD kernel and the "
                       "compiler, and exit");
  fibremss::cli::addScenesCommand(app);
  fibremss::cli::addCheckCommand(app);
  fibremss::cli::addRunCommand(app);
  fibremss::cli::addCompareCommand(app);
  fibremss::cli::addMergeCommand(app);
  fibremss::cli::addFibresCommand(app);
  fibremss::cli::addStabilityCommand(app);
  fibremss::cli::addReferenceCommand(app);
  fibremss::cli::addViewCommand(app);
  addExitCodes(app);
  if (argc < 2) {  // no subcommand: what there is to run
    std::cout << app.help();
    return 0;
  }
  if (const std::string error = unknownSubcommand(app, argv[1]); !error.empty()) {
    std::cerr << "fibremss: error: " << error << "\nRun with --help for more information.\n";
    return kExitBadInput;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return exitFor(app, e);
  } catch (const fibremss::InputError& e) {
    std::cerr << "fibremss: error: " << capped(e.what()) << "\n";
    return kExitBadInput;
  } catch (const std::exception& e) {
    std::cerr << "fibremss: error: " << capped(e.what()) << "\n";
    return 1;
  }
  return 0;
}
