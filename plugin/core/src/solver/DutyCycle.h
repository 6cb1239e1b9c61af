#pragma once
// When a pool worker should run tasks only in short bursts (issue 18), internal. A worker that
// shares its core with another CPU-bound thread is preempted now and then, and if that happens
// while it holds a task, the caller's join waits for it for the other thread's whole time slice
// (milliseconds: several solver iterations). A worker that has seen such contention therefore
// *cycles*: after it gets the core it claims tasks for at most kBurstMs, shorter than the slice
// the scheduler grants a thread that has just woken, then sleeps for kSleepMs without holding a
// task, so the other thread gets its share while the caller works on alone. This is the policy
// alone: TaskPool::loop feeds it the worker's involuntary context switches, so it can be tested on
// synthetic figures.

namespace fibremss {

/// Whether one worker cycles, from what it reports after its jobs and bursts.
class DutyCycle {
 public:
  /// Longest time a cycling worker claims tasks after it wakes [ms] (a task it has claimed runs
  /// to its end). Next to a busy loop on the 2-core reference VM (kernel 6.18, 4 ms tick), bursts
  /// of 0.5 ms were preempted in 1–3 % of cases, of 1.5 ms and more in 11–48 %.
  static constexpr double kBurstMs = 0.5;
  /// Longest wait of a cycling worker for the next job within a burst (longer than the serial
  /// work between two phases); it sleeps if none opens by then [ms].
  static constexpr double kGapMs = 0.05;
  /// A cycling worker's voluntary sleep between bursts [ms].
  static constexpr double kSleepMs = 0.1;
  /// Calm bursts in a row (never switched out) that end the cycling.
  static constexpr int kCalmBursts = 16;

  /// Whether the worker runs tasks only in bursts.
  bool cycling() const { return cycling_; }

  /// After a job whose tasks the worker ran at full time, switched out involuntarily
  /// `preemptions` times while it held them: any such switch starts the cycling.
  void afterTasks(long preemptions) {
    if (preemptions > 0) {
      cycling_ = true;
      calm_ = 0;
    }
  }

  /// After a burst in which the worker was switched out involuntarily `preemptions` times;
  /// kCalmBursts calm ones (never switched out) in a row end the cycling. How late it woke does
  /// not count: a worker that shares the caller's core always wakes late, and would cycle on.
  void afterBurst(long preemptions) {
    calm_ = preemptions == 0 ? calm_ + 1 : 0;
    if (calm_ >= kCalmBursts) cycling_ = false;
  }

 private:
  bool cycling_ = false;  ///< runs tasks only in bursts
  int calm_ = 0;          ///< calm bursts in a row while cycling
};

}  // namespace fibremss
