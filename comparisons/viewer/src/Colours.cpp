#include "Colours.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <span>
#include <vector>

namespace fibremss::viewer {
namespace {

/// Distinct colours for muscles, none of them grey or ivory (the bones' colour).
constexpr std::array<Rgb, 8> kPalette{{{0.85f, 0.25f, 0.22f},
                                       {0.20f, 0.55f, 0.85f},
                                       {0.30f, 0.72f, 0.30f},
                                       {0.90f, 0.55f, 0.10f},
                                       {0.60f, 0.35f, 0.80f},
                                       {0.10f, 0.70f, 0.70f},
                                       {0.85f, 0.35f, 0.60f},
                                       {0.55f, 0.60f, 0.15f}}};
/// Blue, grey, red: values below 1 (shortened), at 1, above 1 (stretched).
constexpr std::array<Rgb, 3> kDiverging{
    {{0.23f, 0.30f, 0.75f}, {0.86f, 0.86f, 0.86f}, {0.71f, 0.02f, 0.15f}}};
/// Dark blue through teal to yellow: small to large.
constexpr std::array<Rgb, 3> kSequential{
    {{0.27f, 0.00f, 0.33f}, {0.13f, 0.57f, 0.55f}, {0.99f, 0.91f, 0.14f}}};

bool isStretch(const std::string& array) {
  return array.find("stretch") != std::string::npos;
}

/// Piecewise-linear interpolation between equally spaced colours, t in 0..1.
Rgb interpolate(std::span<const Rgb> colours, float t) {
  const float position = std::clamp(t, 0.0f, 1.0f) * float(colours.size() - 1);
  const size_t i = std::min(static_cast<size_t>(position), colours.size() - 2);
  const float f = position - float(i);
  Rgb c;
  for (int k = 0; k < 3; ++k) c[k] = colours[i][k] + f * (colours[i + 1][k] - colours[i][k]);
  return c;
}

/// The range of stretches `values` symmetric in their logarithm about 1, holding 98 % of them:
/// a stretch of 16 and a shortening to 1/16 are as far from grey, and the low end stays above 0.
Range logSymmetricRange(std::vector<float>& values) {
  for (float& v : values) v = v > 0 ? std::abs(std::log(v)) : std::numeric_limits<float>::max();
  auto percentile = values.begin() + static_cast<long>(0.98 * double(values.size() - 1));
  std::nth_element(values.begin(), percentile, values.end());
  const float half = std::clamp(*percentile, 1e-3f, 20.0f);
  return {std::exp(-half), std::exp(half)};
}

/// Where `value` lies on the diverging map over `range`: 0.5 (grey) at 1, the range's ends at 0
/// and 1, linear on each side of 1 (so also for a range not symmetric about 1).
float divergingPosition(float value, const Range& range) {
  if (range.low < 1 && value < 1) return 0.5f * (value - range.low) / (1 - range.low);
  if (range.high > 1 && value >= 1) return 0.5f + 0.5f * (value - 1) / (range.high - 1);
  return (value - range.low) / (range.high - range.low);
}

}  // namespace

Range arrayRange(const ViewFrame& frame, const std::string& array, Range& extremes) {
  std::vector<float> values;
  for (const ViewMesh& mesh : frame.muscles)
    if (const std::vector<float>* meshValues = mesh.array(array))
      std::copy_if(meshValues->begin(), meshValues->end(), std::back_inserter(values),
                   [](float v) { return std::isfinite(v); });
  if (values.empty()) return extremes = {};
  const auto [low, high] = std::minmax_element(values.begin(), values.end());
  extremes = {*low, *high};
  if (isStretch(array)) return logSymmetricRange(values);
  const auto at = [&values](double fraction) {
    auto it = values.begin() + static_cast<long>(fraction * double(values.size() - 1));
    std::nth_element(values.begin(), it, values.end());
    return *it;
  };
  const float bottom = at(0.01), top = at(0.99);
  // A sparse array (penetration: 0 nearly everywhere) keeps its few values in view.
  return {bottom, std::max(top > bottom ? top : extremes.high, bottom + 1e-6f)};
}

Rgb colourOf(const std::string& array, float value, const Range& range) {
  if (array == "muscle_id") {
    const long index = std::lround(std::max(value, 0.0f));
    return kPalette[static_cast<size_t>(index) % kPalette.size()];
  }
  if (isStretch(array)) return interpolate(kDiverging, divergingPosition(value, range));
  return interpolate(kSequential, (value - range.low) / (range.high - range.low));
}

}  // namespace fibremss::viewer
