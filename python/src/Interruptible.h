#pragma once
// Long calls that Ctrl-C stops: the work runs on a thread of its own while the calling thread,
// holding the GIL between waits, lets Python handle its signals; on a KeyboardInterrupt (or any
// exception a signal handler raises) the work's cancel flag is set, the work ends within its
// running step and the exception propagates.
#include <pybind11/pybind11.h>

#include <atomic>
#include <chrono>
#include <exception>
#include <future>
#include <utility>

namespace fibremss::python {

/// How often the waiting thread lets Python run its signal handlers [ms].
inline constexpr int kSignalPollMs = 50;

/// work(cancel) on a thread of its own, its result returned or its exception rethrown; a Python
/// signal handler's exception (KeyboardInterrupt on Ctrl-C) sets `cancel`, waits for the work to
/// stop and is raised instead.
template <typename Work>
auto interruptible(Work&& work) {
  std::atomic<bool> cancel{false};
  auto result = std::async(std::launch::async, [&] { return work(&cancel); });
  for (;;) {
    std::future_status status;
    {
      pybind11::gil_scoped_release release;
      status = result.wait_for(std::chrono::milliseconds(kSignalPollMs));
    }
    if (status == std::future_status::ready) return result.get();
    if (PyErr_CheckSignals() != 0) {
      cancel = true;
      {
        pybind11::gil_scoped_release release;
        result.wait();
      }
      throw pybind11::error_already_set();
    }
  }
}

}  // namespace fibremss::python
