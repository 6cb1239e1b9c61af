// The scene model: defaults, overrides, errors naming field and file, units, paths, motions,
// and export -> load round trips.
#include "fibremss/Scene.h"

#include <BulletCollision/BroadphaseCollision/btDbvtBroadphase.h>
#include <BulletDynamics/ConstraintSolver/btSequentialImpulseConstraintSolver.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "fibremss/Error.h"
#include "fibremss/SceneSystem.h"
#include "fibremss/SolverSettings.h"

namespace fs = std::filesystem;
using fibremss::InputError;
using fibremss::LoadedScene;
using fibremss::loadScene;
using Json = nlohmann::ordered_json;

namespace {

const fs::path kFixtures = fs::path(FIBREMSS_SOURCE_DIR) / "tests" / "data" / "scenes";

/// Writes `text` to a fresh file under the test's temporary directory and returns its path.
std::string writeScene(const std::string& name, const std::string& text) {
  const fs::path directory = fs::temp_directory_path() / "fibremss_scene_test";
  fs::create_directories(directory);
  const fs::path path = directory / name;
  std::ofstream(path) << text;
  return path.string();
}

/// A sphere muscle with chord fibres (no files), in metres, plus `extra` top-level fields.
std::string sphereScene(const std::string& extra = "", const std::string& muscleExtra = "") {
  return R"({
    "muscles": [{
      "name": "ball",
      "surface": {"generator": {"type": "ellipsoid", "radii": [0.03, 0.03, 0.03]}},
      "fibres": {"generator": {"type": "chords"}})" +
         muscleExtra + R"(
    }])" +
         extra + "}";
}

/// A pelvis-like box and a femur-like box swept about a pivot (poses as given: no sub-poses).
std::string sweepScene(const std::string& motion) {
  return R"({"units": "mm", "simulation": {"max_step_deg": 0}, "bones": [
    {"name": "fixed", "mesh": {"generator": {"type": "box", "size": [20, 20, 20]}}},
    {"name": "moving", "mesh": {"generator": {"type": "box", "centre": [0, -60, 0], "size": [10, 80, 10]}},
     "motion": )" +
         motion + "}]}";
}

/// Runs `load` and returns the InputError it throws (fails the test when none is thrown).
template <typename Load>
InputError errorOf(Load&& load) {
  try {
    load();
  } catch (const InputError& error) {
    return error;
  }
  ADD_FAILURE() << "expected an InputError";
  return InputError("", "", "");
}

}  // namespace

TEST(Scene, DefaultsFilledIn) {
  const std::string path = writeScene("defaults.json", sphereScene());
  const LoadedScene scene = loadScene(path);
  EXPECT_EQ(scene.name, "defaults");  // file stem
  EXPECT_EQ(scene.source, path);
  ASSERT_EQ(scene.muscles.size(), 1u);
  const auto& muscle = scene.muscles[0];
  const fibremss::MuscleParameters muscleDefaults;
  EXPECT_EQ(muscle.parameters.resolution, muscleDefaults.resolution);
  EXPECT_FLOAT_EQ(muscle.parameters.attachmentDistance, muscleDefaults.attachmentDistance);
  EXPECT_EQ(muscle.parameters.skinNeighbours, muscleDefaults.skinNeighbours);
  EXPECT_EQ(muscle.parameters.springs.layout, muscleDefaults.springs.layout);
  EXPECT_EQ(muscle.parameters.springs.neighbours, muscleDefaults.springs.neighbours);
  EXPECT_FLOAT_EQ(muscle.parameters.springs.kappa, muscleDefaults.springs.kappa);
  EXPECT_LT(muscle.parameters.springs.damping, 0);  // "auto": Zeleny's estimate
  EXPECT_EQ(muscle.fibres.fibreCount(), 64u);
  const fibremss::MuscleSystemDef simulation;
  EXPECT_EQ(scene.simulation.integrator, simulation.integrator);
  EXPECT_EQ(scene.simulation.stepSettings.adaptiveTimeStep,
            simulation.stepSettings.adaptiveTimeStep);
  EXPECT_FLOAT_EQ(scene.simulation.stepSettings.timeStep, simulation.stepSettings.timeStep);
  EXPECT_FLOAT_EQ(scene.simulation.stepSettings.minTimeStep, simulation.stepSettings.minTimeStep);
  EXPECT_EQ(scene.simulation.stepSettings.stopRule, simulation.stepSettings.stopRule);
  EXPECT_EQ(scene.simulation.stepSettings.iterations, simulation.stepSettings.iterations);
  EXPECT_FLOAT_EQ(scene.simulation.stepSettings.epsilon, simulation.stepSettings.epsilon);
  EXPECT_EQ(scene.simulation.seed, simulation.seed);
  EXPECT_FLOAT_EQ(scene.simulation.stepSettings.budgetMs, simulation.stepSettings.budgetMs);
  EXPECT_FLOAT_EQ(scene.simulation.stepSettings.deviationEpsilon,
                  simulation.stepSettings.deviationEpsilon);
  EXPECT_EQ(scene.simulation.rebuildEveryStep, simulation.rebuildEveryStep);
  EXPECT_EQ(scene.simulation.blendedPretransform, simulation.blendedPretransform);
  EXPECT_EQ(scene.simulation.pretransformBlend, simulation.pretransformBlend);
  EXPECT_FLOAT_EQ(scene.simulation.stepSettings.motionFraction,
                  simulation.stepSettings.motionFraction);
  EXPECT_FLOAT_EQ(scene.simulation.initialNoise, simulation.initialNoise);
  EXPECT_FLOAT_EQ(muscle.parameters.springs.dampingScale, muscleDefaults.springs.dampingScale);
  EXPECT_FLOAT_EQ(muscle.parameters.springs.density, muscleDefaults.springs.density);
  EXPECT_TRUE(scene.simulation.muscleMuscle);
  EXPECT_TRUE(scene.simulation.muscleBone);
  EXPECT_EQ(scene.outputs.frameEvery, 1);
  EXPECT_EQ(scene.poseCount, 1);
  ASSERT_EQ(scene.poseLabels.size(), 1u);
  EXPECT_DOUBLE_EQ(scene.unitScale, 1.0);

  // The complete JSON holds every section and field, with the defaults written out.
  const Json complete = Json::parse(scene.json);
  for (const char* key : {"name", "description", "units", "data_dir", "bones", "muscles", "model",
                          "simulation", "collision", "outputs"})
    EXPECT_TRUE(complete.contains(key)) << key;
  EXPECT_EQ(complete["units"], "m");
  EXPECT_EQ(complete["model"]["damping"], "auto");
  EXPECT_EQ(complete["muscles"][0]["resolution"], muscleDefaults.resolution);
  EXPECT_EQ(complete["simulation"]["integrator"], "projective");
  EXPECT_EQ(complete["muscles"][0]["fibres"]["generator"]["inset"], 0.8);
}

TEST(Scene, EverySolverSettingIsAKeyTheSimulationOrModelSectionReads) {
  const Json complete = Json::parse(loadScene("fusiform").json);
  for (const std::string& key : fibremss::solverSettings())
    EXPECT_TRUE(complete["simulation"].contains(key) || complete["model"].contains(key)) << key;
}

TEST(Scene, ReadmeHasARowForEveryKeyOfTheSettingsSections) {
  // A key's row in its section's table (Parameters.h for the simulation and collision sections,
  // SceneSettings.h for the model's and a muscle's) gives it its reading, validation and
  // shorthand; its meaning is its row in the section's table of scenes/README.md.
  std::ifstream in(fs::path(FIBREMSS_SOURCE_DIR) / "scenes" / "README.md");
  const std::string readme((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const Json complete = Json::parse(loadScene("fusiform").json);
  ASSERT_FALSE(complete["muscles"].empty());
  const std::pair<std::string, Json> sections[] = {{"model", complete["model"]},
                                                   {"simulation", complete["simulation"]},
                                                   {"collision", complete["collision"]},
                                                   {"outputs", complete["outputs"]},
                                                   {"muscles[i]", complete["muscles"][0]}};
  for (const auto& [section, keys] : sections) {
    const size_t start = readme.find(": `" + section + "`\n");
    ASSERT_NE(start, std::string::npos) << section;
    const std::string table = readme.substr(start, readme.find("\n## ", start) - start);
    for (const auto& item : keys.items())
      EXPECT_NE(table.find("\n| `" + item.key() + "` |"), std::string::npos)
          << section << "." << item.key();
  }
}

namespace {

/// Every key of `value`'s objects, however deep, that `known` lacks.
std::vector<std::string> keysMissingFrom(const Json& value, const std::vector<std::string>& known) {
  std::vector<std::string> missing;
  if (value.is_object())
    for (const auto& item : value.items())
      if (std::find(known.begin(), known.end(), item.key()) == known.end())
        missing.push_back(item.key());
  if (value.is_structured())
    for (const Json& element : value)
      for (std::string& key : keysMissingFrom(element, known)) missing.push_back(std::move(key));
  return missing;
}

}  // namespace

TEST(Scene, SceneKeysHoldEveryKeyOfTheCompleteSceneFiles) {
  // Scenes from files read fields no built-in scene has (a surface's file, weld, fill_holes).
  const std::vector<std::string> keys = fibremss::sceneKeys();
  EXPECT_TRUE(std::is_sorted(keys.begin(), keys.end()));
  EXPECT_EQ(std::adjacent_find(keys.begin(), keys.end()), keys.end());
  std::vector<fs::path> files = {kFixtures / "files.json"};
  for (const auto& entry : fs::directory_iterator(fs::path(FIBREMSS_SOURCE_DIR) / "scenes/json"))
    if (entry.path().extension() == ".json") files.push_back(entry.path());
  for (const fs::path& file : files) {
    std::ifstream in(file);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (text.find("${data_dir}") != std::string::npos) continue;  // needs --set data_dir=...
    EXPECT_EQ(keysMissingFrom(Json::parse(loadScene(file.string()).json), keys),
              std::vector<std::string>{})
        << file;
  }
}

TEST(Scene, OverrideForms) {
  const std::string twoMuscles = R"({"muscles": [
    {"name": "a", "surface": {"generator": {"type": "ellipsoid", "radii": [0.03, 0.03, 0.03]}},
     "fibres": {"generator": {"type": "chords"}}},
    {"name": "b", "surface": {"generator": {"type": "ellipsoid", "centre": [0.1, 0, 0], "radii": [0.02, 0.02, 0.02]}},
     "fibres": {"generator": {"type": "chords"}}}]})";
  const std::string path = writeScene("overrides.json", twoMuscles);
  // Shorthands reach every muscle, the model and the simulation.
  LoadedScene scene = loadScene(
      path, {"resolution=12", "kappa=2.5", "iterations=33", "integrator=semi-implicit-euler",
             "fibre_count=16", "muscle_bone=false", "layout=delaunay"});
  for (const auto& muscle : scene.muscles) {
    EXPECT_EQ(muscle.parameters.resolution, 12);
    EXPECT_FLOAT_EQ(muscle.parameters.springs.kappa, 2.5f);
    EXPECT_EQ(muscle.parameters.springs.layout, fibremss::SpringLayout::Delaunay);
    EXPECT_EQ(muscle.fibres.fibreCount(), 16u);
  }
  EXPECT_EQ(scene.simulation.stepSettings.iterations, 33);
  EXPECT_EQ(loadScene(path, {"stop=spring-deviation"}).simulation.stepSettings.stopRule,
            fibremss::StopRule::SpringDeviation);
  EXPECT_FLOAT_EQ(loadScene(path, {"motion_fraction=0.25"}).simulation.stepSettings.motionFraction,
                  0.25f);
  EXPECT_EQ(scene.simulation.integrator, fibremss::Integrator::SemiImplicitEuler);
  EXPECT_FALSE(scene.simulation.muscleBone);

  // Dotted paths by index and by element name; later overrides win; values parse as JSON.
  scene = loadScene(path, {"model.kappa=2", "simulation.iterations=100", "muscles.0.resolution=20",
                           "muscles.b.resolution=30", "simulation.time_step=fixed",
                           "simulation.dt=0.0005", "resolution=7", "muscles.1.resolution=8"});
  EXPECT_FLOAT_EQ(scene.muscles[0].parameters.springs.kappa, 2.f);
  EXPECT_EQ(scene.simulation.stepSettings.iterations, 100);
  EXPECT_EQ(scene.muscles[0].parameters.resolution, 7);
  EXPECT_EQ(scene.muscles[1].parameters.resolution, 8);
  EXPECT_FALSE(scene.simulation.stepSettings.adaptiveTimeStep);
  EXPECT_FLOAT_EQ(scene.simulation.stepSettings.timeStep, 0.0005f);
  // The overrides show in the complete JSON too.
  EXPECT_EQ(Json::parse(scene.json)["simulation"]["iterations"], 100);

  // A lattice layout makes generated fibres a grid.
  scene = loadScene(path, {"layout=lattice6"});
  EXPECT_EQ(scene.muscles[0].fibreGridColumns, 8);

  // Unknown keys list the valid ones; malformed overrides say what was expected.
  InputError error = errorOf([&] { loadScene(path, {"resolutoin=20"}); });
  EXPECT_EQ(error.source(), "--set");
  EXPECT_NE(std::string(error.what()).find("resolution"), std::string::npos) << error.what();
  error = errorOf([&] { loadScene(path, {"resolution"}); });
  EXPECT_NE(error.problem().find("key=value"), std::string::npos);
  error = errorOf([&] { loadScene(path, {"muscles.5.resolution=3"}); });
  EXPECT_NE(error.problem().find("2 elements"), std::string::npos) << error.what();
  error = errorOf([&] { loadScene(path, {"model.kapa=3"}); });
  EXPECT_EQ(error.where(), "model.kapa");
  EXPECT_NE(error.problem().find("kappa"), std::string::npos) << error.what();
  // A sweep shorthand on a scene without a sweep is an error rather than silently ignored.
  error = errorOf([&] { loadScene(path, {"step_deg=5"}); });
  EXPECT_NE(error.problem().find("sweep"), std::string::npos) << error.what();
}

TEST(Scene, AKeyThatMayBeAutoSaysWhatAutoTakesAndTheNumbersItTakes) {
  const InputError error = errorOf([] {
    loadScene(
        writeScene("volume-auto.json", sphereScene(R"(, "model": {"volume_stiffness": "lots"})")));
  });
  EXPECT_EQ(error.where(), "model.volume_stiffness");
  const std::string what = error.what();
  EXPECT_NE(what.find("\"auto\" (from poisson_ratio)"), std::string::npos) << what;
  EXPECT_NE(what.find("a number in [0, 1e+06]"), std::string::npos) << what;
  // A number out of its range is refused as any other key's.
  EXPECT_EQ(errorOf([] { loadScene("fusiform", {"damping=-1"}); }).where(), "model.damping");
}

TEST(Scene, ErrorsNameFieldAndFile) {
  struct Case {
    std::string file, text, where;
  };
  const std::vector<Case> cases = {
      {"unknown.json", sphereScene("", R"(, "resolutoin": 20)"), "muscles[0].resolutoin"},
      {"unknown-top.json", sphereScene(R"(, "simulaton": {})"), "simulaton"},
      {"type.json", sphereScene("", R"(, "resolution": "high")"), "muscles[0].resolution"},
      {"zero-resolution.json", sphereScene("", R"(, "resolution": 0)"), "muscles[0].resolution"},
      {"fraction.json", sphereScene("", R"(, "resolution": 2.5)"), "muscles[0].resolution"},
      {"negative-dt.json", sphereScene(R"(, "simulation": {"dt": -0.001})"), "simulation.dt"},
      {"neighbours.json", sphereScene(R"(, "model": {"neighbours": 0})"), "model.neighbours"},
      {"layout.json", sphereScene(R"(, "model": {"layout": "hexagonal"})"), "model.layout"},
      {"blend.json", sphereScene(R"(, "simulation": {"pretransform_blend": "cubic"})"),
       "simulation.pretransform_blend"},
      {"damping.json", sphereScene(R"(, "model": {"damping": "lots"})"), "model.damping"},
      {"units.json", sphereScene(R"(, "units": "inch")"), "units"},
      {"bool.json", sphereScene(R"(, "collision": {"muscle_bone": 1})"), "collision.muscle_bone"},
      {"min-dt.json", sphereScene(R"(, "simulation": {"dt": 0.001, "min_dt": 0.01})"),
       "simulation.min_dt"},
      {"generator.json",
       R"({"muscles": [{"surface": {"generator": {"type": "ellipsoid", "radii": [1, 1, 1], "sides": 3}},
                        "fibres": {"generator": {"type": "chords"}}}]})",
       "muscles[0].surface.generator.sides"},
      {"vector.json",
       R"({"muscles": [{"surface": {"generator": {"type": "ellipsoid", "radii": [1, 1]}},
                        "fibres": {"generator": {"type": "chords"}}}]})",
       "muscles[0].surface.generator.radii"},
      {"source.json",
       R"({"muscles": [{"surface": {}, "fibres": {"generator": {"type": "chords"}}}]})",
       "muscles[0].surface"},
      {"mismatch.json",
       R"({"muscles": [{"surface": {"generator": {"type": "box", "size": [1, 1, 1]}},
                        "fibres": {"generator": {"type": "tube"}}}]})",
       "muscles[0].fibres.generator.type"},
      {"duplicate.json",
       R"({"bones": [{"name": "b", "mesh": {"generator": {"type": "box", "size": [1, 1, 1]}}},
                     {"name": "b", "mesh": {"generator": {"type": "box", "size": [1, 1, 1]}}}]})",
       "bones[1].name"},
      {"missing-file.json", R"({"bones": [{"mesh": {"file": "nowhere.obj"}}]})",
       "bones[0].mesh.file"},
      {"top.json", "[1, 2]", "(top level)"},
  };
  for (const Case& c : cases) {
    const std::string path = writeScene(c.file, c.text);
    const InputError error = errorOf([&] { loadScene(path); });
    EXPECT_EQ(error.source(), path) << c.file;
    EXPECT_EQ(error.where(), c.where) << c.file << ": " << error.what();
    EXPECT_NE(std::string(error.what()).find(path), std::string::npos) << error.what();
  }
  // Not JSON at all: the file and the parser's position.
  const std::string broken = writeScene("broken.json", R"({"muscles": [)");
  const InputError error = errorOf([&] { loadScene(broken); });
  EXPECT_EQ(error.source(), broken);
  EXPECT_NE(error.problem().find("not valid JSON"), std::string::npos);
  // Neither a built-in nor a file.
  EXPECT_THROW(loadScene("no-such-scene"), InputError);
  EXPECT_THROW(fibremss::exportBuiltInScene("no-such-scene"), InputError);
}

TEST(Scene, MillimetresBecomeMetres) {
  const std::string metres = writeScene("metres.json", sphereScene());
  const std::string millimetres = writeScene("millimetres.json", R"({"units": "mm", "muscles": [{
        "surface": {"generator": {"type": "ellipsoid", "radii": [30, 30, 30]}},
        "fibres": {"generator": {"type": "chords"}}, "attachment_distance": 2.5}],
        "simulation": {"initial_noise": 1.5}})");
  const LoadedScene m = loadScene(metres);
  const LoadedScene mm = loadScene(millimetres);
  EXPECT_DOUBLE_EQ(mm.unitScale, 1e-3);
  ASSERT_EQ(m.muscles[0].surface.vertices.size(), mm.muscles[0].surface.vertices.size());
  for (size_t i = 0; i < m.muscles[0].surface.vertices.size(); ++i)
    EXPECT_LT((m.muscles[0].surface.vertices[i] - mm.muscles[0].surface.vertices[i]).length(),
              1e-7);
  EXPECT_FLOAT_EQ(mm.muscles[0].parameters.attachmentDistance, 0.0025f);
  EXPECT_FLOAT_EQ(mm.simulation.initialNoise, 0.0015f);
  // The default attachment distance (4 mm) is written in the scene's own units.
  EXPECT_EQ(Json::parse(m.json)["muscles"][0]["attachment_distance"], 0.004);
  const std::string defaultMm = writeScene("default-mm.json", R"({"units": "mm", "muscles": [{
        "surface": {"generator": {"type": "ellipsoid", "radii": [30, 30, 30]}},
        "fibres": {"generator": {"type": "chords"}}}]})");
  const LoadedScene d = loadScene(defaultMm);
  EXPECT_NEAR(Json::parse(d.json)["muscles"][0]["attachment_distance"].get<double>(), 4.0, 1e-9);
  EXPECT_FLOAT_EQ(d.muscles[0].parameters.attachmentDistance, 0.004f);
}

TEST(Scene, FilesRelativeToTheSceneAndDataDir) {
  const fs::path sceneFile = kFixtures / "files.json";
  // Load from another working directory: paths resolve against the scene file, not the cwd.
  const fs::path previous = fs::current_path();
  fs::current_path(fs::temp_directory_path());
  LoadedScene scene;
  EXPECT_NO_THROW(scene = loadScene(sceneFile.string()));
  fs::current_path(previous);
  ASSERT_EQ(scene.bones.size(), 1u);
  ASSERT_EQ(scene.muscles.size(), 1u);
  EXPECT_EQ(scene.muscles[0].fibres.fibreCount(), 4u);
  EXPECT_EQ(scene.muscles[0].parameters.resolution, 10);
  // The cube spans y = 20..40 mm.
  btVector3 lower, upper;
  fibremss::pointBounds(scene.bones[0].mesh.vertices, lower, upper);
  EXPECT_NEAR(lower.y(), 0.020, 1e-6);
  EXPECT_NEAR(upper.y(), 0.040, 1e-6);

  // ${data_dir} needs --set data_dir=...; then the same files load.
  const std::string dataDirScene = (kFixtures / "data-dir.json").string();
  const InputError error = errorOf([&] { loadScene(dataDirScene); });
  EXPECT_EQ(error.where(), "bones[0].mesh.file");
  EXPECT_NE(error.problem().find("data_dir"), std::string::npos);
  const LoadedScene withData =
      loadScene(dataDirScene, {"data_dir=" + (kFixtures / "meshes").string()});
  EXPECT_EQ(withData.bones[0].mesh.vertices.size(), scene.bones[0].mesh.vertices.size());
  EXPECT_EQ(withData.muscles[0].fibres.fibreCount(), 4u);

  // Fewer fibres asked for than the file has: an evenly spaced subset, with a warning.
  const LoadedScene subset = loadScene(sceneFile.string(), {"fibre_count=2"});
  EXPECT_EQ(subset.muscles[0].fibres.fibreCount(), 2u);
  EXPECT_FALSE(subset.warnings.empty());
}

TEST(Scene, SweepPosesAndAngles) {
  LoadedScene scene = loadScene(writeScene(
      "sweep.json", sweepScene(R"({"type": "sweep", "pivot": [0, 0, 0], "axis": [1, 0, 0],
                                  "start_deg": 0, "end_deg": 80, "step_deg": 10})")));
  ASSERT_EQ(scene.poseCount, 9);
  for (int p = 0; p < scene.poseCount; ++p) EXPECT_DOUBLE_EQ(scene.poseLabels[p], 10.0 * p);
  EXPECT_TRUE(scene.motions[0].poses.empty());  // the fixed bone has no motion
  // The pivot stays put; a point 100 mm below it turns by the pose's angle about +x.
  const btVector3 below(0, -0.1f, 0);
  for (int p = 0; p < scene.poseCount; ++p) {
    const btTransform pose = scene.bonePose(1, p);
    EXPECT_LT((pose * btVector3(0, 0, 0)).length(), 1e-6);
    const double angle = scene.poseLabels[p] * M_PI / 180;
    const btVector3 expected(0, btScalar(-0.1 * std::cos(angle)), btScalar(-0.1 * std::sin(angle)));
    EXPECT_LT((pose * below - expected).length(), 1e-6) << "pose " << p;
    EXPECT_EQ(scene.bonePose(0, p) * below, below);
  }
  // Steps that do not divide the range end exactly at end_deg; overrides change the step.
  scene = loadScene(
      writeScene("sweep3.json", sweepScene(R"({"type": "sweep", "end_deg": 80, "step_deg": 3})")));
  ASSERT_EQ(scene.poseCount, 28);  // 0, 3, ..., 78, 80
  EXPECT_DOUBLE_EQ(scene.poseLabels[26], 78.0);
  EXPECT_DOUBLE_EQ(scene.poseLabels.back(), 80.0);
  for (double step : {2.0, 4.0, 5.0, 10.0}) {
    scene =
        loadScene(writeScene("sweep-step.json", sweepScene(R"({"type": "sweep", "end_deg": 80})")),
                  {"step_deg=" + std::to_string(step)});
    EXPECT_EQ(scene.poseCount, int(std::round(80 / step)) + 1) << step;
  }
  // Downwards sweeps count down.
  scene = loadScene(writeScene(
      "sweep-down.json",
      sweepScene(R"({"type": "sweep", "start_deg": 10, "end_deg": -20, "step_deg": 10})")));
  EXPECT_EQ(scene.poseLabels, (std::vector<double>{10, 0, -10, -20}));
  // A zero or negative step is an error naming the field.
  const std::string bad =
      writeScene("sweep-bad.json", sweepScene(R"({"type": "sweep", "step_deg": 0})"));
  EXPECT_EQ(errorOf([&] { loadScene(bad); }).where(), "bones[1].motion.step_deg");
}

TEST(Scene, KeyframesAxisAngleAndQuaternionAgree) {
  const LoadedScene scene =
      loadScene(writeScene("keyframes.json", sweepScene(R"({"type": "keyframes", "keyframes": [
      {"translation": [0, 0, 0]},
      {"translation": [10, 0, 0], "rotation": {"axis": [0, 0, 1], "angle_deg": 90}},
      {"translation": [10, 0, 0], "quaternion": [0, 0, 0.70710678, 0.70710678], "label": 7}]})")));
  ASSERT_EQ(scene.poseCount, 3);
  EXPECT_EQ(scene.poseLabels, (std::vector<double>{0, 1, 7}));
  const btVector3 x(1, 0, 0);
  EXPECT_LT((scene.bonePose(1, 1) * x - btVector3(0.01f, 1, 0)).length(), 1e-6);
  EXPECT_LT((scene.bonePose(1, 2) * x - scene.bonePose(1, 1) * x).length(), 1e-6);
  // Motions with different pose counts cannot be combined.
  const std::string mismatch = writeScene("mismatch-poses.json", R"({"bones": [
    {"mesh": {"generator": {"type": "box", "size": [1, 1, 1]}},
     "motion": {"type": "sweep", "end_deg": 20, "step_deg": 10}},
    {"mesh": {"generator": {"type": "box", "size": [1, 1, 1]}},
     "motion": {"type": "sweep", "end_deg": 30, "step_deg": 10}}]})");
  EXPECT_EQ(errorOf([&] { loadScene(mismatch); }).where(), "bones[1].motion");
}

TEST(Scene, ExportedBuiltInsLoadAgainUnchanged) {
  for (const auto& builtIn : fibremss::builtInScenes()) {
    const std::string exported = fibremss::exportBuiltInScene(builtIn.name);
    const LoadedScene original = loadScene(builtIn.name);
    EXPECT_EQ(exported, original.json) << builtIn.name;
    const std::string path = writeScene(builtIn.name + ".json", exported);
    const LoadedScene again = loadScene(path);
    EXPECT_EQ(Json::parse(again.json), Json::parse(exported)) << builtIn.name;
    EXPECT_EQ(again.name, builtIn.name);
    ASSERT_EQ(again.muscles.size(), original.muscles.size());
    ASSERT_EQ(again.bones.size(), original.bones.size());
    EXPECT_EQ(again.poseCount, original.poseCount);
    for (size_t m = 0; m < again.muscles.size(); ++m) {
      EXPECT_EQ(again.muscles[m].surface.triangles, original.muscles[m].surface.triangles);
      EXPECT_EQ(again.muscles[m].fibres.points.size(), original.muscles[m].fibres.points.size());
      // Exported coordinates are rounded to 1 µm in millimetre scenes.
      for (size_t i = 0; i < again.muscles[m].fibres.points.size(); ++i)
        ASSERT_LT(
            (again.muscles[m].fibres.points[i] - original.muscles[m].fibres.points[i]).length(),
            1e-6)
            << builtIn.name << " muscle " << m;
    }
    for (int p = 0; p < again.poseCount; ++p)
      for (size_t b = 0; b < again.bones.size(); ++b) {
        const btVector3 probe(0.1f, 0.2f, 0.3f);
        EXPECT_LT((again.bonePose(b, p) * probe - original.bonePose(b, p) * probe).length(), 1e-6);
      }
  }
}

TEST(Scene, RepositorySceneFilesLoadAndRoundTrip) {
  const fs::path directory = fs::path(FIBREMSS_SOURCE_DIR) / "scenes" / "json";
  size_t files = 0;
  for (const auto& entry : fs::directory_iterator(directory)) {
    if (entry.path().extension() != ".json") continue;
    SCOPED_TRACE(entry.path().string());
    std::ifstream in(entry.path());
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (text.find("${data_dir}") != std::string::npos) continue;  // needs --set data_dir=...
    ++files;
    const LoadedScene scene = loadScene(entry.path().string());
    EXPECT_FALSE(scene.muscles.empty());
    // The complete form (every default written out) loads to the same complete form; copied
    // elsewhere only when no relative file paths would break.
    if (text.find("\"file\"") != std::string::npos) continue;
    const std::string copy = writeScene(entry.path().filename().string(), scene.json);
    EXPECT_EQ(Json::parse(loadScene(copy).json), Json::parse(scene.json));
  }
  EXPECT_GE(files, 1u);
}

namespace {

/// sweepScene's bones and a tube muscle from inside the fixed box to the moving box's face,
/// with muscle-level fields `declarations` (and fibres `fibres`).
std::string declaredScene(const std::string& declarations,
                          const std::string& fibres = R"({"generator": {"type": "tube"}})") {
  std::string scene = sweepScene(R"({"type": "sweep", "end_deg": 30})");
  scene.pop_back();  // reopen the top-level object
  return scene + R"(, "muscles": [{"name": "m",
      "surface": {"generator": {"type": "tube", "points": [[0, 5, 7], [0, -30, 8], [0, -60, 7]],
                                "radii": [3, 3, 3]}},
      "fibres": )" +
         fibres + ", " + (declarations.empty() ? "" : declarations + ", ") +
         "\"fibre_count\": 16, \"resolution\": 12}]}";
}

}  // namespace

TEST(Attachments, DeclaredOriginAndInsertionInASceneFile) {
  const LoadedScene scene = loadScene(writeScene(
      "declared.json",
      declaredScene(R"("origin": {"landmarks": [[0, 5, 7]], "radius": 5, "bones": ["fixed"]},
                       "insertion": {"bone": "moving", "distance": 2})")));
  ASSERT_EQ(scene.muscles.size(), 1u);
  const auto& attachments = scene.muscles[0].attachments;
  ASSERT_EQ(attachments.size(), 2u);
  EXPECT_EQ(attachments[0].name, "origin");
  EXPECT_EQ(attachments[0].bones, std::vector<uint32_t>{0});
  EXPECT_EQ(attachments[1].bones, std::vector<uint32_t>{1});
  const fibremss::TriangleMesh& surface = scene.muscles[0].surface;
  ASSERT_FALSE(attachments[0].surfaceVertices.empty());
  for (uint32_t v : attachments[0].surfaceVertices)
    EXPECT_LT(surface.vertices[v].distance(btVector3(0, 0.005f, 0.007f)), 0.005f);
  const fibremss::MeshDistance femur(scene.bones[1].mesh);
  ASSERT_FALSE(attachments[1].surfaceVertices.empty());
  for (uint32_t v : attachments[1].surfaceVertices)
    EXPECT_LT(femur.closest(surface.vertices[v]).distance, 0.002f);
  // The complete scene keeps them; loading it again gives the same areas.
  const LoadedScene again = loadScene(writeScene("declared-again.json", scene.json));
  ASSERT_EQ(again.muscles[0].attachments.size(), 2u);
  EXPECT_EQ(again.muscles[0].attachments[1].surfaceVertices, attachments[1].surfaceVertices);
  // Without declarations the nearest-bone rule stays: no attachments.
  EXPECT_TRUE(
      loadScene(writeScene("undeclared.json", declaredScene(""))).muscles[0].attachments.empty());
}

TEST(Attachments, BadDeclarationsNameTheField) {
  auto whereOf = [](const std::string& declarations,
                    const std::string& fibres = R"({"generator": {"type": "tube"}})") {
    const std::string path = writeScene("bad-declared.json", declaredScene(declarations, fibres));
    return errorOf([&] { loadScene(path); });
  };
  const std::string insertion = R"("insertion": {"bone": "moving"})";
  EXPECT_EQ(whereOf(insertion).where(), "muscles[0].origin");
  EXPECT_EQ(whereOf(R"("origin": {"landmarks": [[0, 5, 7]]}, )" + insertion).where(),
            "muscles[0].origin");
  EXPECT_EQ(whereOf(R"("origin": {"bones": ["nope"]}, )" + insertion).where(),
            "muscles[0].origin.bones");
  EXPECT_EQ(whereOf(R"("origin": {"bone": "fixed", "bones": ["fixed"]}, )" + insertion).where(),
            "muscles[0].origin.bones");
  // The surface fibre generator takes the muscle's areas; its own would contradict them.
  EXPECT_EQ(whereOf(R"("origin": {"bone": "fixed"}, )" + insertion,
                    R"({"generator": {"type": "surface", "insertion": {"bone": "moving"}}})")
                .where(),
            "muscles[0].fibres.generator.insertion");
}

TEST(Attachments, DeclaredAreasReachOneAndAHalfSampleSteps) {
  const LoadedScene scene = loadScene(writeScene(
      "declared-reach.json",
      declaredScene(R"("origin": {"landmarks": [[0, 5, 7]], "radius": 5, "bones": ["fixed"]},
                       "insertion": {"bone": "moving", "distance": 2})")));
  const fibremss::MuscleInput& muscle = scene.muscles[0];
  std::vector<double> steps;
  for (size_t f = 0; f < muscle.fibres.fibreCount(); ++f) {
    const auto fibre = muscle.fibres.fibre(f);
    double length = 0;
    for (size_t i = 1; i < fibre.size(); ++i) length += fibre[i].distance(fibre[i - 1]);
    steps.push_back(length / (muscle.parameters.resolution - 1));
  }
  std::sort(steps.begin(), steps.end());
  EXPECT_NEAR(muscle.parameters.attachmentDistance, 1.5 * steps[steps.size() / 2], 1e-6);
  // Given, it is kept; without declared areas the default is 4 mm (MillimetresBecomeMetres).
  EXPECT_FLOAT_EQ(
      loadScene(writeScene("declared-reach.json", declaredScene(R"("origin": {"landmarks":
          [[0, 5, 7]], "radius": 5, "bones": ["fixed"]}, "insertion": {"bone": "moving",
          "distance": 2}, "attachment_distance": 3)")))
          .muscles[0]
          .parameters.attachmentDistance,
      0.003f);
}

TEST(Attachments, AnEndWithNoFixedParticleIsAnErrorUnlessDeclaredFree) {
  const auto prepare = [](const std::vector<std::string>& overrides) {
    const LoadedScene scene = loadScene("fusiform", overrides);
    fibremss::prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  };
  // Nothing within 0 mm of the bars: the origin is named first, then the insertion.
  const InputError origin = errorOf([&] { prepare({"attachment_distance=0"}); });
  EXPECT_EQ(origin.where(), "free_end");
  EXPECT_NE(origin.source().find("'fusiform'"), std::string::npos) << origin.what();
  EXPECT_NE(origin.problem().find("fixed at its origin"), std::string::npos) << origin.what();
  const InputError insertion = errorOf([&] {
    prepare({"attachment_distance=0", "free_end=origin"});
  });
  EXPECT_NE(insertion.problem().find("fixed at its insertion"), std::string::npos)
      << insertion.what();
  EXPECT_NO_THROW(prepare({"attachment_distance=0", "free_end=both"}));
  EXPECT_NO_THROW(prepare({}));
  EXPECT_EQ(errorOf([&] { loadScene("fusiform", {"free_end=top"}); }).where(),
            "muscles[0].free_end");
}

TEST(Attachments, AMuscleDeeperInABoneThanTheAttachmentDistanceNamesTheDistance) {
  // The cylinder's flat ends reach 1.5 mm into the plates, along its fibres: below that, the
  // particles inside are pushed out onto one point of the plate's face.
  const auto prepare = [](const std::string& distance) {
    const LoadedScene scene = loadScene("cylinder-twist", {"attachment_distance=" + distance});
    fibremss::prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  };
  const InputError shallow = errorOf([&] { prepare("1.2"); });
  EXPECT_EQ(shallow.where(), "attachment_distance") << shallow.what();
  EXPECT_NE(shallow.problem().find("deepest particle: 1.5 mm"), std::string::npos)
      << shallow.what();
  EXPECT_NO_THROW(prepare("1.6"));
}

TEST(Attachments, CheckWarnsWhenNothingIsFixedToABoneThatMovesAway) {
  // The insertion names the fixed bone: nothing is fixed to the moving one the fibres end at
  // (nor, the insertion declared free, anything at the insertion).
  const LoadedScene scene = loadScene(writeScene(
      "declared-wrong.json",
      declaredScene(R"("origin": {"landmarks": [[0, 5, 7]], "radius": 5, "bones": ["fixed"]},
                       "insertion": {"landmarks": [[0, -60, 7]], "radius": 5, "bones": ["fixed"]},
                       "free_end": "insertion")")));
  const fibremss::PreparedScene prepared =
      fibremss::prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  const std::vector<std::string> warnings = fibremss::attachmentWarnings(scene, prepared);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("bone 'moving'"), std::string::npos) << warnings[0];
  // Declared right, nothing to warn about.
  const LoadedScene right = loadScene(writeScene(
      "declared-right.json",
      declaredScene(R"("origin": {"landmarks": [[0, 5, 7]], "radius": 5, "bones": ["fixed"]},
                       "insertion": {"bone": "moving", "distance": 2})")));
  EXPECT_TRUE(fibremss::attachmentWarnings(
                  right, fibremss::prepareScene(right.bones, right.muscles, right.simulation.seed))
                  .empty());
}

TEST(SceneSystem, AddsEveryBoneAndThenEveryMuscleInSceneOrder) {
  const LoadedScene scene = loadScene("fusiform", {"resolution=8"});
  const fibremss::PreparedScene prepared = fibremss::prepareScene(scene);
  ASSERT_FALSE(prepared.muscles.empty());
  fibremss::MuscleSystem system(scene.simulation);
  const fibremss::SceneHandles handles = fibremss::addScene(system, prepared);
  ASSERT_EQ(handles.bones.size(), prepared.bones.size());
  ASSERT_EQ(handles.muscles.size(), prepared.muscles.size());
  for (size_t m = 0; m < prepared.muscles.size(); ++m)
    EXPECT_EQ(&system.settings(handles.muscles[m]), prepared.muscles[m].get());
}

TEST(SceneSystem, PutsTheBonesOfAWorldAtTheScenesFirstPose) {
  const LoadedScene scene = loadScene("fusiform", {"resolution=8"});
  const fibremss::PreparedScene prepared = fibremss::prepareScene(scene);
  btSoftBodyRigidBodyCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher(&configuration);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  fibremss::MuscleWorld world(&dispatcher, &broadphase, &solver, &configuration, scene.simulation);
  fibremss::WorldScene added = fibremss::addScene(world, scene, prepared);
  ASSERT_EQ(added.bodies.size(), prepared.bones.size());
  ASSERT_EQ(added.handles.muscles.size(), prepared.muscles.size());
  for (size_t b = 0; b < added.bodies.size(); ++b) {
    const btTransform expected = scene.bonePose(b, 0);
    EXPECT_EQ(added.bodies[b]->transform().getOrigin(), expected.getOrigin()) << "bone " << b;
  }
  for (fibremss::MuscleHandle muscle : added.handles.muscles) world.removeMuscle(muscle);
  for (fibremss::BoneHandle bone : added.handles.bones) world.removeBone(bone);
}

TEST(SetShorthands, EveryKeyOfASettingsSectionIsSetWithoutItsSection) {
  const Json complete = Json::parse(loadScene("fusiform").json);
  for (const char* section : {"model", "simulation", "collision", "outputs"}) {
    ASSERT_TRUE(complete.contains(section)) << section;
    for (const auto& item : complete[section].items()) {
      const LoadedScene scene = loadScene("fusiform", {item.key() + "=" + item.value().dump()});
      EXPECT_EQ(nlohmann::json::parse(scene.json)[section][item.key()], item.value())
          << section << "." << item.key();
    }
  }
}

TEST(SetShorthands, EveryMuscleSettingIsSetOnEveryMuscle) {
  // Every key of a muscle but those read around its settings' table.
  const std::vector<std::string> notSettings = {"name", "surface", "fibres", "origin", "insertion"};
  const Json complete = Json::parse(loadScene("hip-flexion").json);
  ASSERT_GT(complete["muscles"].size(), 1u);
  for (const auto& item : complete["muscles"][0].items()) {
    if (std::find(notSettings.begin(), notSettings.end(), item.key()) != notSettings.end())
      continue;
    const Json value = item.value();
    const Json muscles =
        Json::parse(loadScene("hip-flexion", {item.key() + "=" + value.dump()}).json)["muscles"];
    for (const Json& muscle : muscles) EXPECT_EQ(muscle[item.key()], value) << item.key();
  }
}

TEST(SetShorthands, ReachTheTopLevelEveryMuscleEveryBonesSpheresAndEverySweep) {
  const LoadedScene scene = loadScene(
      "hip-extension", {"description=set", "tendon_stiffness=30", "thinning=0.25", "end_deg=40"});
  EXPECT_EQ(scene.description, "set");
  ASSERT_FALSE(scene.muscles.empty());
  for (const auto& muscle : scene.muscles) EXPECT_FLOAT_EQ(muscle.parameters.tendonStiffness, 30);
  ASSERT_FALSE(scene.bones.empty());
  for (const auto& bone : scene.bones) EXPECT_FLOAT_EQ(bone.spheres.thinning, 0.25f);
  const nlohmann::json complete = nlohmann::json::parse(scene.json);
  int sweeps = 0;
  for (const auto& bone : complete["bones"])
    if (bone["motion"].value("type", "") == "sweep") {
      EXPECT_EQ(bone["motion"]["end_deg"], 40);
      ++sweeps;
    }
  EXPECT_GT(sweeps, 0);
}
