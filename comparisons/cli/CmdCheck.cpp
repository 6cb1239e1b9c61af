// `fibremss check SCENE`: load and prepare a scene, print its statistics (text or --json),
// optionally write the prepared rest state for ParaView (--out DIR).
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>

#include "Commands.h"
#include "SceneArgs.h"
#include "fibremss/Measures.h"
#include "fibremss/Messages.h"
#include "fibremss/Output.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"

namespace fibremss::cli {
namespace {

struct CheckArgs {
  SceneArgs scene;
  bool json = false;
  std::string out;
};

/// A file-name-safe version of a body name, distinct from every stem in `used` ("a b" and
/// "a_b" both give a_b: the second becomes a_b-1, with the body's index).
std::string fileStem(const std::string& name, size_t index, std::set<std::string>& used) {
  std::string stem = name;
  for (char& c : stem)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') c = '_';
  while (!used.insert(stem).second) stem += "-" + std::to_string(index);
  return stem;
}

PolyData meshData(const TriangleMesh& mesh) {
  PolyData data;
  data.points = mesh.vertices;
  data.triangles = mesh.triangles;
  return data;
}

/// Writes surfaces, fibres, particles (radius, fixed, boundary) and bone spheres in scene units
/// (`unitScale` metres each), plus rest.pvd.
void writeRestState(const std::string& directory, const PreparedScene& prepared, double unitScale) {
  namespace fs = std::filesystem;
  PvdCollection collection;
  int part = 0;
  const auto scale = btScalar(1.0 / unitScale);
  auto add = [&](const std::string& file, PolyData data) {
    data.pointScale = scale;
    writeVtp((fs::path(directory) / file).string(), data);
    collection.add(0.0, file, part++);
  };
  std::set<std::string> muscleStems, boneStems;
  for (size_t m = 0; m < prepared.muscles.size(); ++m) {
    const MuscleSettings* muscle = prepared.muscles[m].get();
    const std::string stem = "muscle-" + fileStem(muscle->name, m, muscleStems);
    add(stem + "-surface.vtp", meshData(muscle->restSurface));

    PolyData fibres;
    fibres.points = muscle->restPositions;
    fibres.lineIndices = muscle->fibreParticles;
    fibres.lineOffsets = muscle->fibreOffsets;
    add(stem + "-fibres.vtp", fibres);

    PolyData particles;
    particles.points = muscle->restPositions;
    particles.pointsAsVertices = true;
    std::vector<float> radius, fixed, boundary, tendon;
    for (size_t i = 0; i < muscle->particleCount(); ++i) {
      radius.push_back(float(muscle->radii[i] * scale));
      fixed.push_back(muscle->isFixed(uint32_t(i)) ? 1.f : 0.f);
      boundary.push_back(muscle->isBoundary(uint32_t(i)) ? 1.f : 0.f);
      tendon.push_back(muscle->isTendon(uint32_t(i)) ? 1.f : 0.f);
    }
    particles.pointData = {{"radius", 1, radius},
                           {"fixed", 1, fixed},
                           {"boundary", 1, boundary},
                           {"tendon", 1, tendon}};
    add(stem + "-particles.vtp", particles);
  }
  for (size_t b = 0; b < prepared.bones.size(); ++b) {
    const BoneSettings* bone = prepared.bones[b].get();
    const std::string stem = "bone-" + fileStem(bone->name, b, boneStems);
    add(stem + "-mesh.vtp", meshData(bone->mesh));
    PolyData spheres;
    spheres.points = bone->sphereCentres;
    spheres.pointsAsVertices = true;
    std::vector<float> radius;
    for (btScalar r : bone->sphereRadii) radius.push_back(float(r * scale));
    spheres.pointData = {{"radius", 1, radius}};
    add(stem + "-spheres.vtp", spheres);
  }
  collection.write((fs::path(directory) / "rest.pvd").string());
}

/// Particles of the muscle fixed to each bone, by bone name (bones fixing none left out).
nlohmann::ordered_json fixedByBone(const MuscleSettings& muscle, const PreparedScene& prepared) {
  const std::vector<size_t> counts = fixedParticlesPerBone(muscle, prepared.bones.size());
  nlohmann::ordered_json object = nlohmann::ordered_json::object();
  for (size_t b = 0; b < counts.size(); ++b)
    if (counts[b] > 0) object[prepared.bones[b]->name] = counts[b];
  return object;
}

/// "412 to 'pelvis', 40 to 'femur'" (or "none").
std::string describeFixed(const nlohmann::ordered_json& byBone) {
  std::string text;
  for (auto it = byBone.begin(); it != byBone.end(); ++it)
    text += (text.empty() ? "" : ", ") + std::to_string(it.value().get<size_t>()) + " to '" +
            it.key() + "'";
  return text.empty() ? "none" : text;
}

/// Per bone that particles were pushed out of, by name: how deep the deepest lay [mm].
template <typename Name>
nlohmann::ordered_json deepestByName(const MusclePreparationReport& report, Name name) {
  nlohmann::ordered_json object = nlohmann::ordered_json::object();
  for (size_t b = 0; b < report.pushedOutOfBones.size(); ++b)
    if (report.pushedOutOfBones[b] > 0) object[name(b)] = report.pushedOutOfBonesDepth[b] * 1000;
  return object;
}

/// What preparation found and repaired, per muscle, by name (the JSON "preparation" object).
nlohmann::ordered_json preparationReport(const PreparationReport& report,
                                         const LoadedScene& scene) {
  auto byName = [](const std::vector<size_t>& counts, auto name) {
    nlohmann::ordered_json object = nlohmann::ordered_json::object();
    for (size_t i = 0; i < counts.size(); ++i)
      if (counts[i] > 0) object[name(i)] = counts[i];
    return object;
  };
  auto boneName = [&](size_t b) { return scene.bones[b].name; };
  auto muscleName = [&](size_t m) { return scene.muscles[m].name; };
  nlohmann::ordered_json muscles = nlohmann::ordered_json::array();
  for (size_t m = 0; m < report.muscles.size(); ++m) {
    const MusclePreparationReport& r = report.muscles[m];
    muscles.push_back(
        {{"name", scene.muscles[m].name},
         {"sampled_particles", r.sampledParticles},
         {"merged_particles", r.mergedParticles},
         {"merge_distance_mm", r.mergeDistance * 1000},
         {"shortest_spring_mm", r.shortestSpring * 1000},
         {"tendon_particles", r.tendonParticles},
         {"tendon_springs", r.tendonSprings},
         {"pushed_out_of_muscles", byName(r.pushedOutOfMuscles, muscleName)},
         {"pushed_out_of_bones", byName(r.pushedOutOfBones, boneName)},
         {"pushed_out_of_bones_deepest_mm", deepestByName(r, boneName)},
         {"surface_vertices_pushed_out", byName(r.surfaceVerticesPushedOut, boneName)}});
  }
  return {{"repairs", report.repairs}, {"muscles", muscles}};
}

/// What `check` reports of a prepared scene: its muscles and bones and their totals.
struct CheckSummary {
  nlohmann::ordered_json muscles = nlohmann::ordered_json::array();  ///< one entry per muscle
  nlohmann::ordered_json bones = nlohmann::ordered_json::array();    ///< one entry per bone
  nlohmann::ordered_json preparation;  ///< what preparation found and repaired
  std::vector<std::string> warnings;   ///< preparation's and the attachments' warnings
  size_t particles = 0;                ///< particles of all muscles
  size_t boundary = 0;                 ///< boundary particles of all muscles
  size_t fixed = 0;                    ///< fixed particles of all muscles
  size_t springs = 0;                  ///< springs of all muscles
  size_t spheres = 0;                  ///< spheres of all bones
  double loadSeconds = 0;              ///< loading the scene [s]
};

/// Each muscle's and bone's entry and the totals into `summary`.
void summarise(const PreparedScene& prepared, CheckSummary& summary) {
  for (size_t m = 0; m < prepared.muscles.size(); ++m) {
    const MuscleSettings& muscle = *prepared.muscles[m];
    nlohmann::ordered_json entry{{"name", muscle.name},
                                 {"particles", muscle.particleCount()},
                                 {"boundary_particles", muscle.boundaryParticles.size()},
                                 {"fixed_particles", muscle.fixedParticles.size()},
                                 {"fixed_to_bones", fixedByBone(muscle, prepared)},
                                 {"springs", muscle.springs.size()},
                                 {"fibres", muscle.fibreCount()},
                                 {"loose_fibre_ends", prepared.report.muscles[m].looseFibreEnds}};
    if (m < prepared.report.surfaceCoverage.size())
      entry["surface_coverage"] = prepared.report.surfaceCoverage[m];
    summary.muscles.push_back(entry);
    summary.particles += muscle.particleCount();
    summary.boundary += muscle.boundaryParticles.size();
    summary.fixed += muscle.fixedParticles.size();
    summary.springs += muscle.springs.size();
  }
  for (const auto& bone : prepared.bones) {
    summary.bones.push_back({{"name", bone->name},
                             {"spheres", bone->sphereCentres.size()},
                             {"triangles", bone->mesh.triangles.size()}});
    summary.spheres += bone->sphereCentres.size();
  }
}

/// The summary as JSON on stdout (--json).
void printJson(const LoadedScene& scene, const PreparedScene& prepared,
               const CheckSummary& summary) {
  nlohmann::ordered_json result{{"scene", scene.name},
                                {"particles", summary.particles},
                                {"boundary_particles", summary.boundary},
                                {"fixed_particles", summary.fixed},
                                {"springs", summary.springs},
                                {"bone_spheres", summary.spheres},
                                {"poses", scene.poseCount},
                                {"load_seconds", summary.loadSeconds},
                                {"preparation_seconds", prepared.report.seconds},
                                {"muscles", summary.muscles},
                                {"bones", summary.bones},
                                {"warnings", summary.warnings},
                                {"notes", scene.notes},
                                {"preparation", summary.preparation}};
  for (const auto& warning : scene.warnings) result["warnings"].push_back(warning);
  std::cout << result.dump(2) << "\n";
}

/// The muscles' table: particles, boundary, fixed, springs, coverage, loose fibre ends.
void printMuscleTable(const nlohmann::ordered_json& muscles) {
  std::cout << std::left << std::setw(24) << "muscle" << std::right << std::setw(10) << "particles"
            << std::setw(10) << "boundary" << std::setw(8) << "fixed" << std::setw(10) << "springs"
            << std::setw(10) << "coverage" << std::setw(13) << "loose ends"
            << "\n";
  for (const auto& m : muscles) {
    std::cout << std::left << std::setw(24) << m["name"].get<std::string>() << std::right
              << std::setw(10) << m["particles"].get<size_t>() << std::setw(10)
              << m["boundary_particles"].get<size_t>() << std::setw(8)
              << m["fixed_particles"].get<size_t>() << std::setw(10) << m["springs"].get<size_t>();
    if (m.contains("surface_coverage"))
      std::cout << std::setw(9) << std::fixed << std::setprecision(1)
                << 100 * m["surface_coverage"].get<double>() << "%" << std::defaultfloat;
    std::cout << std::setw(13) << m["loose_fibre_ends"].get<size_t>() << "\n";
  }
  const bool anyLoose = std::any_of(muscles.begin(), muscles.end(), [](const auto& m) {
    return m["loose_fibre_ends"].template get<size_t>() > 0;
  });
  if (!anyLoose) return;
  std::cout << "(loose ends: fibres that end on a bone with their last particle free; it lies up "
               "to one sample spacing before the end, held by its neighbours; a larger "
               "attachment_distance or resolution fixes it)\n";
}

/// The summary as text on stdout.
void printText(const LoadedScene& scene, const PreparedScene& prepared, const CheckSummary& summary,
               const std::string& out) {
  std::cout << "scene " << scene.name << " (" << scene.source << "): " << scene.bones.size()
            << " bones, " << scene.muscles.size() << " muscles, " << scene.poseCount << " poses\n";
  printMuscleTable(summary.muscles);
  for (const auto& m : summary.muscles)
    std::cout << "fixed particles of " << m["name"].get<std::string>() << ": "
              << describeFixed(m["fixed_to_bones"]) << "\n";
  for (const auto& b : summary.bones)
    std::cout << std::left << std::setw(24) << ("bone " + b["name"].get<std::string>())
              << std::right << std::setw(10) << b["spheres"].get<size_t>() << " spheres\n";
  std::cout << "total: " << summary.particles << " particles, " << summary.boundary << " boundary, "
            << summary.fixed << " fixed, " << summary.springs << " springs, " << summary.spheres
            << " bone spheres\n";
  std::cout << std::setprecision(3) << "load " << summary.loadSeconds << " s, preparation "
            << prepared.report.seconds << " s\n";
  std::cout << "preparation report:"
            << (prepared.report.repairs.empty() ? " nothing repaired\n" : "\n");
  for (const auto& repair : prepared.report.repairs) std::cout << "  repaired: " << repair << "\n";
  if (!out.empty()) std::cout << "rest state written to " << out << "/rest.pvd\n";
}

void runCheck(const CheckArgs& args) {
  using Clock = std::chrono::steady_clock;
  const auto loadStart = Clock::now();
  const LoadedScene scene = loadScene(args.scene.scene, args.scene.overrides);
  CheckSummary summary;
  summary.loadSeconds = std::chrono::duration<double>(Clock::now() - loadStart).count();
  printWarnings(scene.warnings);
  printNotes(scene.notes);

  if (!args.out.empty()) requireWritableDirectory(args.out);  // fail before preparing
  const PreparedScene prepared =
      prepareScene(scene.bones, scene.muscles, scene.simulation.seed, scene.simulation.threads);
  printWarnings(prepared.report.warnings);
  summary.preparation = preparationReport(prepared.report, scene);
  summary.warnings = prepared.report.warnings;
  for (auto& warning : attachmentWarnings(scene, prepared)) {
    printWarning(warning);
    summary.warnings.push_back(std::move(warning));
  }
  summarise(prepared, summary);

  if (!args.out.empty()) {
    const OutputDirectory locked(args.out);
    writeRestState(args.out, prepared, scene.unitScale);
  }
  if (args.json)
    printJson(scene, prepared, summary);
  else
    printText(scene, prepared, summary, args.out);
}

}  // namespace

void addCheckCommand(CLI::App& app) {
  auto args = std::make_shared<CheckArgs>();
  auto* command = app.add_subcommand(
      "check", "Prepare a scene and print its statistics (particles, springs, spheres, time)");
  addSceneArgs(*command, args->scene);
  command->add_flag("--json", args->json, "Print the statistics as one JSON object");
  command->add_option("--out", args->out, "Write the prepared rest state (.vtp + rest.pvd) here");
  command->callback([args] { runCheck(*args); });
}

}  // namespace fibremss::cli
