#pragma once
// Progress of long jobs for the command line: on a terminal one line redrawn in place (a bar,
// steps, iterations per second, time left); otherwise (logs, pipes) a plain line when the job
// ends and one a minute while it runs.
#include <chrono>
#include <cstdio>
#include <string>

namespace fibremss {

/// True when `stream` is an interactive terminal.
bool isTerminal(std::FILE* stream);

/// "0.4 s", "12 s", "3 min 05 s", "2 h 10 min": a duration for people.
std::string formatDuration(double seconds);

class ProgressBar {
 public:
  /// Reports `total` steps of the job named `label` on `stream`; `interactive` redraws in place
  /// (default: when `stream` is a terminal).
  ProgressBar(std::string label, int total, std::FILE* stream = stderr);
  ProgressBar(std::string label, int total, std::FILE* stream, bool interactive);

  /// `done` of the total steps are finished, `iterations` solver iterations so far (0: no
  /// rate shown), `seconds` since the job started. On a terminal the line is redrawn at most ten
  /// times a second, in a log written at most once a minute (always for the last step).
  void update(int done, long iterations, double seconds);
  /// Ends the redrawn line so that later output starts on a fresh one.
  void finish();

  /// One progress line without newline, e.g.
  /// "fusiform [#####-----] 5/10 steps, 1.2e+04 it/s, 3 s left" (a bar only when barWidth > 0).
  static std::string format(const std::string& label, int done, int total, long iterations,
                            double seconds, int barWidth);

 private:
  std::string label_;                                 ///< job name shown first
  int total_;                                         ///< steps planned
  std::FILE* stream_;                                 ///< where lines go
  bool interactive_;                                  ///< redraw in place
  bool drawn_ = false;                                ///< a redrawn line is open on the terminal
  std::chrono::steady_clock::time_point lastDraw_{};  ///< for throttling redraws and log lines
};

}  // namespace fibremss
