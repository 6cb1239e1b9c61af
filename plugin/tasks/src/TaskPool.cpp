#include "fibremss/TaskPool.h"

#include <ctime>
#include <span>
#include <string>
#include <system_error>

#include "fibremss/Error.h"

#if defined(__SSE2__)
#include <immintrin.h>
#endif

namespace fibremss {
namespace {

/// Busy-wait rounds before yielding: a few tens of microseconds, longer than the serial gaps
/// between the phases of an iteration, shorter than the gaps between steps.
constexpr int kSpinRounds = 4000;
/// Rounds of giving the core away (sched_yield) before sleeping: a thread of another process
/// that holds this core runs, and the wait still wakes within a time slice.
constexpr int kYieldRounds = 64;

void relax() {
#if defined(__SSE2__)
  _mm_pause();
#else
  std::this_thread::yield();
#endif
}

/// Waits until `value` differs from `old`: spins briefly, then yields the core, then sleeps
/// (futex on Linux).
template <typename T>
T awaitChange(const std::atomic<T>& value, T old) {
  for (int round = 0; round < kSpinRounds + kYieldRounds; ++round) {
    const T now = value.load(std::memory_order_acquire);
    if (now != old) return now;
    if (round < kSpinRounds)
      relax();
    else
      std::this_thread::yield();
  }
  value.wait(old, std::memory_order_acquire);
  return value.load(std::memory_order_acquire);
}

/// When `threads` equally fast threads finish tasks of `ms` handed out in order, each to the
/// first thread free (TaskPool::work) [ms].
double scheduleEnd(std::span<const double> ms, unsigned threads) {
  double free[TaskProfile::kThreads] = {};
  for (double task : ms) *std::min_element(free, free + threads) += task;
  return *std::max_element(free, free + threads);
}

}  // namespace

double threadCpuMs() {
  timespec now{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &now);
  return static_cast<double>(now.tv_sec) * 1e3 + static_cast<double>(now.tv_nsec) * 1e-6;
}

TaskProfile::Phase& TaskProfile::phase(const char* name) {
  for (Phase& slot : phases)
    if (slot.name == name || !slot.name) {
      slot.name = name;
      return slot;
    }
  return phases[kPhases - 1];
}

unsigned TaskPool::resolve(int threads) {
  if (threads > 0) return static_cast<unsigned>(threads);
  return std::max(1u, std::thread::hardware_concurrency());
}

TaskPool::TaskPool(unsigned threads, const TaskScheduler& host) : host_(host) {
  const unsigned total = host_.present() ? 1 : threads == 0 ? resolve(0) : threads;
  workers_.reserve(total - 1);
  times_.resize(host_.present() ? resolve(1, host_) : total);
  for (unsigned t = 1; t < total; ++t) {
    try {
      workers_.emplace_back([this, t] { loop(t); });
    } catch (const std::system_error& e) {
      stop();  // the threads started end before the pool does
      throw InputError("simulation.threads", "",
                       "cannot start thread " + std::to_string(t + 1) + " of " +
                           std::to_string(total) + " (" + e.what() +
                           "): the system's limit on threads or memory (ulimit -u, ulimit -v) "
                           "allows fewer; expected fewer threads");
    }
  }
}

TaskPool::~TaskPool() {
  stop();
}

void TaskPool::stop() {
  stopping_.store(true);
  generation_.fetch_add(2);
  generation_.notify_all();
  for (std::thread& worker : workers_) worker.join();
}

void TaskPool::runOnHost(size_t count, Call call, void* context) const {
  struct Job {
    Call call;
    void* context;
  } job{call, context};
  const TaskCallback task = [](uint32_t begin, uint32_t end, uint32_t worker, void* erased) {
    const Job& running = *static_cast<const Job*>(erased);
    for (uint32_t index = begin; index < end; ++index) running.call(running.context, index, worker);
  };
  void* handle = host_.enqueueTask(task, static_cast<uint32_t>(count), 1, &job, host_.userContext);
  if (handle) host_.finishTask(handle, host_.userContext);
}

void TaskPool::runErased(size_t count, Call call, void* context) {
  if (host_.present() && count > 0) return runOnHost(count, call, context);
  if (workers_.empty() || count <= 1) {
    for (size_t index = 0; index < count; ++index) call(context, index, 0);
    return;
  }
  // Close the last job, let any late worker leave it, then publish this one. Sequentially
  // consistent: a worker either sees the closed generation or is seen inside.
  const uint64_t closed = generation_.fetch_add(1) + 1;
  while (inside_.load() != 0) relax();
  count_ = count;
  call_ = call;
  context_ = context;
  next_.store(0);
  done_.store(0);
  generation_.store(closed + 1);
  generation_.notify_all();
  work(0);
  for (size_t finished = done_.load(); finished != count; finished = done_.load())
    awaitChange(done_, finished);
}

void TaskPool::attach(TaskProfile* profile) {
  profile_ = profile;
  lastEndMs_ = -1;
  if (!profile) return;
  // The median time between two back-to-back reads.
  constexpr int kReads = 201;
  double gaps[kReads];
  for (double& gap : gaps) {
    const double first = threadCpuMs();
    gap = threadCpuMs() - first;
  }
  std::nth_element(gaps, gaps + kReads / 2, gaps + kReads);
  clockMs_ = gaps[kReads / 2];
}

void TaskPool::runProfiled(size_t count, Call call, void* context, const char* phase) {
  const double beginMs = threadCpuMs();
  if (lastEndMs_ >= 0) profile_->outsideMs += std::max(0.0, beginMs - lastEndMs_ - clockMs_);
  struct Profiled {
    Call call;
    void* context;
    std::vector<ThreadTimes>& times;
    std::vector<double>& taskMs;
    double clockMs;
  } profiled{call, context, times_, taskMs_, clockMs_};
  const Call timed = [](void* erased, size_t index, unsigned thread) {
    const Profiled& job = *static_cast<const Profiled*>(erased);
    const double start = threadCpuMs();
    job.call(job.context, index, thread);
    const double ms = std::max(0.0, threadCpuMs() - start - job.clockMs);
    ThreadTimes& own = job.times[thread];
    own.totalMs += ms;
    own.largestMs = std::max(own.largestMs, ms);
    job.taskMs[index] = ms;
  };
  std::fill(times_.begin(), times_.end(), ThreadTimes{});
  if (taskMs_.size() < count) taskMs_.resize(count);
  runErased(count, timed, &profiled);
  TaskProfile::Phase& slot = profile_->phase(phase);
  double total = 0, largest = 0;
  for (size_t t = 0; t < times_.size(); ++t) {
    total += times_[t].totalMs;
    largest = std::max(largest, times_[t].largestMs);
    if (t < TaskProfile::kThreads) profile_->busyMs[t] += times_[t].totalMs;
  }
  ++slot.runs;
  slot.tasks += count;
  slot.taskMs += total;
  slot.largestMs += largest;
  for (unsigned t = 0; t < TaskProfile::kThreads; ++t) {
    slot.boundMs[t] += std::max(largest, total / (t + 1));
    slot.scheduleMs[t] += scheduleEnd({taskMs_.data(), count}, t + 1);
  }
  lastEndMs_ = threadCpuMs();
}

void TaskPool::work(unsigned thread) {
  for (size_t index = next_.fetch_add(1); index < count_; index = next_.fetch_add(1)) {
    call_(context_, index, thread);
    if (done_.fetch_add(1) + 1 == count_) done_.notify_one();
  }
}

void TaskPool::loop(unsigned thread) {
  uint64_t seen = 0;
  while (true) {
    seen = awaitChange(generation_, seen);
    if (stopping_.load()) return;
    if (seen % 2 == 1) continue;  // being set up: wait for it to open
    inside_.fetch_add(1);
    if (generation_.load() == seen) work(thread);  // else it closed before we got in
    inside_.fetch_sub(1);
  }
}

}  // namespace fibremss
