#include "fibremss/Progress.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <utility>

namespace fibremss {

bool isTerminal(std::FILE* stream) {
  return stream && isatty(fileno(stream)) == 1;
}

std::string formatDuration(double seconds) {
  char text[64];
  if (!std::isfinite(seconds) || seconds < 0) return "?";
  if (seconds < 10) {
    std::snprintf(text, sizeof text, "%.1f s", seconds);
  } else if (seconds < 60) {
    std::snprintf(text, sizeof text, "%.0f s", seconds);
  } else if (seconds < 3600) {
    const long whole = std::lround(seconds);
    std::snprintf(text, sizeof text, "%ld min %02ld s", whole / 60, whole % 60);
  } else {
    const long minutes = std::lround(seconds / 60);
    std::snprintf(text, sizeof text, "%ld h %02ld min", minutes / 60, minutes % 60);
  }
  return text;
}

ProgressBar::ProgressBar(std::string label, int total, std::FILE* stream)
    : ProgressBar(std::move(label), total, stream, isTerminal(stream)) {}

ProgressBar::ProgressBar(std::string label, int total, std::FILE* stream, bool interactive)
    : label_(std::move(label)),
      total_(total),
      stream_(stream),
      interactive_(interactive),
      lastDraw_(std::chrono::steady_clock::now()) {}

std::string ProgressBar::format(const std::string& label, int done, int total, long iterations,
                                double seconds, int barWidth) {
  std::string line = label;
  if (barWidth > 0) {
    const int filled =
        total > 0
            ? static_cast<int>(static_cast<long>(barWidth) * std::clamp(done, 0, total) / total)
            : 0;
    line += " [" + std::string(filled, '#') + std::string(barWidth - filled, '-') + "]";
  }
  char text[160];
  std::snprintf(text, sizeof text, " %d/%d steps", done, total);
  line += text;
  if (seconds > 0 && iterations > 0) {  // a job without iterations (ccx) shows none
    const double rate = static_cast<double>(iterations) / seconds;
    std::snprintf(text, sizeof text, rate >= 100 ? ", %.0f it/s" : ", %.3g it/s", rate);
    line += text;
  }
  if (done > 0 && done < total)
    line += ", " + formatDuration(seconds / done * (total - done)) + " left";
  else if (done >= total)
    line += ", " + formatDuration(seconds) + " in all";
  return line;
}

void ProgressBar::update(int done, long iterations, double seconds) {
  if (!stream_) return;
  const auto now = std::chrono::steady_clock::now();
  if (!interactive_) {
    // A log gets the job's last line, and one a minute while it runs.
    if (done < total_ && now - lastDraw_ < std::chrono::minutes(1)) return;
    lastDraw_ = now;
    std::fprintf(stream_, "%s\n", format(label_, done, total_, iterations, seconds, 0).c_str());
    std::fflush(stream_);
    return;
  }
  if (drawn_ && done < total_ && now - lastDraw_ < std::chrono::milliseconds(100)) return;
  lastDraw_ = now;
  // Carriage return, the line, then erase whatever a longer previous line left behind.
  std::fprintf(stream_, "\r%s\x1b[K",
               format(label_, done, total_, iterations, seconds, 30).c_str());
  std::fflush(stream_);
  drawn_ = true;
}

void ProgressBar::finish() {
  if (stream_ && interactive_ && drawn_) {
    std::fputc('\n', stream_);
    std::fflush(stream_);
  }
  drawn_ = false;
}

}  // namespace fibremss
