#pragma once
// One progress bar per job on stderr, with lines of news in between: what `compare` and
// `reference` show while they run.
#include <cstdio>
#include <memory>
#include <string>

#include "fibremss/Progress.h"

namespace fibremss::cli {

class ProgressLog {
 public:
  /// A line of news: ends the current bar first.
  void line(const std::string& text) {
    finish();
    std::fprintf(stderr, "%s\n", text.c_str());
  }
  /// `done` of `total` steps of the job `label` (a new bar when the label changes).
  void update(const std::string& label, int done, int total, long iterations, double seconds) {
    if (!bar_ || label_ != label) {
      finish();
      bar_ = std::make_unique<ProgressBar>(label, total);
      label_ = label;
    }
    bar_->update(done, iterations, seconds);
  }
  /// Ends the current bar (if any).
  void finish() {
    if (bar_) bar_->finish();
    bar_.reset();
  }

 private:
  std::unique_ptr<ProgressBar> bar_;
  std::string label_;
};

}  // namespace fibremss::cli
