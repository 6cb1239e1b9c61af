// Programs the references run as processes (tetgen, ccx): started with fork/exec in a working
// directory, output to a log file, polled so that a long solve shows progress and can be
// cancelled.
#include <fcntl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <map>
#include <mutex>
#include <regex>
#include <stdexcept>
#include <thread>

#include "fibremss/Calculix.h"

namespace fibremss {
namespace {

/// In the child: into `workDir`, its address space limited to `memoryLimit` bytes (0: not
/// limited), stdout and stderr to `logPath`, then exec `args` (null-terminated, built before the
/// fork: the child allocates nothing, since malloc after fork is unsafe in a threaded process
/// and fails under the limit in a sanitizer build). Never returns.
[[noreturn]] void execChild(char* const* args, const std::string& workDir,
                            const std::string& logPath, uint64_t memoryLimit) {
  if (!workDir.empty() && chdir(workDir.c_str()) != 0) _exit(126);
  const rlimit limit{memoryLimit, memoryLimit};
  if (memoryLimit > 0 && setrlimit(RLIMIT_AS, &limit) != 0) _exit(126);
  const int log = open(logPath.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (log < 0) _exit(126);
  dup2(log, STDOUT_FILENO);
  dup2(log, STDERR_FILENO);
  close(log);
  const int null = open("/dev/null", O_RDONLY);
  if (null >= 0) dup2(null, STDIN_FILENO);
  execvp(args[0], args);
  _exit(127);
}

int exitStatus(int status) {
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
  return -1;
}

}  // namespace

int runProgram(const std::vector<std::string>& argv, const std::string& workDir,
               const std::string& logPath, const std::function<bool()>& poll,
               uint64_t memoryLimit) {
  if (argv.empty()) throw std::runtime_error("runProgram: no program given");
  std::vector<char*> args;
  for (const std::string& arg : argv) args.push_back(const_cast<char*>(arg.c_str()));
  args.push_back(nullptr);
  const pid_t child = fork();
  if (child < 0) throw std::runtime_error("cannot start " + argv[0] + ": " + std::strerror(errno));
  if (child == 0) execChild(args.data(), workDir, logPath, memoryLimit);
  int status = 0;
  for (;;) {
    const pid_t done = waitpid(child, &status, WNOHANG);
    if (done == child) break;
    if (done < 0 && errno != EINTR)
      throw std::runtime_error("waitpid: " + std::string(std::strerror(errno)));
    if (poll && !poll()) {
      kill(child, SIGTERM);
      while (waitpid(child, &status, 0) < 0 && errno == EINTR) {
      }
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  const int code = exitStatus(status);
  if (code == 127) throw std::runtime_error("cannot run '" + argv[0] + "' (not installed?)");
  return code;
}

double defaultCalculixMemoryGiB() {
  const double physical =
      double(sysconf(_SC_PHYS_PAGES)) * double(sysconf(_SC_PAGE_SIZE)) / double(1ull << 30);
  return physical > 0 ? std::min(8.0, physical / 2) : 8.0;
}

std::string calculixVersion(const std::string& program) {
  static std::mutex mutex;
  static std::map<std::string, std::string> versions;
  const std::lock_guard lock(mutex);
  if (auto it = versions.find(program); it != versions.end()) return it->second;
  char path[] = "/tmp/fibremss-ccx-version-XXXXXX";
  const int file = mkstemp(path);
  if (file < 0) throw std::runtime_error("cannot create a temporary file for 'ccx -v'");
  close(file);
  runProgram({program, "-v"}, "", path);
  std::ifstream in(path);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::remove(path);
  std::smatch match;
  const std::string version = std::regex_search(text, match, std::regex("Version ([0-9.]+)"))
                                  ? "ccx " + match[1].str()
                                  : "ccx (unknown version)";
  return versions[program] = version;
}

}  // namespace fibremss
