#pragma once
// Whether the step's iterations run on all of the pool's threads or on the caller alone (issue
// 18), internal. Another process that holds a core preempts a worker in the middle of a task,
// and the caller then waits at the join for the worker's next time slice: two threads can be
// slower than one. Over each window of iterations the governor takes the CPU time the threads
// spent working: the caller's thread CPU time less its wall time waiting at the joins, plus the
// workers' thread CPU time in tasks (TaskPool::joinTimes). A wait short of the spin is CPU time;
// a longer one (a worker preempted in a task, or late) also takes off the time the caller slept:
// it counts against all threads. The caller alone would need that work divided by the
// share of a core it gets when alone (from its windows alone, the latest weighing half; 1 until
// one ran), so all threads pay while their window's wall time is shorter than that. Stalls, a
// worker that gets no core, and threads that share one all show in the same window's figures.
// It switches to the caller alone as soon as a window on all threads does not pay, and then
// probes all threads for a window now and then (the interval doubling while the probes confirm
// the caller alone). While all threads pay only thanks to the measured share (their work is less
// than their wall time), a window on the caller alone refreshes the share at the same intervals;
// on an idle machine their work exceeds their wall time and nothing is probed. The results are
// the same bits in either mode (every task is independent and every sum runs in a fixed order),
// so a switch changes only the time.
#include <chrono>

#include "TaskPool.h"

namespace fibremss {

class ThreadGovernor {
 public:
  /// Iterations per window: enough that one window's verdict is not the machine's noise (a
  /// wrong switch to the caller alone lasts at least kFirstInterval).
  static constexpr int kWindow = 20;
  /// Iterations before the first probe after a switch; each probe that confirms the mode
  /// doubles it, up to kLongestInterval.
  static constexpr int kFirstInterval = 4 * kWindow;
  static constexpr int kLongestInterval = 32 * kWindow;

  /// What one iteration, or a window of them, took [ms].
  struct Times {
    double wallMs = 0;    ///< wall time
    double callerMs = 0;  ///< the caller's thread CPU time
    double waitMs = 0;    ///< the caller's wall time waiting at the joins
    double workerMs = 0;  ///< the workers' thread CPU time in tasks
  };

  /// Before an iteration, with the pool's running totals: whether it runs on all threads (false:
  /// on the caller alone).
  bool begin(const JoinTimes& totals);
  /// After that iteration, with the pool's running totals: record() of what it took.
  void end(const JoinTimes& totals);
  /// Whether the next iteration runs on all threads.
  bool parallel() const { return probing_ != chosenParallel_; }
  /// Adds an iteration that ran as parallel() said to the window; decides at the window's end.
  void record(const Times& iteration);

 private:
  using Clock = std::chrono::steady_clock;
  /// The window's verdict and the next mode.
  void endWindow();
  /// After a window on all threads: whether they paid, at the caller's share `share`.
  bool paid(double share) const;

  bool chosenParallel_ = true;     ///< the mode the iterations run on outside probes
  bool probing_ = false;           ///< the running window runs the other mode
  int sinceProbe_ = 0;             ///< iterations since the last probe or switch
  int interval_ = kFirstInterval;  ///< iterations before the next probe
  /// The share of a core the caller gets alone: over its windows alone, each new one weighing half.
  double aloneShare_ = 1;
  Times window_;                 ///< what the running window took so far
  int inWindow_ = 0;             ///< its iterations
  Clock::time_point startWall_;  ///< when the running iteration began
  double startCallerMs_ = 0;     ///< the caller's thread CPU time then [ms]
  JoinTimes startTotals_;        ///< the pool's totals then
};

}  // namespace fibremss
