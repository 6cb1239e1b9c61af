#pragma once
// The analytic tier: an exact case's answer and what a run's surface says about it (a straight
// cylinder stretched or twisted between its attachments, fibremss::AnalyticCase).
#include <nlohmann/json.hpp>
#include <span>
#include <string>

#include "fibremss/Geometry.h"
#include "fibremss/RunMetrics.h"
#include "fibremss/Scene.h"

namespace fibremss {

/// The exact answers of a case (its "exact" fields; the measured ones NaN). Stretch: the
/// homogeneous uniaxial stretch of a compressible Neo-Hookean solid with free sides, strain
/// energy C10 (Ī1 − 3) + (J − 1)² / D1 (CalculiX's NEO HOOKE) at the case's ν, the volume
/// change scaled by the free length's share of the muscle. Twist: exact torsion keeps the
/// radius and the volume, sections turn linearly along the free length.
AnalyticMetrics exactAnalytic(const AnalyticCase& analytic, const TriangleMesh& rest);

/// The case measured on one muscle's surface (`deformed`: its vertices, in the order of `rest`)
/// beside the exact answers. Sections are the rest vertices within 1 mm of a station on the
/// axis; their radius is the mean distance from the rest axis, their rotation error the mean
/// angle each vertex turned about it beyond the exact torsion at its own rest place along the
/// axis (the mid-section's rotation is the exact one plus that error). Empty type when the
/// case is "none".
AnalyticMetrics measureAnalytic(const AnalyticCase& analytic, const TriangleMesh& rest,
                                std::span<const btVector3> deformed);

/// One line for the terminal: each measured figure with the exact one in parentheses ("" when
/// the metrics have no case).
std::string analyticLine(const AnalyticMetrics& metrics);

/// A markdown section for report.md: one row per run that measured an analytic case, and the
/// exact answer's row; empty when no run did.
std::string analyticReport(const nlohmann::json& runs);

}  // namespace fibremss
