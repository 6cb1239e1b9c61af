#pragma once
// How the viewer colours muscles by an array: "muscle_id" by a palette of distinct colours,
// "fibre_stretch" (and any array with "stretch" in its name) by a diverging blue-grey-red
// map with grey at 1 (linear on each side of 1), everything else by a sequential
// dark-blue-to-yellow map.
#include <array>
#include <string>

#include "ViewFrame.h"

namespace fibremss::viewer {

using Rgb = std::array<float, 3>;  ///< red, green, blue in 0..1

/// The values mapped to the ends of a colour map.
struct Range {
  float low = 0;   ///< mapped to the first colour
  float high = 1;  ///< mapped to the last colour
};

/// The range of `array` over every muscle of the frame that holds 98 % of the values (a few
/// outliers, e.g. at tendon ends, would leave the rest one pale colour); for a stretch,
/// symmetric in its logarithm about 1 (from 1/s to s, never below 0); up to the largest value when
/// 98 % of them are equal (e.g. penetration). `extremes` receives the true smallest and largest
/// value.
Range arrayRange(const ViewFrame& frame, const std::string& array, Range& extremes);
/// The colour of `value` of `array` in `range`.
Rgb colourOf(const std::string& array, float value, const Range& range);

}  // namespace fibremss::viewer
