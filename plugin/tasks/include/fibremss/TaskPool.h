#pragma once
// A small fixed pool of worker threads owned by the plugin (Debian's Bullet has no task
// scheduler): the core's step and preparation and the fibres' implicit surfaces run on it. A
// step is a fork–join of a dozen to a few dozen tasks per phase (per muscle, per chunk of a
// muscle's forces, per muscle pair), several phases per iteration: it wants a cheap wake-up and
// no allocation more than work stealing, and a pool of its own adds no dependency to the
// library.
#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <thread>
#include <type_traits>
#include <vector>

#include "fibremss/TaskScheduler.h"

namespace fibremss {

/// The thread CPU time of the tasks of every run() while attached to a pool (TaskPool::attach),
/// per phase name: fibremss_bench's balance report. Thread CPU time does not count
/// the time another process holds the core, so the shares hold on a loaded machine. A profiled
/// run reads the thread clock twice per task.
struct TaskProfile {
  static constexpr size_t kPhases = 16;    ///< distinct phase names kept (more: the last slot)
  static constexpr unsigned kThreads = 8;  ///< thread counts the bounds are given for
  /// What the runs of one phase cost.
  struct Phase {
    const char* name = nullptr;  ///< run()'s phase name (null: an unused slot)
    size_t runs = 0;             ///< run() calls
    size_t tasks = 0;            ///< tasks run
    double taskMs = 0;           ///< Σ of the tasks' thread CPU time [ms]
    double largestMs = 0;        ///< Σ over runs of the run's largest task [ms]
    /// Σ over runs of max(largest task, task time / T) for T = index + 1: no schedule of the
    /// run's tasks on T threads ends sooner (the critical-path bound) [ms].
    double boundMs[kThreads] = {};
    /// Σ over runs of the end of the pool's own schedule of the measured tasks on T = index + 1
    /// equally fast threads (each task, in index order, to the first thread free) [ms].
    double scheduleMs[kThreads] = {};
  };
  Phase phases[kPhases];         ///< by first appearance of the name
  double busyMs[kThreads] = {};  ///< thread CPU time in tasks per pool thread (0: the caller) [ms]
  /// The caller's thread CPU time between runs (from the end of one to the start of the next):
  /// the serial work between the phases [ms].
  double outsideMs = 0;

  /// The slot of phase `name` (pointer identity: names are string literals).
  Phase& phase(const char* name);
};

/// The calling thread's CPU time [ms] (CLOCK_THREAD_CPUTIME_ID).
double threadCpuMs();

/// threads − 1 workers plus the calling thread. run() hands out task indices one at a time
/// from a shared counter (largest tasks first balances best), so which thread runs a task
/// varies: tasks must write only their own outputs, or scratch of the thread index they get.
/// The caller waits for the tasks, never for a worker to show up: on a machine busy with other
/// processes a sleeping worker may get its time slice milliseconds later, and the caller then
/// simply runs every task itself. Workers spin briefly between runs, then sleep on the
/// generation counter. No allocation after construction; tasks must not throw.
class TaskPool {
 public:
  /// `threads` counts the caller; 0 means the machine's hardware threads. With a `host`
  /// scheduler the pool starts no threads and hands every run() to the host instead. Throws
  /// InputError (naming simulation.threads), the threads it started joined, when the system
  /// cannot start as many.
  explicit TaskPool(unsigned threads = 1, const TaskScheduler& host = {});
  ~TaskPool();
  TaskPool(const TaskPool&) = delete;
  TaskPool& operator=(const TaskPool&) = delete;

  /// Threads that run tasks, the caller included (≥ 1).
  unsigned threads() const { return resolve(static_cast<int>(workers_.size()) + 1, host_); }
  /// The host scheduler run() hands tasks to (empty: the pool's own threads).
  const TaskScheduler& host() const { return host_; }

  /// Calls task(index, thread) for every index in [0, count) and returns when all are done;
  /// thread < threads() names the running thread's scratch (0: the caller). `phase` names the
  /// run in an attached profile.
  template <typename Task>
  void run(size_t count, Task&& task, const char* phase = "tasks") {
    auto call = [](void* context, size_t index, unsigned thread) {
      (*static_cast<std::remove_reference_t<Task>*>(context))(index, thread);
    };
    void* context = const_cast<void*>(static_cast<const void*>(&task));
    if (profile_)
      runProfiled(count, call, context, phase);
    else
      runErased(count, call, context);
  }

  /// Records every later run() in `profile` (null: stops). Not during a run. Measures what a
  /// read of the thread clock costs, which every task's time then leaves out.
  void attach(TaskProfile* profile);

  /// The thread count a `threads` setting means (0: hardware threads, at least 1).
  static unsigned resolve(int threads);
  /// The threads a run with `host` (when present: its workerCount) or else `threads` uses.
  static unsigned resolve(int threads, const TaskScheduler& host) {
    return host.present() ? std::max(1u, host.workerCount) : resolve(threads);
  }

 private:
  using Call = void (*)(void* context, size_t index, unsigned thread);

  void runErased(size_t count, Call call, void* context);
  /// runErased with each task's thread CPU time added to profile_.
  void runProfiled(size_t count, Call call, void* context, const char* phase);
  /// runErased on the host scheduler: one enqueued task, then its finish.
  void runOnHost(size_t count, Call call, void* context) const;
  /// Runs tasks of the current job until the counter passes its end.
  void work(unsigned thread);
  /// A worker: waits for a new generation, works, reports done.
  void loop(unsigned thread);
  /// Ends the workers and joins them.
  void stop();

  TaskScheduler host_;                   ///< the host's scheduler, or empty
  std::vector<std::thread> workers_;     ///< threads 1 … threads−1
  std::atomic<uint64_t> generation_{0};  ///< even: a job is open; odd: the next is being set up
  std::atomic<unsigned> inside_{0};      ///< workers that may be reading the job's fields
  std::atomic<size_t> next_{0};          ///< next task index of the current job
  std::atomic<size_t> done_{0};          ///< tasks of the current job finished
  std::atomic<bool> stopping_{false};    ///< set by the destructor
  size_t count_ = 0;                     ///< tasks of the current job
  Call call_ = nullptr;                  ///< the current job's trampoline
  void* context_ = nullptr;              ///< the current job's task object
  TaskProfile* profile_ = nullptr;       ///< attached profile, or null
  /// A profiled run's sums per thread, each written by its own thread only.
  struct alignas(64) ThreadTimes {
    double totalMs = 0;    ///< Σ task thread CPU time in this run [ms]
    double largestMs = 0;  ///< largest task in this run [ms]
  };
  std::vector<ThreadTimes> times_;  ///< per thread of the pool
  std::vector<double> taskMs_;      ///< a profiled run's task times by index [ms]
  double clockMs_ = 0;              ///< what one read of the thread clock costs [ms]
  double lastEndMs_ = -1;           ///< the caller's thread clock when the last run ended [ms]
};

}  // namespace fibremss
