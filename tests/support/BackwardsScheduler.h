#pragma once
// A host scheduler (TaskScheduler.h) that runs tasks in the reverse of the pool's order.
#include "fibremss/TaskScheduler.h"

namespace fibremss::testing {

/// A host scheduler that runs every task at once, on the calling thread, from the last index to
/// the first (worker indices 0, 1, 2 in turn): the reverse of the pool's order on one thread.
inline TaskScheduler backwards() {
  TaskScheduler scheduler;
  scheduler.enqueueTask = [](TaskCallback task, uint32_t count, uint32_t, void* context,
                             void*) -> void* {
    for (uint32_t k = count; k-- > 0;) task(k, k + 1, k % 3, context);
    return nullptr;  // done: nothing to finish
  };
  scheduler.finishTask = [](void*, void*) {};
  scheduler.workerCount = 3;
  return scheduler;
}

}  // namespace fibremss::testing
