#pragma once
// Widgets the panel's parts share: rows that wrap to the panel's width instead of running past
// its edge.
#include <array>

#include "Source.h"

namespace fibremss::viewer {

/// Puts the next widget, `width` wide [px], on the current line when it fits, else below.
void sameLineIfFits(float width);
/// A checkbox's width with `label` [px].
float checkboxWidth(const char* label);
/// Play/Pause, Step and Reset for `source` and a loop checkbox, on as many lines as the panel
/// needs; returns whether the checkbox changed `loop`.
bool playbackButtons(Source& source, bool& loop);
/// The time of each part of a step [ms] (mass-spring, muscle and bone collision detection,
/// response, output) under `heading`, one a line: a number is never split at its point.
void partTimes(const char* heading, const std::array<double, 5>& ms);

}  // namespace fibremss::viewer
