#include "ThreadGovernor.h"

#include <algorithm>

namespace fibremss {

bool ThreadGovernor::begin(const JoinTimes& totals) {
  startWall_ = Clock::now();
  startCallerMs_ = threadCpuMs();
  startTotals_ = totals;
  return parallel();
}

void ThreadGovernor::end(const JoinTimes& totals) {
  record({std::chrono::duration<double, std::milli>(Clock::now() - startWall_).count(),
          threadCpuMs() - startCallerMs_, totals.waitMs - startTotals_.waitMs,
          totals.workerMs - startTotals_.workerMs});
}

void ThreadGovernor::record(const Times& iteration) {
  window_.wallMs += iteration.wallMs;
  window_.callerMs += iteration.callerMs;
  window_.waitMs += iteration.waitMs;
  window_.workerMs += iteration.workerMs;
  ++sinceProbe_;
  if (++inWindow_ == kWindow) endWindow();
}

bool ThreadGovernor::paid(double share) const {
  const double workMs = window_.callerMs - window_.waitMs + window_.workerMs;
  return workMs / share > window_.wallMs;
}

void ThreadGovernor::endWindow() {
  const bool parallel = this->parallel();
  if (!parallel && window_.wallMs > 0)
    aloneShare_ = (aloneShare_ + std::clamp(window_.callerMs / window_.wallMs, 0.05, 1.0)) / 2;
  const bool pays = parallel && paid(aloneShare_);
  const bool probed = probing_;
  probing_ = false;
  if (parallel && !pays) {  // to the caller alone
    interval_ =
        chosenParallel_ || !probed ? kFirstInterval : std::min(2 * interval_, kLongestInterval);
    chosenParallel_ = false;
    sinceProbe_ = 0;
  } else if (parallel && !chosenParallel_) {  // a probe that paid: back to all threads
    chosenParallel_ = true;
    interval_ = kFirstInterval;
    sinceProbe_ = 0;
  } else if (probed) {  // the share refreshed (all threads), or a probe confirmed (alone)
    interval_ = std::min(2 * interval_, kLongestInterval);
    sinceProbe_ = 0;
  } else if (sinceProbe_ >= interval_ && (!chosenParallel_ || !paid(1))) {
    probing_ = true;  // all threads again, or the share their verdict rests on
  }
  window_ = Times{};
  inWindow_ = 0;
}

}  // namespace fibremss
