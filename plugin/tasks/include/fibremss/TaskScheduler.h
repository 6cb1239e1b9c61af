#pragma once
// A host application's own task system, handed to the solver and to preparation (Box2D v3's
// enqueue/finish pair). Without one, FibreMSS runs its tasks on a small pool of its own.
#include <cstdint>

namespace fibremss {

/// A task FibreMSS hands to the host: run items [begin, end) on worker `worker` (< the
/// scheduler's workerCount; two ranges running at once must get different workers, as each
/// worker index names its own scratch). `taskContext` is FibreMSS's, pass it through.
using TaskCallback = void (*)(uint32_t begin, uint32_t end, uint32_t worker, void* taskContext);

/// The host's task system. enqueueTask must run task over every item of [0, itemCount) in
/// ranges of at least minRange items (in any order, on any of its workers, the caller's thread
/// included) and return a handle for finishTask, or null when it already ran every range;
/// finishTask(handle) returns once every range has run. FibreMSS enqueues one task at a time
/// and finishes it before the next, so a host may serialise them. Tasks do not throw. Results
/// are bit-identical to FibreMSS's own pool for any workerCount.
struct TaskScheduler {
  void* (*enqueueTask)(TaskCallback task, uint32_t itemCount, uint32_t minRange, void* taskContext,
                       void* userContext) = nullptr;                ///< null: FibreMSS's own pool
  void (*finishTask)(void* userTask, void* userContext) = nullptr;  ///< waits for a task
  void* userContext = nullptr;  ///< passed to enqueueTask and finishTask
  uint32_t workerCount = 1;     ///< distinct worker indices enqueued tasks may receive (≥ 1)

  /// Whether a host scheduler is set.
  bool present() const { return enqueueTask != nullptr && finishTask != nullptr; }
  bool operator==(const TaskScheduler&) const = default;
};

}  // namespace fibremss
