#pragma once
// A small fixed pool of worker threads owned by the plugin (Debian's Bullet has no task
// scheduler), internal. A step is a fork–join of a dozen per-muscle tasks per phase, several
// phases per iteration: it wants a cheap wake-up and no allocation more than work stealing,
// and a pool of its own adds no dependency to the library.
#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <thread>
#include <type_traits>
#include <vector>

#include "fibremss/TaskScheduler.h"

namespace fibremss {

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
  /// scheduler the pool starts no threads and hands every run() to the host instead.
  explicit TaskPool(unsigned threads = 1, const TaskScheduler& host = {});
  ~TaskPool();
  TaskPool(const TaskPool&) = delete;
  TaskPool& operator=(const TaskPool&) = delete;

  /// Threads that run tasks, the caller included (≥ 1).
  unsigned threads() const { return resolve(static_cast<int>(workers_.size()) + 1, host_); }
  /// The host scheduler run() hands tasks to (empty: the pool's own threads).
  const TaskScheduler& host() const { return host_; }

  /// Calls task(index, thread) for every index in [0, count) and returns when all are done;
  /// thread < threads() names the running thread's scratch (0: the caller).
  template <typename Task>
  void run(size_t count, Task&& task) {
    auto call = [](void* context, size_t index, unsigned thread) {
      (*static_cast<std::remove_reference_t<Task>*>(context))(index, thread);
    };
    runErased(count, call, const_cast<void*>(static_cast<const void*>(&task)));
  }

  /// The thread count a `threads` setting means (0: hardware threads, at least 1).
  static unsigned resolve(int threads);
  /// The threads a run with `host` (when present: its workerCount) or else `threads` uses.
  static unsigned resolve(int threads, const TaskScheduler& host) {
    return host.present() ? std::max(1u, host.workerCount) : resolve(threads);
  }

 private:
  using Call = void (*)(void* context, size_t index, unsigned thread);

  void runErased(size_t count, Call call, void* context);
  /// runErased on the host scheduler: one enqueued task, then its finish.
  void runOnHost(size_t count, Call call, void* context) const;
  /// Runs tasks of the current job until the counter passes its end.
  void work(unsigned thread);
  /// A worker: waits for a new generation, works, reports done.
  void loop(unsigned thread);

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
};

}  // namespace fibremss
