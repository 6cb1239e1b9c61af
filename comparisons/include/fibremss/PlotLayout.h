#pragma once
// Where the speed–error plots put their axes and point labels. gnuplot does not move a label
// off another (pinch's fronts crowd seven labels into one spot), so `compare` sets explicit
// logarithmic ranges and places every label itself, in graph fractions (0 to 1 across the plot
// area), each where it covers no other label, point or line if such a place exists.
#include <string>
#include <vector>

namespace fibremss {

/// A logarithmic axis' range [low, high] (both > 0).
struct LogRange {
  double low = 1, high = 10;
  /// Where `value` lies on the axis: 0 at low, 1 at high.
  double fraction(double value) const;
};

/// The range over `values` (those > 0 and finite; [1, 10] if none) in which they span the
/// fractions [lowMargin, 1 − highMargin] of the axis; at least half a decade of data span.
LogRange logRangeOver(const std::vector<double>& values, double lowMargin, double highMargin);

/// Tic values m × 10^k inside the range: m = 1, 2, 5; over 4 decades 1 alone; within 1.2
/// decades 1, 1.5, 2, 3, 5, 7 (so that a narrow range still has several).
std::vector<double> logTics(const LogRange& range);

/// A rectangle in graph fractions.
struct PlotBox {
  double left = 0, bottom = 0, right = 0, top = 0;
};

/// A box's overlap area with another [graph fraction²].
double overlapArea(const PlotBox& a, const PlotBox& b);

/// A marked point of a front: where it is [graph fractions] and its label's text.
struct LabelledPoint {
  double x = 0, y = 0;
  std::string text;
};

/// A label as gnuplot draws it: text anchored at (x, y) [graph fractions], justified "left",
/// "center" or "right", vertically centred on y; `box` is the area it covers.
struct PlotLabel {
  std::string text;
  double x = 0, y = 0;
  const char* justify = "center";
  PlotBox box;
  bool leader = false;  ///< a row or more away from its point: draw a line to it
};

/// The box a label of `text` covers when anchored at (x, y) with `justify` (the plot's 1000×650
/// canvas, labels in 8-point DejaVu Sans: the estimates in PlotLayout.cpp).
PlotBox labelBox(const std::string& text, double x, double y, const char* justify);

/// Each point's label, placed in turn at the first of these places that overlaps nothing
/// placed before it, no point, no line and stays inside the plot: above, below, right, left,
/// the four diagonals, then one and two label heights farther above and below (one above or
/// below a point by the plot's side slid along until it is inside). Where every place
/// overlaps something, the one that overlaps least. `lines` are the fronts (points
/// joined in order, graph fractions); `taken` the boxes of labels already set (titles, notes).
std::vector<PlotLabel> placeLabels(const std::vector<LabelledPoint>& points,
                                   const std::vector<std::vector<LabelledPoint>>& lines,
                                   const std::vector<PlotBox>& taken);

}  // namespace fibremss
