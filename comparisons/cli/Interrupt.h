#pragma once
// Ctrl-C for long commands (run, compare): the first SIGINT asks the work to stop after its
// current step, so every file written stays complete and the summary says "interrupted"; a
// second one ends the process at once.
#include <signal.h>
#include <unistd.h>

#include <atomic>

namespace fibremss::cli {

/// Exit code of a command stopped by Ctrl-C.
constexpr int kExitInterrupted = 130;

/// Set by SIGINT while an InterruptGuard lives; pass its address as the work's cancel flag.
inline std::atomic<bool> interruptRequested{false};

inline void onInterrupt(int) {
  interruptRequested.store(true);
  // write() is async-signal-safe; SA_RESETHAND made a second Ctrl-C end the process at once.
  const char message[] = "\nfibremss: interrupted, stopping after the current step\n";
  [[maybe_unused]] ssize_t written = write(STDERR_FILENO, message, sizeof message - 1);
}

/// Stops the work on SIGINT for as long as it lives, then restores the previous handler.
class InterruptGuard {
 public:
  InterruptGuard() {
    interruptRequested.store(false);
    struct sigaction action {};
    action.sa_handler = onInterrupt;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_RESETHAND;
    sigaction(SIGINT, &action, &previous_);
  }
  ~InterruptGuard() { sigaction(SIGINT, &previous_, nullptr); }
  InterruptGuard(const InterruptGuard&) = delete;
  InterruptGuard& operator=(const InterruptGuard&) = delete;

 private:
  struct sigaction previous_ {};
};

}  // namespace fibremss::cli
