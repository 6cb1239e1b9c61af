#include "fibremss/PlotLayout.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

namespace fibremss {
namespace {

// The speed–error plots' plot area on their 1000×650 canvas (measured on pinch's, key of two
// rows below it) and the size of an 8-point DejaVu Sans label on it [pixels].
constexpr double kAreaWidthPx = 890, kAreaHeightPx = 500;
constexpr double kCharWidthPx = 6.2, kLabelHeightPx = 12;
/// A point's half size (pt 7 at ps 1.2) and the gap between it and its label [pixels].
constexpr double kPointRadiusPx = 6, kGapPx = 3;

double width(const std::string& text) {
  return (static_cast<double>(text.size()) * kCharWidthPx + 2) / kAreaWidthPx;
}
constexpr double kHeight = kLabelHeightPx / kAreaHeightPx;

PlotBox around(double x, double y, double radiusPx) {
  return {x - radiusPx / kAreaWidthPx, y - radiusPx / kAreaHeightPx, x + radiusPx / kAreaWidthPx,
          y + radiusPx / kAreaHeightPx};
}

/// The area of `box` outside the plot area.
double outside(const PlotBox& box) {
  const PlotBox inside{std::max(box.left, 0.0), std::max(box.bottom, 0.0), std::min(box.right, 1.0),
                       std::min(box.top, 1.0)};
  return (box.right - box.left) * (box.top - box.bottom) - overlapArea(box, inside);
}

/// The places tried for a label of the point at (x, y), in order (placeLabels).
std::vector<PlotLabel> candidates(const LabelledPoint& p) {
  const double gx = (kPointRadiusPx + kGapPx) / kAreaWidthPx,
               gy = (kPointRadiusPx + kGapPx) / kAreaHeightPx, up = gy + kHeight / 2;
  const struct {
    double dx, dy;
    const char* justify;
  } places[] = {{0, up, "center"},
                {0, -up, "center"},
                {gx, 0, "left"},
                {-gx, 0, "right"},
                {gx * 0.7, gy * 0.7 + kHeight / 2, "left"},
                {-gx * 0.7, gy * 0.7 + kHeight / 2, "right"},
                {gx * 0.7, -gy * 0.7 - kHeight / 2, "left"},
                {-gx * 0.7, -gy * 0.7 - kHeight / 2, "right"},
                {0, up + kHeight, "center"},
                {0, -up - kHeight, "center"},
                {0, up + 2 * kHeight, "center"},
                {0, -up - 2 * kHeight, "center"}};
  std::vector<PlotLabel> labels;
  for (const auto& place : places) {
    double x = p.x + place.dx;
    const double y = p.y + place.dy;
    PlotBox box = labelBox(p.text, x, y, place.justify);
    // Above or below a point by the plot's side: slid along until it is inside (by 10⁻⁶).
    if (place.dx == 0) {
      const double slide = box.left < 0 ? 1e-6 - box.left : std::min(0.0, 1 - 1e-6 - box.right);
      x += slide, box.left += slide, box.right += slide;
    }
    labels.push_back({p.text, x, y, place.justify, box, labels.size() >= 8});
  }
  return labels;
}

/// The points, and points every 4 pixels along each line's segments, as small boxes.
std::vector<PlotBox> pointAndLineBoxes(const std::vector<LabelledPoint>& points,
                                       const std::vector<std::vector<LabelledPoint>>& lines) {
  std::vector<PlotBox> boxes;
  for (const LabelledPoint& p : points) boxes.push_back(around(p.x, p.y, kPointRadiusPx));
  for (const auto& line : lines)
    for (size_t i = 1; i < line.size(); ++i) {
      const double dx = line[i].x - line[i - 1].x, dy = line[i].y - line[i - 1].y;
      const double px = std::hypot(dx * kAreaWidthPx, dy * kAreaHeightPx);
      const int samples = static_cast<int>(px / 4);
      for (int s = 1; s < samples; ++s) {
        const double t = static_cast<double>(s) / samples;
        boxes.push_back(around(line[i - 1].x + t * dx, line[i - 1].y + t * dy, 1.5));
      }
    }
  return boxes;
}

}  // namespace

double LogRange::fraction(double value) const {
  return std::log(value / low) / std::log(high / low);
}

LogRange logRangeOver(const std::vector<double>& values, double lowMargin, double highMargin) {
  double low = std::numeric_limits<double>::infinity(), high = 0;
  for (const double v : values)
    if (v > 0 && std::isfinite(v)) low = std::min(low, v), high = std::max(high, v);
  if (high == 0) return {};
  // At least half a decade of data span, about its middle.
  const double minimum = std::log10(std::sqrt(10.0));
  double lo = std::log10(low), hi = std::log10(high);
  if (hi - lo < minimum) {
    const double middle = (lo + hi) / 2;
    lo = middle - minimum / 2, hi = middle + minimum / 2;
  }
  const double total = (hi - lo) / (1 - lowMargin - highMargin);
  return {std::pow(10.0, lo - lowMargin * total), std::pow(10.0, hi + highMargin * total)};
}

std::vector<double> logTics(const LogRange& range) {
  const double decades = std::log10(range.high / range.low);
  const std::vector<double> mantissas = decades > 4     ? std::vector<double>{1}
                                        : decades > 1.2 ? std::vector<double>{1, 2, 5}
                                                        : std::vector<double>{1, 1.5, 2, 3, 5, 7};
  std::vector<double> tics;
  for (int k = static_cast<int>(std::floor(std::log10(range.low)));
       k <= static_cast<int>(std::ceil(std::log10(range.high))); ++k)
    for (const double m : mantissas) {
      const double v = m * std::pow(10.0, k);
      if (v >= range.low && v <= range.high) tics.push_back(v);
    }
  return tics;
}

double overlapArea(const PlotBox& a, const PlotBox& b) {
  const double w = std::min(a.right, b.right) - std::max(a.left, b.left);
  const double h = std::min(a.top, b.top) - std::max(a.bottom, b.bottom);
  return w > 0 && h > 0 ? w * h : 0;
}

PlotBox labelBox(const std::string& text, double x, double y, const char* justify) {
  const double w = width(text);
  const double left = std::strcmp(justify, "left") == 0    ? x
                      : std::strcmp(justify, "right") == 0 ? x - w
                                                           : x - w / 2;
  return {left, y - kHeight / 2, left + w, y + kHeight / 2};
}

std::vector<PlotLabel> placeLabels(const std::vector<LabelledPoint>& points,
                                   const std::vector<std::vector<LabelledPoint>>& lines,
                                   const std::vector<PlotBox>& taken) {
  std::vector<PlotBox> obstacles = pointAndLineBoxes(points, lines);
  obstacles.insert(obstacles.end(), taken.begin(), taken.end());
  std::vector<PlotLabel> labels;
  for (const LabelledPoint& point : points) {
    double least = std::numeric_limits<double>::infinity();
    PlotLabel best;
    for (const PlotLabel& place : candidates(point)) {
      // Outside the plot counts ten times: a label may cover a line sooner than leave it.
      double overlap = 10 * outside(place.box);
      for (const PlotBox& box : obstacles) overlap += overlapArea(place.box, box);
      if (overlap < least) least = overlap, best = place;
      if (overlap == 0) break;
    }
    labels.push_back(best);
    obstacles.push_back(best.box);
  }
  return labels;
}

}  // namespace fibremss
