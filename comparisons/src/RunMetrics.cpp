#include "fibremss/RunMetrics.h"

#include <cmath>

namespace fibremss {
namespace {

nlohmann::json number(double value) {
  return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
}

/// The values as a JSON array (NaN: null).
nlohmann::json numbers(const std::vector<double>& values) {
  nlohmann::json array = nlohmann::json::array();
  for (double value : values) array.push_back(number(value));
  return array;
}

/// What `numbers` wrote under `key` (null: NaN), or nothing.
std::vector<double> numbersAt(const nlohmann::json& object, const char* key) {
  std::vector<double> values;
  if (auto it = object.find(key); it != object.end() && it->is_array())
    for (const auto& v : *it) values.push_back(v.is_number() ? v.get<double>() : RunMetrics::kNone);
  return values;
}

double numberOr(const nlohmann::json& object, const char* key, double fallback) {
  auto it = object.find(key);
  if (it == object.end() || !it->is_number()) return fallback;
  return it->get<double>();
}

nlohmann::json toJson(const std::vector<MuscleRms>& muscles) {
  nlohmann::json list = nlohmann::json::array();
  for (const MuscleRms& m : muscles)
    list.push_back(
        {{"muscle", m.muscle}, {"rms_mm", number(m.rmsMm)}, {"per_pose_mm", numbers(m.perPoseMm)}});
  return list;
}

std::vector<MuscleRms> musclesFromJson(const nlohmann::json& object, const char* key) {
  std::vector<MuscleRms> muscles;
  if (auto list = object.find(key); list != object.end() && list->is_array())
    for (const auto& m : *list)
      muscles.push_back({m.value("muscle", std::string()), numberOr(m, "rms_mm", RunMetrics::kNone),
                         numbersAt(m, "per_pose_mm")});
  return muscles;
}

nlohmann::json toJson(const MusclePoseRms& worst) {
  return {{"muscle", worst.muscle}, {"pose", worst.pose}, {"rms_mm", number(worst.rmsMm)}};
}

MusclePoseRms musclePoseRmsFromJson(const nlohmann::json& object) {
  MusclePoseRms worst;
  if (auto o = object.find("worst_muscle_pose_to_equilibrium"); o != object.end() && o->is_object())
    worst = {o->value("muscle", worst.muscle), o->value("pose", worst.pose),
             numberOr(*o, "rms_mm", worst.rmsMm)};
  return worst;
}

nlohmann::json toJson(const AnalyticMetrics& a) {
  if (a.type.empty()) return nullptr;
  nlohmann::json contact = nlohmann::json::array();
  for (const ContactPose& c : a.contact)
    contact.push_back({{"pose", c.pose},
                       {"approach_mm", number(c.approachMm)},
                       {"radius_mm", number(c.radiusMm)},
                       {"exact_radius_mm", number(c.exactRadiusMm)}});
  return {{"type", a.type},
          {"contact", contact},
          {"poisson_ratio", number(a.poissonRatio)},
          {"exact_poisson_ratio", number(a.exactPoissonRatio)},
          {"volume_change_pct", number(a.volumeChangePct)},
          {"exact_volume_change_pct", number(a.exactVolumeChangePct)},
          {"mid_radius_ratio", number(a.midRadiusRatio)},
          {"exact_mid_radius_ratio", number(a.exactMidRadiusRatio)},
          {"mid_rotation_deg", number(a.midRotationDeg)},
          {"exact_mid_rotation_deg", number(a.exactMidRotationDeg)},
          {"rotation_error_deg", number(a.rotationErrorDeg)},
          {"exact_torsion_rms_mm", number(a.exactTorsionRmsMm)}};
}

AnalyticMetrics analyticFromJson(const nlohmann::json& o) {
  AnalyticMetrics a;
  if (!o.is_object()) return a;
  a.type = o.value("type", a.type);
  a.poissonRatio = numberOr(o, "poisson_ratio", a.poissonRatio);
  a.exactPoissonRatio = numberOr(o, "exact_poisson_ratio", a.exactPoissonRatio);
  a.volumeChangePct = numberOr(o, "volume_change_pct", a.volumeChangePct);
  a.exactVolumeChangePct = numberOr(o, "exact_volume_change_pct", a.exactVolumeChangePct);
  a.midRadiusRatio = numberOr(o, "mid_radius_ratio", a.midRadiusRatio);
  a.exactMidRadiusRatio = numberOr(o, "exact_mid_radius_ratio", a.exactMidRadiusRatio);
  a.midRotationDeg = numberOr(o, "mid_rotation_deg", a.midRotationDeg);
  a.exactMidRotationDeg = numberOr(o, "exact_mid_rotation_deg", a.exactMidRotationDeg);
  a.rotationErrorDeg = numberOr(o, "rotation_error_deg", a.rotationErrorDeg);
  a.exactTorsionRmsMm = numberOr(o, "exact_torsion_rms_mm", a.exactTorsionRmsMm);
  if (auto contact = o.find("contact"); contact != o.end() && contact->is_array())
    for (const auto& c : *contact) {
      ContactPose pose;
      pose.pose = c.value("pose", 0);
      pose.approachMm = numberOr(c, "approach_mm", pose.approachMm);
      pose.radiusMm = numberOr(c, "radius_mm", pose.radiusMm);
      pose.exactRadiusMm = numberOr(c, "exact_radius_mm", pose.exactRadiusMm);
      a.contact.push_back(pose);
    }
  return a;
}

nlohmann::json musclesJson(const std::vector<MuscleResults>& muscles) {
  nlohmann::json list = nlohmann::json::array();
  for (const MuscleResults& muscle : muscles) list.push_back(toJson(muscle));
  return list;
}

}  // namespace

nlohmann::json toJson(const RunMetrics& m) {
  return {
      {"scene", m.scene},
      {"method", m.method},
      {"integrator", m.integrator},
      {"particles", m.particles},
      {"springs", m.springs},
      {"boundary_particles", m.boundaryParticles},
      {"bone_spheres", m.boneSpheres},
      {"steps", m.steps},
      {"poses", m.poses},
      {"iterations", m.iterations},
      {"threads", m.threads},
      {"ms_per_step", number(m.msPerStep)},
      {"ms_per_iteration", number(m.msPerIteration)},
      {"ms_per_time_step", number(m.msPerTimeStep)},
      {"timing",
       {{"mss", m.timing.mss},
        {"volume", m.timing.volume},
        {"muscle_cd", m.timing.muscleCd},
        {"bone_cd", m.timing.boneCd},
        {"response", m.timing.response},
        {"output", m.timing.output}}},
      {"max_penetration_mm", number(m.maxPenetrationMm)},
      {"mean_penetration_mm", number(m.meanPenetrationMm)},
      {"volume_change_pct", number(m.volumeChangePct)},
      {"worst_muscle_volume_change_pct", number(m.worstMuscleVolumeChangePct)},
      {"worst_volume_muscle", m.worstVolumeMuscle},
      {"spring_deviation_ratio", number(m.springDeviationRatio)},
      {"rms_to_reference_mm", number(m.rmsToReferenceMm)},
      {"shape_rms_to_reference_mm", number(m.shapeRmsToReferenceMm)},
      {"worst_muscle", m.worstMuscle},
      {"worst_muscle_rms_mm", number(m.worstMuscleRmsMm)},
      {"rms_to_reference_per_pose_mm", numbers(m.rmsToReferencePerPoseMm)},
      {"muscles_to_reference", toJson(m.musclesToReference)},
      {"rms_to_self_reference_mm", number(m.rmsToSelfReferenceMm)},
      {"rms_to_equilibrium_mm", number(m.rmsToEquilibriumMm)},
      {"worst_pose_rms_to_equilibrium_mm", number(m.worstPoseRmsToEquilibriumMm)},
      {"rms_to_equilibrium_poses", m.rmsToEquilibriumPoses},
      {"rms_to_equilibrium_per_pose_mm", numbers(m.rmsToEquilibriumPerPoseMm)},
      {"worst_pose_to_equilibrium", m.worstPoseToEquilibrium},
      {"worst_muscle_to_equilibrium", m.worstMuscleToEquilibrium},
      {"worst_muscle_rms_to_equilibrium_mm", number(m.worstMuscleRmsToEquilibriumMm)},
      {"worst_muscle_pose_to_equilibrium", toJson(m.worstMusclePoseToEquilibrium)},
      {"muscles_to_equilibrium", toJson(m.musclesToEquilibrium)},
      {"rms_to_finer_resolution_mm", number(m.rmsToFinerResolutionMm)},
      {"unconverged_poses", m.unconvergedPoses},
      {"residual_rms_mm", number(m.residualRmsMm)},
      {"residual_max_mm", number(m.residualMaxMm)},
      {"residual_rms_n", number(m.residualRmsN)},
      {"residual_max_n", number(m.residualMaxN)},
      {"residual_worst_pose", m.residualWorstPose},
      {"residual_contact_particles", m.residualContacts},
      {"residual_rms_mm_per_pose", numbers(m.residualRmsMmPerPose)},
      {"residual_max_mm_per_pose", numbers(m.residualMaxMmPerPose)},
      {"residual_rms_n_per_pose", numbers(m.residualRmsNPerPose)},
      {"residual_max_n_per_pose", numbers(m.residualMaxNPerPose)},
      {"rms_to_reference_poses", m.rmsToReferencePoses},
      {"rms_to_self_reference_poses", m.rmsToSelfReferencePoses},
      {"nan", m.nan},
      {"exploded", m.exploded},
      {"failed_step", m.failedStep},
      {"excluded_from", m.excludedFrom},
      {"exclusion", m.exclusion},
      {"interrupted", m.interrupted},
      {"peak_memory_mb", number(m.peakMemoryMb)},
      {"wall_seconds", m.wallSeconds},
      {"analytic", toJson(m.analytic)},
      {"volume_error_to_exact_pct", number(m.analytic.volumeErrorPct())},
      {"muscles", musclesJson(m.muscles)},
      {"series", seriesJson(m.series)},
  };
}

RunMetrics runMetricsFromJson(const nlohmann::json& o) {
  RunMetrics m;
  m.scene = o.value("scene", m.scene);
  m.method = o.value("method", m.method);
  m.integrator = o.value("integrator", m.integrator);
  m.particles = o.value("particles", m.particles);
  m.springs = o.value("springs", m.springs);
  m.boundaryParticles = o.value("boundary_particles", m.boundaryParticles);
  m.boneSpheres = o.value("bone_spheres", m.boneSpheres);
  m.steps = o.value("steps", m.steps);
  m.poses = o.value("poses", m.poses);
  m.iterations = o.value("iterations", m.iterations);
  m.threads = o.value("threads", m.threads);
  m.msPerStep = numberOr(o, "ms_per_step", m.msPerStep);
  m.msPerIteration = numberOr(o, "ms_per_iteration", m.msPerIteration);
  m.msPerTimeStep = numberOr(o, "ms_per_time_step", m.msPerTimeStep);
  if (auto t = o.find("timing"); t != o.end() && t->is_object()) {
    m.timing.mss = numberOr(*t, "mss", 0);
    m.timing.volume = numberOr(*t, "volume", 0);
    m.timing.muscleCd = numberOr(*t, "muscle_cd", 0);
    m.timing.boneCd = numberOr(*t, "bone_cd", 0);
    m.timing.response = numberOr(*t, "response", 0);
    m.timing.output = numberOr(*t, "output", 0);
  }
  m.maxPenetrationMm = numberOr(o, "max_penetration_mm", m.maxPenetrationMm);
  m.meanPenetrationMm = numberOr(o, "mean_penetration_mm", m.meanPenetrationMm);
  m.volumeChangePct = numberOr(o, "volume_change_pct", m.volumeChangePct);
  m.worstMuscleVolumeChangePct =
      numberOr(o, "worst_muscle_volume_change_pct", m.worstMuscleVolumeChangePct);
  m.worstVolumeMuscle = o.value("worst_volume_muscle", m.worstVolumeMuscle);
  m.springDeviationRatio = numberOr(o, "spring_deviation_ratio", m.springDeviationRatio);
  m.rmsToReferenceMm = numberOr(o, "rms_to_reference_mm", m.rmsToReferenceMm);
  m.shapeRmsToReferenceMm = numberOr(o, "shape_rms_to_reference_mm", m.shapeRmsToReferenceMm);
  m.worstMuscle = o.value("worst_muscle", m.worstMuscle);
  m.worstMuscleRmsMm = numberOr(o, "worst_muscle_rms_mm", m.worstMuscleRmsMm);
  m.rmsToReferencePerPoseMm = numbersAt(o, "rms_to_reference_per_pose_mm");
  m.musclesToReference = musclesFromJson(o, "muscles_to_reference");
  m.rmsToSelfReferenceMm = numberOr(o, "rms_to_self_reference_mm", m.rmsToSelfReferenceMm);
  m.rmsToEquilibriumMm = numberOr(o, "rms_to_equilibrium_mm", m.rmsToEquilibriumMm);
  m.worstPoseRmsToEquilibriumMm =
      numberOr(o, "worst_pose_rms_to_equilibrium_mm", m.worstPoseRmsToEquilibriumMm);
  m.rmsToEquilibriumPoses = o.value("rms_to_equilibrium_poses", m.rmsToEquilibriumPoses);
  m.rmsToEquilibriumPerPoseMm = numbersAt(o, "rms_to_equilibrium_per_pose_mm");
  m.worstPoseToEquilibrium = o.value("worst_pose_to_equilibrium", m.worstPoseToEquilibrium);
  m.worstMuscleToEquilibrium = o.value("worst_muscle_to_equilibrium", m.worstMuscleToEquilibrium);
  m.worstMuscleRmsToEquilibriumMm =
      numberOr(o, "worst_muscle_rms_to_equilibrium_mm", m.worstMuscleRmsToEquilibriumMm);
  m.worstMusclePoseToEquilibrium = musclePoseRmsFromJson(o);
  m.musclesToEquilibrium = musclesFromJson(o, "muscles_to_equilibrium");
  m.rmsToFinerResolutionMm = numberOr(o, "rms_to_finer_resolution_mm", m.rmsToFinerResolutionMm);
  m.unconvergedPoses = o.value("unconverged_poses", m.unconvergedPoses);
  m.residualRmsMm = numberOr(o, "residual_rms_mm", m.residualRmsMm);
  m.residualMaxMm = numberOr(o, "residual_max_mm", m.residualMaxMm);
  m.residualRmsN = numberOr(o, "residual_rms_n", m.residualRmsN);
  m.residualMaxN = numberOr(o, "residual_max_n", m.residualMaxN);
  m.residualWorstPose = o.value("residual_worst_pose", m.residualWorstPose);
  m.residualContacts = o.value("residual_contact_particles", m.residualContacts);
  m.residualRmsMmPerPose = numbersAt(o, "residual_rms_mm_per_pose");
  m.residualMaxMmPerPose = numbersAt(o, "residual_max_mm_per_pose");
  m.residualRmsNPerPose = numbersAt(o, "residual_rms_n_per_pose");
  m.residualMaxNPerPose = numbersAt(o, "residual_max_n_per_pose");
  m.rmsToReferencePoses = o.value("rms_to_reference_poses", m.rmsToReferencePoses);
  m.rmsToSelfReferencePoses = o.value("rms_to_self_reference_poses", m.rmsToSelfReferencePoses);
  m.nan = o.value("nan", m.nan);
  m.exploded = o.value("exploded", m.exploded);
  m.failedStep = o.value("failed_step", m.failedStep);
  m.excludedFrom = o.value("excluded_from", m.excludedFrom);
  m.exclusion = o.value("exclusion", m.exclusion);
  m.interrupted = o.value("interrupted", m.interrupted);
  m.peakMemoryMb = numberOr(o, "peak_memory_mb", m.peakMemoryMb);
  m.wallSeconds = numberOr(o, "wall_seconds", m.wallSeconds);
  if (auto a = o.find("analytic"); a != o.end()) m.analytic = analyticFromJson(*a);
  if (auto list = o.find("muscles"); list != o.end() && list->is_array())
    for (const auto& muscle : *list) m.muscles.push_back(muscleResultsFromJson(muscle));
  if (auto series = o.find("series"); series != o.end()) m.series = seriesFromJson(*series);
  return m;
}

}  // namespace fibremss
