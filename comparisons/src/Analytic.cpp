#include "fibremss/Analytic.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "fibremss/Measures.h"

namespace fibremss {
namespace {

constexpr double kBand = 1e-3;  // half-width of a section along the axis [m]
constexpr double kDegrees = 180.0 / M_PI;
/// Contact tolerance as a share of the plate's approach δ: on Hertz's exact surface the gap
/// outside the patch opens as (r − a)^(3/2) and reaches δ/300 at r = 1.02 a, so the measure
/// reads the exact answer within +2 %.
constexpr double kContactTolerance = 1.0 / 300;

/// Lateral stretch s of a compressible Neo-Hookean solid (C10 (Ī1 − 3) + (J − 1)² / D1)
/// stretched by `a` along one axis with free sides: the root of σ_lateral / μ =
/// (s² − a²) / (3 J^(5/3)) + (K/μ)(J − 1), J = a s², K/μ = 2(1 + ν) / (3(1 − 2ν)).
double lateralStretch(double a, double nu) {
  const double bulkOverShear = 2 * (1 + nu) / (3 * (1 - 2 * nu));
  auto stress = [&](double s) {
    const double j = a * s * s;
    return (s * s - a * a) / (3 * std::pow(j, 5.0 / 3.0)) + bulkOverShear * (j - 1);
  };
  double low = 1e-3, high = 2;  // stress(low) < 0 < stress(high) for any stretch in use
  for (int i = 0; i < 200; ++i) {
    const double middle = 0.5 * (low + high);
    (stress(middle) < 0 ? low : high) = middle;
  }
  return 0.5 * (low + high);
}

/// Share of the rest surface's extent along the axis that lies between the attachments.
double freeShare(const AnalyticCase& analytic, const TriangleMesh& rest) {
  const btVector3 axis = (analytic.axisEnd - analytic.axisStart).normalized();
  double lowest = INFINITY, highest = -INFINITY;
  for (const btVector3& p : rest.vertices) {
    const double along = (p - analytic.axisStart).dot(axis);
    lowest = std::min(lowest, along);
    highest = std::max(highest, along);
  }
  const double extent = highest - lowest;
  return extent > 0 ? std::min(1.0, double(analytic.axisStart.distance(analytic.axisEnd)) / extent)
                    : 1.0;
}

/// Angle in (−180, 180] degrees.
double wrapDegrees(double angle) {
  angle = std::fmod(angle + 180, 360);
  return angle <= 0 ? angle + 180 : angle - 180;
}

/// The exact torsion's turn of a rest point `along` the axis of free length `length` [°]: none
/// before the free length, all of the twist past it.
double exactTurnDeg(const AnalyticCase& analytic, double along, double length) {
  return analytic.twistDeg * std::clamp(along / length, 0.0, 1.0);
}

/// One section of the surface at fraction t of the free length: mean radius at rest and now
/// (from the rest axis), and how far its vertices turned about the axis beyond the exact
/// torsion at each one's own place along the axis (angles unwrapped towards it).
struct Section {
  double restRadius = NAN, radius = NAN, rotationErrorDeg = NAN;
};

Section measureSection(const AnalyticCase& analytic, const TriangleMesh& rest,
                       std::span<const btVector3> deformed, double t) {
  const btVector3 start = analytic.axisStart;
  const double length = start.distance(analytic.axisEnd);
  const btVector3 axis = (analytic.axisEnd - start) / btScalar(length);
  double restRadius = 0, radius = 0, error = 0;
  int count = 0;
  for (size_t i = 0; i < rest.vertices.size() && i < deformed.size(); ++i) {
    const btVector3 p0 = rest.vertices[i] - start;
    const double along = p0.dot(axis);
    if (std::abs(along - t * length) > kBand) continue;
    const btVector3 r0 = p0 - axis * btScalar(along);
    const btVector3 p = deformed[i] - start;
    const btVector3 r = p - axis * p.dot(axis);
    if (r0.length2() <= 0 || r.length2() <= 0) continue;
    const double exact = exactTurnDeg(analytic, along, length);
    const double turned = std::atan2(double(axis.dot(r0.cross(r))), double(r0.dot(r))) * kDegrees;
    error += wrapDegrees(turned - exact);
    restRadius += r0.length();
    radius += r.length();
    ++count;
  }
  if (count == 0) return {};
  return {restRadius / count, radius / count, error / count};
}

/// Surface vertex RMS [mm] to the exact torsion of `rest`: each vertex turned about the axis by
/// the twist at its own rest place along it (none before the free length, all of it past it).
double exactTorsionRmsMm(const AnalyticCase& analytic, const TriangleMesh& rest,
                         std::span<const btVector3> deformed) {
  const btVector3 start = analytic.axisStart;
  const double length = start.distance(analytic.axisEnd);
  const btVector3 axis = (analytic.axisEnd - start) / btScalar(length);
  std::vector<btVector3> exact(rest.vertices.size());
  for (size_t i = 0; i < exact.size(); ++i) {
    const btVector3 p0 = rest.vertices[i] - start;
    const double turn = exactTurnDeg(analytic, double(p0.dot(axis)), length);
    exact[i] = start + quatRotate(btQuaternion(axis, btScalar(turn / kDegrees)), p0);
  }
  return rmsDistanceMm(deformed, exact);
}

}  // namespace

AnalyticMetrics exactAnalytic(const AnalyticCase& analytic, const TriangleMesh& rest) {
  AnalyticMetrics exact;
  if (analytic.type == "none") return exact;
  exact.type = analytic.type;
  if (analytic.type == "sphere-planes") return exact;  // per pose: measureContact
  if (analytic.type == "cylinder-stretch") {
    const double s = lateralStretch(analytic.stretch, analytic.poissonRatio);
    exact.exactMidRadiusRatio = s;
    exact.exactPoissonRatio = -std::log(s) / std::log(analytic.stretch);
    exact.exactVolumeChangePct = 100 * (analytic.stretch * s * s - 1) * freeShare(analytic, rest);
  } else {
    exact.exactMidRadiusRatio = 1;
    exact.exactVolumeChangePct = 0;
    exact.exactMidRotationDeg = analytic.twistDeg / 2;
  }
  return exact;
}

AnalyticMetrics measureAnalytic(const AnalyticCase& analytic, const TriangleMesh& rest,
                                std::span<const btVector3> deformed) {
  AnalyticMetrics metrics = exactAnalytic(analytic, rest);
  if (metrics.type.empty() || deformed.size() != rest.vertices.size()) return metrics;
  metrics.volumeChangePct = volumeChangePercent(rest, deformed);
  if (metrics.type == "sphere-planes") return metrics;
  const Section mid = measureSection(analytic, rest, deformed, 0.5);
  metrics.midRadiusRatio = mid.radius / mid.restRadius;
  if (analytic.type == "cylinder-stretch") {
    metrics.poissonRatio = -std::log(metrics.midRadiusRatio) / std::log(analytic.stretch);
    return metrics;
  }
  metrics.midRotationDeg = analytic.twistDeg / 2 + mid.rotationErrorDeg;
  metrics.exactTorsionRmsMm = exactTorsionRmsMm(analytic, rest, deformed);
  metrics.rotationErrorDeg = 0;
  for (int k = 1; k <= 9; ++k) {
    const Section section = measureSection(analytic, rest, deformed, k / 10.0);
    if (std::isnan(section.rotationErrorDeg)) return metrics.rotationErrorDeg = NAN, metrics;
    metrics.rotationErrorDeg =
        std::max(metrics.rotationErrorDeg, std::abs(section.rotationErrorDeg));
  }
  return metrics;
}

double contactRadius(const TriangleMesh& rest, std::span<const btVector3> deformed,
                     const btVector3& face, const btVector3& normal, double tolerance) {
  std::vector<char> touching(deformed.size());
  for (size_t v = 0; v < deformed.size(); ++v)
    touching[v] = (deformed[v] - face).dot(normal) >= -tolerance;
  double area = 0;  // each touching vertex's third of its triangles, projected on the plate
  for (const auto& t : rest.triangles) {
    if (t[0] >= deformed.size() || t[1] >= deformed.size() || t[2] >= deformed.size()) continue;
    const int count = touching[t[0]] + touching[t[1]] + touching[t[2]];
    if (count == 0) continue;
    const btVector3 cross =
        (deformed[t[1]] - deformed[t[0]]).cross(deformed[t[2]] - deformed[t[0]]);
    area += count / 3.0 * std::abs(double(cross.dot(normal))) / 2;
  }
  return std::sqrt(area / M_PI);
}

ContactPose measureContact(const LoadedScene& scene, const TriangleMesh& rest,
                           std::span<const btVector3> deformed, int pose) {
  const AnalyticCase& analytic = scene.analytic;
  ContactPose contact;
  contact.pose = pose;
  if (analytic.type != "sphere-planes" || analytic.plateBone < 0) return contact;
  const btTransform plate = scene.bonePose(static_cast<size_t>(analytic.plateBone), pose);
  const btVector3 out = (analytic.axisEnd - analytic.axisStart).normalized();
  const btVector3 face = plate * analytic.axisEnd;
  const double approach = std::max(0.0, double((analytic.axisEnd - face).dot(out)));
  const double radius = analytic.axisStart.distance(analytic.axisEnd);
  contact.approachMm = 1000 * approach;
  contact.exactRadiusMm = 1000 * std::sqrt(radius * approach);
  contact.radiusMm = 1000 * contactRadius(rest, deformed, face, plate.getBasis() * out,
                                          kContactTolerance * approach);
  return contact;
}

AnalyticMetrics measureAnalyticPoses(const LoadedScene& scene, const TriangleMesh& rest,
                                     const std::vector<std::vector<btVector3>>& poseSurfaces) {
  if (poseSurfaces.empty()) return exactAnalytic(scene.analytic, rest);
  auto firstMuscle = [&](const std::vector<btVector3>& surface) {
    return std::span<const btVector3>(surface).first(
        std::min(rest.vertices.size(), surface.size()));
  };
  AnalyticMetrics metrics = measureAnalytic(scene.analytic, rest, firstMuscle(poseSurfaces.back()));
  if (metrics.type != "sphere-planes") return metrics;
  for (size_t p = 0; p < poseSurfaces.size(); ++p)
    metrics.contact.push_back(
        measureContact(scene, rest, firstMuscle(poseSurfaces[p]), static_cast<int>(p)));
  return metrics;
}

std::string analyticLine(const AnalyticMetrics& m) {
  if (m.type.empty()) return "";
  char line[320];
  if (m.type == "sphere-planes") {
    std::string text = m.type + ": contact radius [mm] (Hertz √(Rδ))";
    for (const ContactPose& c : m.contact) {
      std::snprintf(line, sizeof line, "%s δ %.3g mm: %.3g (%.3g)", c.pose ? "," : "", c.approachMm,
                    c.radiusMm, c.exactRadiusMm);
      text += line;
    }
    std::snprintf(line, sizeof line, "; volume %+.3g %%", m.volumeChangePct);
    return text + line;
  }
  if (m.type == "cylinder-stretch") {
    std::snprintf(line, sizeof line,
                  "%s: effective Poisson ratio %.3g (exact %.3g), volume %+.3g %% (exact %+.3g "
                  "%%), mid radius %.4g r0 (exact %.4g)",
                  m.type.c_str(), m.poissonRatio, m.exactPoissonRatio, m.volumeChangePct,
                  m.exactVolumeChangePct, m.midRadiusRatio, m.exactMidRadiusRatio);
  } else {
    std::snprintf(line, sizeof line,
                  "%s: mid-section turned %.4g deg (exact %.4g), worst of 9 sections %.3g deg off "
                  "the linear profile (exact 0), mid radius %.4g r0 (exact %.4g), volume %+.3g %% "
                  "(exact %+.3g %%), surface %.3g mm RMS from the exact torsion",
                  m.type.c_str(), m.midRotationDeg, m.exactMidRotationDeg, m.rotationErrorDeg,
                  m.midRadiusRatio, m.exactMidRadiusRatio, m.volumeChangePct,
                  m.exactVolumeChangePct, m.exactTorsionRmsMm);
  }
  return line;
}

namespace {

/// The value in `format`, "—" when it is not a finite number.
std::string formatted(double value, const char* format) {
  if (!std::isfinite(value)) return "—";
  char text[32];
  std::snprintf(text, sizeof text, format, value);
  return text;
}

/// object[key] if it is a number, else NaN.
double numberAt(const nlohmann::json& object, const char* key) {
  auto it = object.find(key);
  return it == object.end() || !it->is_number() ? NAN : it->get<double>();
}

std::string cell(const nlohmann::json& object, const char* key, const char* format) {
  return formatted(numberAt(object, key), format);
}

/// A row of the analytic table; `prefix` "" for the measured fields, "exact_" for the answer.
std::string analyticRow(const std::string& name, const nlohmann::json& a,
                        const std::string& prefix) {
  auto field = [&](const char* key, const char* format) {
    return cell(a, (prefix + key).c_str(), format);
  };
  return "| " + name + " | " + field("poisson_ratio", "%.3f") + " | " +
         field("volume_change_pct", "%+.2f") + " | " + field("mid_radius_ratio", "%.4f") + " | " +
         field("mid_rotation_deg", "%.2f") + " | " +
         (prefix.empty() ? cell(a, "rotation_error_deg", "%.2f") + " | " +
                               cell(a, "exact_torsion_rms_mm", "%.3f")
                         : std::string("0 | 0")) +
         " |\n";
}

/// sphere-planes: a row per pose of one run (approach, contact radius, Hertz's, their ratio).
std::string contactRows(const std::string& name, const nlohmann::json& a) {
  std::string rows;
  auto contact = a.find("contact");
  if (contact == a.end() || !contact->is_array()) return rows;
  for (const auto& c : *contact) {
    rows += "| " + name + " | " + std::to_string(c.value("pose", 0)) + " | " +
            cell(c, "approach_mm", "%.3f") + " | " + cell(c, "radius_mm", "%.2f") + " | " +
            cell(c, "exact_radius_mm", "%.2f") + " | " +
            formatted(numberAt(c, "radius_mm") / numberAt(c, "exact_radius_mm"), "%.3f") + " |\n";
  }
  return rows;
}

std::string contactReport(const nlohmann::json& runs) {
  std::string rows;
  for (const auto& run : runs) {
    auto a = run.find("analytic");
    if (a != run.end() && a->is_object())
      rows += contactRows(run.value("method", std::string("?")), *a);
  }
  return "\n## Analytic case: sphere-planes\n\nA sphere of radius R between two rigid plates "
         "that close in on it by δ each (frictionless). Exact (small strain, δ ≪ R): by symmetry "
         "the centre stays, and each plate is a Hertz contact of the sphere with a rigid flat, "
         "a = √(Rδ) (Johnson, Contact Mechanics, 1985, §4.2: a³ = 3PR/4E*, δ = a²/R, with δ the "
         "approach of the plate to the sphere's centre; "
         "finite-sphere correction: comparisons/README.md). Measured on the muscle's surface at "
         "each pose: the vertices "
         "within δ/300 of the upper plate's face or beyond it, each with a third of the area of "
         "its triangles projected on the plate, a = √(A/π) (on Hertz's exact surface it reads "
         "within +2 %).\n\n| method | pose | δ [mm] | contact radius [mm] | Hertz √(Rδ) [mm] | "
         "ratio |\n|---|---|---|---|---|---|\n" +
         rows;
}

}  // namespace

std::string analyticReport(const nlohmann::json& runs) {
  std::string rows;
  const nlohmann::json* exact = nullptr;
  for (const auto& run : runs) {
    auto a = run.find("analytic");
    if (a == run.end() || !a->is_object()) continue;
    rows += analyticRow(run.value("method", std::string("?")), *a, "");
    exact = &*a;
  }
  if (!exact) return "";
  const std::string type = exact->value("type", std::string("?"));
  if (type == "sphere-planes") return contactReport(runs);
  const bool stretch = type == "cylinder-stretch";
  return "\n## Analytic case: " + type + "\n\n" +
         (stretch ? "A straight cylinder stretched along its axis by its attachments; exact: the "
                    "homogeneous uniaxial stretch of a compressible Neo-Hookean solid (CalculiX's "
                    "NEO HOOKE) with free sides at the scene's Poisson ratio, its volume change "
                    "scaled by the free length's share of the muscle."
                  : "A straight cylinder, one end twisted about the axis; exact torsion: every "
                    "section turns rigidly, linearly along the free length, keeping its radius "
                    "and the volume.") +
         " Measured at the last pose on the muscle's surface: the mid-section's mean radius "
         "about the rest axis (effective ν = −ln(r/r0) / ln(stretch)), the volume of the closed "
         "surface, the mean angle the vertices of a section turned about the axis, and the "
         "largest deviation of 9 sections (10 % … 90 % of the free length) from the exact "
         "rotation; a twist also the surface's vertex RMS to the exact torsion of the rest "
         "surface (each vertex turned by the twist at its rest place along the axis).\n\n| "
         "method | effective ν | volume [%] | mid radius / r0 | mid rotation [°] | worst section "
         "off [°] | RMS to exact torsion [mm] |\n|---|---|---|---|---|---|---|\n" +
         rows + analyticRow("**exact**", *exact, "exact_");
}

}  // namespace fibremss
