#pragma once
// Ctrl-C (or SIGTERM: `kill`, `timeout`, a job scheduler) for long commands (run, compare,
// stability, reference): the first signal asks the work to stop — a FibreMSS run within its
// current step, at the end of the running iteration (MuscleSystem::setCancelFlag), the baselines
// after their current step, ccx at once — so every file written stays complete, the summary says
// "interrupted" and no ccx is left running; a second one ends the process at once.
#include <signal.h>
#include <unistd.h>

#include <atomic>

namespace fibremss::cli {

/// Set by SIGINT or SIGTERM while an InterruptGuard lives; pass its address as the work's
/// cancel flag.
inline std::atomic<bool> interruptRequested{false};
/// The signal that set interruptRequested (SIGINT or SIGTERM); 0: none.
inline std::atomic<int> interruptSignal{0};

/// Exit code of a command so stopped: 128 + the signal (130 for Ctrl-C, 143 for SIGTERM), as
/// a shell reports a process the signal ended.
inline int interruptExitCode() {
  return 128 + interruptSignal.load();
}

inline void onInterrupt(int signal) {
  interruptSignal.store(signal);
  interruptRequested.store(true);
  // write() is async-signal-safe; SA_RESETHAND made a second Ctrl-C end the process at once.
  const char message[] = "\nfibremss: interrupted, stopping\n";
  [[maybe_unused]] ssize_t written = write(STDERR_FILENO, message, sizeof message - 1);
}

/// Stops the work on SIGINT or SIGTERM for as long as it lives, then restores the previous
/// handlers.
class InterruptGuard {
 public:
  InterruptGuard() {
    interruptRequested.store(false);
    interruptSignal.store(0);
    struct sigaction action {};
    action.sa_handler = onInterrupt;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_RESETHAND;
    sigaction(SIGINT, &action, &previousInterrupt_);
    sigaction(SIGTERM, &action, &previousTerminate_);
  }
  ~InterruptGuard() {
    sigaction(SIGINT, &previousInterrupt_, nullptr);
    sigaction(SIGTERM, &previousTerminate_, nullptr);
  }
  InterruptGuard(const InterruptGuard&) = delete;
  InterruptGuard& operator=(const InterruptGuard&) = delete;

 private:
  struct sigaction previousInterrupt_ {};
  struct sigaction previousTerminate_ {};
};

}  // namespace fibremss::cli
