#include "fibremss/MuscleMetrics.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "fibremss/Measures.h"

namespace fibremss {
namespace {

bool allFinite(std::span<const btVector3> points) {
  return std::all_of(points.begin(), points.end(), [](const btVector3& p) {
    return std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z());
  });
}

nlohmann::json number(double value) {
  return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
}

double numberAt(const nlohmann::json& object, const char* key, double fallback) {
  auto it = object.find(key);
  return it != object.end() && it->is_number() ? it->get<double>() : fallback;
}

/// "pelvis 0.31, femur 0.82" from per-bone values (bones whose value is `skip` left out).
template <typename Value>
std::string perBone(const std::vector<std::string>& bones, const std::vector<Value>& values,
                    const char* format, Value skip) {
  std::string text;
  char number[32];
  for (size_t b = 0; b < bones.size() && b < values.size(); ++b) {
    if (values[b] == skip) continue;
    std::snprintf(number, sizeof number, format, values[b]);
    text += (text.empty() ? "" : ", ") + bones[b] + " " + number;
  }
  return text.empty() ? "none" : text;
}

/// Σ current and Σ rest length of one region's fibre segments [m].
struct RegionLength {
  double current = 0;  ///< Σ l [m]
  double rest = 0;     ///< Σ L0 [m]

  /// Σl / ΣL0 − 1, NaN for a region without segments.
  double strain() const { return rest > 0 ? current / rest - 1 : MuscleStep::kNone; }
};

/// Largest current / rest length of the muscle's fibre segments in its belly and in its tendons,
/// and each region's strain (NaN where it has none).
void fibreStretch(const MuscleSettings& muscle, std::span<const btVector3> positions,
                  MuscleStep& step) {
  const auto inTendon = [&](uint32_t p) { return muscle.flags[p] & (kTendon | kFixed); };
  RegionLength belly, tendon;
  for (size_t f = 0; f < muscle.fibreCount(); ++f)
    for (uint32_t k = muscle.fibreOffsets[f] + 1; k < muscle.fibreOffsets[f + 1]; ++k) {
      const uint32_t a = muscle.fibreParticles[k - 1], b = muscle.fibreParticles[k];
      const double rest = muscle.restPositions[a].distance(muscle.restPositions[b]);
      const double length = positions[a].distance(positions[b]);
      const double ratio = rest > 0 ? length / rest : 1.0;
      const bool isTendon = inTendon(a) && inTendon(b) && !(muscle.isFixed(a) && muscle.isFixed(b));
      double& stretch = isTendon ? step.maxTendonStretch : step.maxBellyStretch;
      if (!(ratio <= stretch)) stretch = ratio;
      RegionLength& region = isTendon ? tendon : belly;
      region.current += length;
      region.rest += rest;
    }
  step.maxFibreStretch = std::isnan(step.maxTendonStretch)
                             ? step.maxBellyStretch
                             : std::max(step.maxBellyStretch, step.maxTendonStretch);
  step.bellyStrain = belly.strain();
  step.tendonStrain = tendon.strain();
}

/// "1.25", or "–" for NaN (not measured, or nothing to measure).
std::string twoDecimals(double value) {
  if (std::isnan(value)) return "–";
  char text[32];
  std::snprintf(text, sizeof text, "%.2f", value);
  return text;
}

/// The larger of two values where NaN means none.
double largest(double a, double b) {
  return !(b <= a) ? b : a;
}

/// A CSV field: the number, or empty when not finite.
std::string csvNumber(double value, const char* format) {
  if (!std::isfinite(value)) return "";
  char text[32];
  std::snprintf(text, sizeof text, format, value);
  return text;
}

/// A CSV field for text: quoted (quotes doubled) when it holds a comma, quote or line break.
std::string csvText(const std::string& text) {
  if (text.find_first_of(",\"\n\r") == std::string::npos) return text;
  std::string quoted = "\"";
  for (char c : text) quoted += c == '"' ? std::string("\"\"") : std::string(1, c);
  return quoted + "\"";
}

/// A count tearing measured, or empty (−1: the muscle does not tear).
std::string tearField(long count) {
  return count >= 0 ? std::to_string(count) : "";
}

/// The largest of `depths` (NaN when empty).
double deepest(const std::vector<double>& depths) {
  double result = MuscleStep::kNone;
  for (double depth : depths)
    if (!(depth <= result)) result = depth;
  return result;
}

}  // namespace

double MuscleStep::maxPenetrationMm() const {
  return deepest(penetrationMm);
}

double MuscleStep::maxSphereDepthMm() const {
  return deepest(sphereDepthMm);
}

std::string seriesCsv(const std::vector<SeriesRow>& rows) {
  std::string csv =
      "step,pose,pose_label,time_s,muscle,volume_change_pct,mean_fibre_length_mm,"
      "max_fibre_stretch,max_penetration_mm,bone_contacts,solver_contacts,residual_rms_mm,"
      "residual_max_mm,max_belly_stretch,max_tendon_stretch,max_sphere_depth_mm,belly_strain,"
      "tendon_strain";
  const bool tears = std::any_of(rows.begin(), rows.end(),
                                 [](const SeriesRow& row) { return row.measures.tears(); });
  const bool cuts = std::any_of(rows.begin(), rows.end(),
                                [](const SeriesRow& row) { return row.measures.cutSprings >= 0; });
  csv += std::string(tears ? ",broken_springs,pieces" : "") + (cuts ? ",cut_springs\n" : "\n");
  for (const SeriesRow& row : rows) {
    const MuscleStep& m = row.measures;
    csv += std::to_string(row.step) + "," + std::to_string(row.pose) + "," +
           csvNumber(row.poseLabel, "%.10g") + "," + csvNumber(row.timeS, "%.10g") + "," +
           csvText(row.muscle) + "," + csvNumber(m.volumeChangePct, "%.6g") + "," +
           csvNumber(m.meanFibreLengthMm, "%.6g") + "," + csvNumber(m.maxFibreStretch, "%.6g") +
           "," + csvNumber(m.maxPenetrationMm(), "%.6g") + "," + std::to_string(m.boneContacts) +
           "," + std::to_string(row.solverContacts) + "," + csvNumber(m.residualRmsMm, "%.6g") +
           "," + csvNumber(m.residualMaxMm, "%.6g") + "," + csvNumber(m.maxBellyStretch, "%.6g") +
           "," + csvNumber(m.maxTendonStretch, "%.6g") + "," +
           csvNumber(m.maxSphereDepthMm(), "%.6g") + "," + csvNumber(m.bellyStrain, "%.6g") + "," +
           csvNumber(m.tendonStrain, "%.6g") +
           (tears ? "," + tearField(m.brokenSprings) + "," + tearField(m.pieces) : "") +
           (cuts ? "," + tearField(m.cutSprings) : "") + "\n";
  }
  return csv;
}

nlohmann::json seriesJson(const std::vector<SeriesRow>& rows) {
  nlohmann::json array = nlohmann::json::array();
  for (const SeriesRow& row : rows) {
    const MuscleStep& m = row.measures;
    array.push_back({{"step", row.step},
                     {"pose", row.pose},
                     {"pose_label", number(row.poseLabel)},
                     {"time_s", number(row.timeS)},
                     {"muscle", row.muscle},
                     {"volume_change_pct", number(m.volumeChangePct)},
                     {"mean_fibre_length_mm", number(m.meanFibreLengthMm)},
                     {"max_fibre_stretch", number(m.maxFibreStretch)},
                     {"max_penetration_mm", number(m.maxPenetrationMm())},
                     {"bone_contacts", m.boneContacts},
                     {"solver_contacts", row.solverContacts},
                     {"residual_rms_mm", number(m.residualRmsMm)},
                     {"residual_max_mm", number(m.residualMaxMm)},
                     {"max_belly_stretch", number(m.maxBellyStretch)},
                     {"max_tendon_stretch", number(m.maxTendonStretch)},
                     {"max_sphere_depth_mm", number(m.maxSphereDepthMm())},
                     {"belly_strain", number(m.bellyStrain)},
                     {"tendon_strain", number(m.tendonStrain)}});
    if (m.tears()) {
      array.back()["broken_springs"] = m.brokenSprings;
      array.back()["pieces"] = m.pieces;
    }
    if (m.cutSprings >= 0) array.back()["cut_springs"] = m.cutSprings;
  }
  return array;
}

std::vector<SeriesRow> seriesFromJson(const nlohmann::json& array) {
  std::vector<SeriesRow> rows;
  if (!array.is_array()) return rows;
  for (const nlohmann::json& o : array) {
    SeriesRow row;
    row.step = o.value("step", row.step);
    row.pose = o.value("pose", row.pose);
    row.poseLabel = numberAt(o, "pose_label", row.poseLabel);
    row.timeS = numberAt(o, "time_s", row.timeS);
    row.muscle = o.value("muscle", row.muscle);
    MuscleStep& m = row.measures;
    m.volumeChangePct = numberAt(o, "volume_change_pct", m.volumeChangePct);
    m.meanFibreLengthMm = numberAt(o, "mean_fibre_length_mm", m.meanFibreLengthMm);
    m.maxFibreStretch = numberAt(o, "max_fibre_stretch", m.maxFibreStretch);
    if (const double depth = numberAt(o, "max_penetration_mm", MuscleStep::kNone);
        std::isfinite(depth))
      m.penetrationMm = {depth};
    m.boneContacts = o.value("bone_contacts", m.boneContacts);
    row.solverContacts = o.value("solver_contacts", row.solverContacts);
    m.residualRmsMm = numberAt(o, "residual_rms_mm", m.residualRmsMm);
    m.residualMaxMm = numberAt(o, "residual_max_mm", m.residualMaxMm);
    m.maxBellyStretch = numberAt(o, "max_belly_stretch", m.maxBellyStretch);
    m.maxTendonStretch = numberAt(o, "max_tendon_stretch", m.maxTendonStretch);
    if (const double depth = numberAt(o, "max_sphere_depth_mm", MuscleStep::kNone);
        std::isfinite(depth))
      m.sphereDepthMm = {depth};
    m.bellyStrain = numberAt(o, "belly_strain", m.bellyStrain);
    m.tendonStrain = numberAt(o, "tendon_strain", m.tendonStrain);
    m.brokenSprings = o.value("broken_springs", m.brokenSprings);
    m.pieces = o.value("pieces", m.pieces);
    m.cutSprings = o.value("cut_springs", m.cutSprings);
    rows.push_back(std::move(row));
  }
  return rows;
}

MuscleStep measureMuscle(const MuscleSettings& muscle, std::span<const btVector3> positions,
                         std::span<const btVector3> surface,
                         std::span<const MeshDistance* const> bones,
                         std::span<const btTransform> boneTransforms) {
  MuscleStep step;
  step.finite = allFinite(positions) && allFinite(surface);
  if (!step.finite) return step;
  if (!muscle.restSurface.empty()) {
    step.volumeChangePct = volumeChangePercent(muscle.restSurface, surface);
    for (size_t b = 0; b < bones.size(); ++b)
      step.penetrationMm.push_back(
          measurePenetration(surface, bones.subspan(b, 1), boneTransforms.subspan(b, 1)).maxMm);
  }
  step.meanFibreLengthMm = 1000.0 * meanFibreLength(muscle, positions);
  fibreStretch(muscle, positions, step);
  if (!muscle.springs.empty()) {
    step.worstSpringRatio = worstSpringRatio(muscle.springs, positions);
    step.springDeviationRatio = springDeviationRatio(muscle.springs, positions);
  }
  return step;
}

MuscleResults::MuscleResults(const MuscleSettings& muscle, std::vector<std::string> boneNames)
    : name(muscle.name),
      bones(std::move(boneNames)),
      maxPenetrationMm(bones.size(), 0.0),
      maxSphereDepthMm(bones.size(), 0.0),
      fixedParticles(fixedParticlesPerBone(muscle, bones.size())),
      fibreLengthRestMm(1000.0 * meanFibreLength(muscle, muscle.restPositions)) {}

void MuscleResults::add(int step, const MuscleStep& measures) {
  if (!measures.finite) return;
  const bool first = lastStep < 0;
  lastStep = step;
  volumeChangePct = measures.volumeChangePct;
  if (std::isfinite(measures.volumeChangePct) &&
      !(std::abs(measures.volumeChangePct) <= std::abs(worstVolumeChangePct))) {
    worstVolumeChangePct = measures.volumeChangePct;
    worstVolumeStep = step;
  }
  for (size_t b = 0; b < measures.penetrationMm.size() && b < maxPenetrationMm.size(); ++b)
    maxPenetrationMm[b] = std::max(maxPenetrationMm[b], measures.penetrationMm[b]);
  for (size_t b = 0; b < measures.sphereDepthMm.size() && b < maxSphereDepthMm.size(); ++b)
    maxSphereDepthMm[b] = std::max(maxSphereDepthMm[b], measures.sphereDepthMm[b]);
  fibreLengthLastMm = measures.meanFibreLengthMm;
  fibreLengthMinMm = first ? fibreLengthLastMm : std::min(fibreLengthMinMm, fibreLengthLastMm);
  fibreLengthMaxMm = first ? fibreLengthLastMm : std::max(fibreLengthMaxMm, fibreLengthLastMm);
  worstSpringRatio = largest(worstSpringRatio, measures.worstSpringRatio);
  worstBellyStretch = largest(worstBellyStretch, measures.maxBellyStretch);
  worstTendonStretch = largest(worstTendonStretch, measures.maxTendonStretch);
  worstBellyStrain = largest(worstBellyStrain, measures.bellyStrain);
  worstTendonStrain = largest(worstTendonStrain, measures.tendonStrain);
  springDeviationRatio = measures.springDeviationRatio;
  brokenSprings = measures.brokenSprings;
  pieces = measures.pieces;
  cutSprings = measures.cutSprings;
}

nlohmann::json toJson(const MuscleResults& r) {
  nlohmann::json penetration = nlohmann::json::object(), spheres = nlohmann::json::object(),
                 fixed = nlohmann::json::object();
  for (size_t b = 0; b < r.bones.size(); ++b) {
    if (b < r.maxPenetrationMm.size()) penetration[r.bones[b]] = number(r.maxPenetrationMm[b]);
    if (b < r.maxSphereDepthMm.size()) spheres[r.bones[b]] = number(r.maxSphereDepthMm[b]);
    if (b < r.fixedParticles.size()) fixed[r.bones[b]] = r.fixedParticles[b];
  }
  nlohmann::json json = {
      {"name", r.name},
      {"volume_change_pct",
       {{"last", number(r.volumeChangePct)},
        {"worst", number(r.worstVolumeChangePct)},
        {"worst_step", r.worstVolumeStep}}},
      {"max_penetration_mm", penetration},
      {"max_sphere_depth_mm", spheres},
      {"fixed_particles", fixed},
      {"frozen", r.frozen},
      {"frozen_step", r.frozenStep},
      {"frozen_cause", r.frozenCause},
      {"rollbacks", r.rollbacks},
      {"fibre_length_mm",
       {{"rest", number(r.fibreLengthRestMm)},
        {"last", number(r.fibreLengthLastMm)},
        {"min", number(r.fibreLengthMinMm)},
        {"max", number(r.fibreLengthMaxMm)}}},
      {"worst_spring_ratio", number(r.worstSpringRatio)},
      {"worst_fibre_stretch",
       {{"belly", number(r.worstBellyStretch)}, {"tendon", number(r.worstTendonStretch)}}},
      {"worst_fibre_strain",
       {{"belly", number(r.worstBellyStrain)}, {"tendon", number(r.worstTendonStrain)}}},
      {"spring_deviation_ratio", number(r.springDeviationRatio)},
      {"last_step", r.lastStep}};
  if (r.brokenSprings >= 0) {
    json["broken_springs"] = r.brokenSprings;
    json["pieces"] = r.pieces;
  }
  if (r.cutSprings >= 0) json["cut_springs"] = r.cutSprings;
  return json;
}

MuscleResults muscleResultsFromJson(const nlohmann::json& o) {
  MuscleResults r;
  r.name = o.value("name", r.name);
  if (auto v = o.find("volume_change_pct"); v != o.end() && v->is_object()) {
    r.volumeChangePct = numberAt(*v, "last", r.volumeChangePct);
    r.worstVolumeChangePct = numberAt(*v, "worst", r.worstVolumeChangePct);
    r.worstVolumeStep = v->value("worst_step", r.worstVolumeStep);
  }
  if (auto p = o.find("max_penetration_mm"); p != o.end() && p->is_object())
    for (auto it = p->begin(); it != p->end(); ++it) {
      r.bones.push_back(it.key());
      r.maxPenetrationMm.push_back(it->is_number() ? it->get<double>() : MuscleResults::kNone);
    }
  if (auto s = o.find("max_sphere_depth_mm"); s != o.end() && s->is_object())
    for (const std::string& bone : r.bones)
      r.maxSphereDepthMm.push_back(numberAt(*s, bone.c_str(), 0));
  if (auto f = o.find("fixed_particles"); f != o.end() && f->is_object())
    for (const std::string& bone : r.bones) r.fixedParticles.push_back(f->value(bone, size_t(0)));
  r.frozen = o.value("frozen", r.frozen);
  r.frozenStep = o.value("frozen_step", r.frozenStep);
  r.frozenCause = o.value("frozen_cause", r.frozenCause);
  r.rollbacks = o.value("rollbacks", r.rollbacks);
  if (auto l = o.find("fibre_length_mm"); l != o.end() && l->is_object()) {
    r.fibreLengthRestMm = numberAt(*l, "rest", r.fibreLengthRestMm);
    r.fibreLengthLastMm = numberAt(*l, "last", r.fibreLengthLastMm);
    r.fibreLengthMinMm = numberAt(*l, "min", r.fibreLengthMinMm);
    r.fibreLengthMaxMm = numberAt(*l, "max", r.fibreLengthMaxMm);
  }
  r.worstSpringRatio = numberAt(o, "worst_spring_ratio", r.worstSpringRatio);
  r.springDeviationRatio = numberAt(o, "spring_deviation_ratio", r.springDeviationRatio);
  if (auto s = o.find("worst_fibre_stretch"); s != o.end() && s->is_object()) {
    r.worstBellyStretch = numberAt(*s, "belly", r.worstBellyStretch);
    r.worstTendonStretch = numberAt(*s, "tendon", r.worstTendonStretch);
  }
  if (auto s = o.find("worst_fibre_strain"); s != o.end() && s->is_object()) {
    r.worstBellyStrain = numberAt(*s, "belly", r.worstBellyStrain);
    r.worstTendonStrain = numberAt(*s, "tendon", r.worstTendonStrain);
  }
  r.lastStep = o.value("last_step", r.lastStep);
  r.brokenSprings = o.value("broken_springs", r.brokenSprings);
  r.pieces = o.value("pieces", r.pieces);
  r.cutSprings = o.value("cut_springs", r.cutSprings);
  return r;
}

std::string muscleTable(const std::vector<MuscleResults>& muscles) {
  std::string table =
      "| muscle | volume last % | volume worst % (step) | max penetration mm | max sphere depth mm "
      "| fixed particles | "
      "mean fibre mm rest / last / min / max | worst spring l/L0 | worst fibre stretch belly / "
      "tendon | worst fibre strain % belly / tendon | rollbacks | frozen |";
  const bool tears = std::any_of(muscles.begin(), muscles.end(),
                                 [](const MuscleResults& m) { return m.brokenSprings >= 0; });
  table += tears ? " broken springs | pieces "
                   "|\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
                 : "\n|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  char line[512];
  for (const MuscleResults& m : muscles) {
    const std::string frozen =
        m.frozen ? "at step " + std::to_string(m.frozenStep) + " (" + m.frozenCause + ")" : "no";
    std::snprintf(
        line, sizeof line,
        "| %s | %.2f | %.2f (%d) | %s | %s | %s | %.1f / %.1f / %.1f / %.1f | %.2f | %s / %s | "
        "%s / %s | %d | %s |\n",
        m.name.c_str(), m.volumeChangePct, m.worstVolumeChangePct, m.worstVolumeStep,
        perBone(m.bones, m.maxPenetrationMm, "%.2f", -1.0).c_str(),
        perBone(m.bones, m.maxSphereDepthMm, "%.2f", -1.0).c_str(),
        perBone(m.bones, m.fixedParticles, "%zu", size_t(0)).c_str(), m.fibreLengthRestMm,
        m.fibreLengthLastMm, m.fibreLengthMinMm, m.fibreLengthMaxMm, m.worstSpringRatio,
        twoDecimals(m.worstBellyStretch).c_str(), twoDecimals(m.worstTendonStretch).c_str(),
        twoDecimals(100 * m.worstBellyStrain).c_str(),
        twoDecimals(100 * m.worstTendonStrain).c_str(), m.rollbacks, frozen.c_str());
    table += line;
    if (tears)
      table.insert(table.size() - 1,
                   " " + tearField(m.brokenSprings) + " | " + tearField(m.pieces) + " |");
  }
  return table;
}

const MuscleResults* worstVolumeMuscle(const std::vector<MuscleResults>& muscles) {
  const MuscleResults* worst = nullptr;
  for (const MuscleResults& m : muscles)
    if (std::isfinite(m.volumeChangePct) &&
        (!worst || std::abs(m.volumeChangePct) > std::abs(worst->volumeChangePct)))
      worst = &m;
  return worst;
}

}  // namespace fibremss
