#pragma once
// The analytic tier: an exact case's answer and what a run's surface says about it (a straight
// cylinder stretched or twisted between its attachments, a sphere squeezed between two plates;
// fibremss::AnalyticCase).
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

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
/// axis (the mid-section's rotation is the exact one plus that error); a twist also the vertex
/// RMS to the exact torsion of `rest`. Empty type when the case is "none".
AnalyticMetrics measureAnalytic(const AnalyticCase& analytic, const TriangleMesh& rest,
                                std::span<const btVector3> deformed);

/// The radius [m] of the patch where `deformed` (vertices in the order of `rest`) lies on a
/// plate whose face passes through `face` with unit normal `normal` (out of the body, into the
/// plate): the vertices within `tolerance` [m] of the face or beyond it, each counted with a
/// third of the area of its triangles projected on the plate (a nodal area: unbiased to first
/// order in the edge length, where the farthest touching vertex lags the edge by up to an edge
/// and whole-triangle areas by half of one); a = √(A/π).
double contactRadius(const TriangleMesh& rest, std::span<const btVector3> deformed,
                     const btVector3& face, const btVector3& normal, double tolerance);

/// sphere-planes at `pose`: the plate's approach δ towards the centre (from where its face
/// touches the rest sphere), the contact radius on it (tolerance δ/300: on Hertz's exact
/// surface the gap outside the patch reaches it at 1.02 a) and Hertz's √(Rδ). NaN figures for
/// any other case.
ContactPose measureContact(const LoadedScene& scene, const TriangleMesh& rest,
                           std::span<const btVector3> deformed, int pose);

/// The scene's case on the first muscle of per-pose surfaces (each all muscles' vertices, the
/// first muscle's first): measureAnalytic at the last pose and, for sphere-planes,
/// measureContact at every pose. No surfaces: the exact answers only.
AnalyticMetrics measureAnalyticPoses(const LoadedScene& scene, const TriangleMesh& rest,
                                     const std::vector<std::vector<btVector3>>& poseSurfaces);

/// One line for the terminal: each measured figure with the exact one in parentheses ("" when
/// the metrics have no case).
std::string analyticLine(const AnalyticMetrics& metrics);

/// A markdown section for report.md: one row per run that measured an analytic case, and the
/// exact answer's row; empty when no run did.
std::string analyticReport(const nlohmann::json& runs);

}  // namespace fibremss
