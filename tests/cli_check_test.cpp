// `fibremss scenes` and `fibremss check` run as a user runs them (the built CLI).
// `check` prepares the scene, so these tests need the preparation (prepareScene) linked in.
#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>

#include "fibremss/Scene.h"

namespace fs = std::filesystem;
using Json = nlohmann::json;

namespace {

struct Result {
  int status = -1;
  std::string out;  ///< standard output (standard error goes to the test log)
};

Result run(const std::string& arguments) {
  Result result;
  const std::string command = std::string("\"") + FIBREMSS_CLI + "\" " + arguments;
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return result;
  std::array<char, 4096> buffer;
  size_t read;
  while ((read = fread(buffer.data(), 1, buffer.size(), pipe)) > 0)
    result.out.append(buffer.data(), read);
  const int status = pclose(pipe);
  result.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

}  // namespace

TEST(CliScenes, ListsEveryBuiltInScene) {
  const Result result = run("scenes");
  ASSERT_EQ(result.status, 0);
  for (const auto& scene : fibremss::builtInScenes())
    EXPECT_NE(result.out.find(scene.name + " "), std::string::npos) << scene.name;
  EXPECT_EQ(std::count(result.out.begin(), result.out.end(), '\n'),
            long(fibremss::builtInScenes().size()));
}

TEST(CliScenes, ExportPrintsLoadableJson) {
  const Result result = run("scenes --export fusiform");
  ASSERT_EQ(result.status, 0);
  const Json scene = Json::parse(result.out);
  EXPECT_EQ(scene["name"], "fusiform");
  EXPECT_EQ(scene["muscles"].size(), 1u);
  EXPECT_TRUE(scene["muscles"][0]["surface"].contains("generator"));
  EXPECT_NE(run("scenes --export no-such-scene 2>/dev/null").status, 0);
}

// Needs prepareScene (the preparation work) in libfibremss.
TEST(CliCheck, JsonStatisticsOfFusiform) {
  const Result result = run("check fusiform --json");
  ASSERT_EQ(result.status, 0) << result.out;
  const Json stats = Json::parse(result.out);
  for (const char* key :
       {"particles", "boundary_particles", "fixed_particles", "springs", "bone_spheres"})
    ASSERT_TRUE(stats.contains(key)) << key;
  const fibremss::LoadedScene scene = fibremss::loadScene("fusiform");
  const auto& muscle = scene.muscles.at(0);
  // Every fibre sampled at `resolution` particles.
  EXPECT_EQ(stats["particles"].get<size_t>(),
            muscle.fibres.fibreCount() * size_t(muscle.parameters.resolution));
  ASSERT_EQ(stats["muscles"].size(), scene.muscles.size());
  ASSERT_EQ(stats["bones"].size(), scene.bones.size());
  size_t particles = 0, boundary = 0, fixed = 0, springs = 0, spheres = 0;
  for (const auto& m : stats["muscles"]) {
    particles += m["particles"].get<size_t>();
    boundary += m["boundary_particles"].get<size_t>();
    fixed += m["fixed_particles"].get<size_t>();
    springs += m["springs"].get<size_t>();
    EXPECT_LT(m["boundary_particles"].get<size_t>(), m["particles"].get<size_t>());
    EXPECT_GT(m["fixed_particles"].get<size_t>(), 0u);  // attached at both bars
  }
  for (const auto& b : stats["bones"]) spheres += b["spheres"].get<size_t>();
  EXPECT_EQ(particles, stats["particles"].get<size_t>());
  EXPECT_EQ(boundary, stats["boundary_particles"].get<size_t>());
  EXPECT_EQ(fixed, stats["fixed_particles"].get<size_t>());
  EXPECT_EQ(springs, stats["springs"].get<size_t>());
  EXPECT_EQ(spheres, stats["bone_spheres"].get<size_t>());
  EXPECT_GT(spheres, 0u);
  // N-nearest springs: at least N/2 per particle (each pair is counted once).
  EXPECT_GE(springs, particles * size_t(muscle.parameters.springs.neighbours) / 2);

  // --set reaches the check: half the resolution, half the particles.
  const Result half = run("check fusiform --set resolution=20 --json");
  ASSERT_EQ(half.status, 0);
  EXPECT_EQ(Json::parse(half.out)["particles"].get<size_t>(), muscle.fibres.fibreCount() * 20);
}

TEST(CliCheck, TextOutputAndRestState) {
  const fs::path out = fs::temp_directory_path() / "fibremss_cli_check_test";
  fs::remove_all(out);
  const Result result = run("check fusiform --out \"" + out.string() + "\"");
  ASSERT_EQ(result.status, 0) << result.out;
  EXPECT_NE(result.out.find("total:"), std::string::npos);
  EXPECT_NE(result.out.find("preparation"), std::string::npos);
  EXPECT_TRUE(fs::exists(out / "rest.pvd"));
  EXPECT_TRUE(fs::exists(out / "muscle-fusiform-particles.vtp"));
  EXPECT_TRUE(fs::exists(out / "muscle-fusiform-surface.vtp"));
  EXPECT_TRUE(fs::exists(out / "muscle-fusiform-fibres.vtp"));
  EXPECT_TRUE(fs::exists(out / "bone-upper-mesh.vtp"));
  EXPECT_TRUE(fs::exists(out / "bone-lower-spheres.vtp"));
}

// The loose-ends column is explained under the table only when a muscle has loose ends.
TEST(CliCheck, LooseEndsAreExplainedOnlyWhereThereAreSome) {
  const Result loose = run("check fusiform 2>&1");
  ASSERT_EQ(loose.status, 0) << loose.out;
  EXPECT_NE(loose.out.find("(loose ends:"), std::string::npos) << loose.out;
  const Result none = run("check cylinder-stretch 2>&1");
  ASSERT_EQ(none.status, 0) << none.out;
  EXPECT_EQ(none.out.find("(loose ends:"), std::string::npos) << none.out;
}

TEST(CliCheck, BadInputFailsWithAMessage) {
  EXPECT_EQ(run("check no-such-scene 2>/dev/null").status, 2);
  EXPECT_EQ(run("check fusiform --set resolution=0 2>/dev/null").status, 2);
  EXPECT_EQ(run("check fusiform --set no_such_key=1 2>/dev/null").status, 2);
}

// Every built-in scene passes `fibremss check` at its own settings, and the main job's thigh13
// at resolution 20, without a warning about itself.
TEST(CliCheck, EveryBuiltInScenePreparesWithoutWarnings) {
  std::vector<std::pair<std::string, std::string>> checks;
  for (const auto& builtIn : fibremss::builtInScenes()) checks.emplace_back(builtIn.name, "");
  checks.emplace_back("thigh13", "resolution=20");
  for (const auto& [name, set] : checks) {
    SCOPED_TRACE(name + " " + set);
    const Result result =
        run("check " + name + (set.empty() ? "" : " --set " + set) + " --json 2>/dev/null");
    ASSERT_EQ(result.status, 0);
    const Json stats = Json::parse(result.out);
    size_t particles = 0;
    for (const auto& muscle :
         fibremss::loadScene(name, set.empty() ? std::vector<std::string>{} : std::vector{set})
             .muscles)
      particles += muscle.fibres.fibreCount() * size_t(muscle.parameters.resolution);
    EXPECT_EQ(stats["particles"].get<size_t>(), particles);
    EXPECT_GT(stats["boundary_particles"].get<size_t>(), 0u);
    EXPECT_GT(stats["springs"].get<size_t>(), 0u);
    EXPECT_EQ(stats["warnings"], Json::array()) << "none about itself";
    if (!fibremss::loadScene(name).bones.empty()) {
      EXPECT_GT(stats["bone_spheres"].get<size_t>(), 0u);
    }
  }
}

TEST(CliCheck, ThinBonePartsAndMusclesDeclaredFreeAreNoWarnings) {
  // hip-flexion's pelvis has a thin part whose sphere centres are pulled back (a repair);
  // sphere-planes' sphere is declared free at both ends and its plates are thin throughout.
  for (const char* scene : {"hip-flexion", "sphere-planes"}) {
    const Result result = run(std::string("check ") + scene + " 2>&1");
    ASSERT_EQ(result.status, 0) << scene << "\n" << result.out;
    EXPECT_EQ(result.out.find("warning"), std::string::npos) << scene << "\n" << result.out;
    EXPECT_NE(result.out.find("sphere centres pulled back inside a thin part"), std::string::npos)
        << scene << "\n"
        << result.out;
  }
}

TEST(CliScenes, ExportAppliesOverrides) {
  const Result result = run("scenes --export thigh13 --set resolution=80 --set kappa=3");
  ASSERT_EQ(result.status, 0);
  const Json scene = Json::parse(result.out);
  for (const auto& muscle : scene["muscles"]) EXPECT_EQ(muscle["resolution"], 80);
  EXPECT_EQ(scene["model"]["kappa"], 3.0);
}

TEST(CliConventions, BareFibremssPrintsTheHelp) {
  const Result result = run("");
  EXPECT_EQ(result.status, 0);
  EXPECT_NE(result.out.find("Usage: fibremss [OPTIONS] SUBCOMMAND"), std::string::npos)
      << result.out;
  for (const char* command : {"run", "compare", "check", "Exit codes"})
    EXPECT_NE(result.out.find(command), std::string::npos) << command << "\n" << result.out;
}

TEST(CliConventions, MistypedNamesAreNamedWithTheClosestValidOneRepeatsAreRefused) {
  const std::pair<const char*, const char*> cases[] = {
      {"frobnicate", "unknown subcommand 'frobnicate' Subcommands: scenes, check, run"},
      {"rnu fusiform", "unknown subcommand 'rnu'; did you mean 'run'?"},
      {"check thigh14", "did you mean 'thigh13'?"},
      {"scenes --export fusifrom", "did you mean 'fusiform'?"},
      {"check fusiform --set resolutoin=10", "unknown key; did you mean 'resolution'?"},
      {"check fusiform --set model.kapa=1", "unknown field; did you mean 'kappa'?"},
      {"run fusiform --frame-every 1 --frame-every 2",
       "--frame-every: given more than once; give it once"}};
  for (const auto& [arguments, expected] : cases) {
    const Result result = run(std::string(arguments) + " 2>&1");
    EXPECT_EQ(result.status, 2) << arguments << "\n" << result.out;
    EXPECT_NE(result.out.find(expected), std::string::npos) << arguments << "\n" << result.out;
  }
}

TEST(CliConventions, EnumOptionsListTheirChoices) {
  const Result help = run("reference --help");
  EXPECT_NE(help.out.find("--ccx-element C3D4|C3D10"), std::string::npos) << help.out;
  EXPECT_NE(help.out.find("--ccx-sliding finite|small"), std::string::npos) << help.out;
  EXPECT_EQ(help.out.find("->"), std::string::npos) << help.out;
  const Result bad = run("reference fusiform --ccx-element C3D8 2>&1");
  EXPECT_EQ(bad.status, 2);
  EXPECT_NE(bad.out.find("expected one of C3D10, C3D4, got C3D8"), std::string::npos) << bad.out;
  const Result format = run("run --help");
  EXPECT_NE(format.out.find("--format vtk|gltf"), std::string::npos) << format.out;
  const Result badFormat = run("run fusiform --format obj 2>&1");
  EXPECT_EQ(badFormat.status, 2);
  EXPECT_NE(badFormat.out.find("expected one of vtk, gltf, got obj"), std::string::npos)
      << badFormat.out;
}

TEST(CliConventions, FlagsThatTurnSomethingOffReadAsTheyAreTyped) {
  const Result help = run("compare --help");
  for (const char* flag : {"--no-fronts ", "--no-reference ", "--no-gates "})
    EXPECT_NE(help.out.find(flag), std::string::npos) << flag << "\n" << help.out;
  EXPECT_EQ(help.out.find("{false}"), std::string::npos) << help.out;
}

TEST(CliConventions, OneTableOfExitCodesInTheHelpTheReadmeAndTheDocs) {
  const std::string help = run("--help").out;
  // Every subcommand's help ends with the same table, after its own footer.
  for (const char* command :
       {"scenes", "check", "run", "compare", "merge", "fibres", "stability", "reference", "view"}) {
    const std::string own = run(std::string(command) + " --help").out;
    EXPECT_NE(own.find("Exit codes (every subcommand): 0 done"), std::string::npos)
        << command << "\n"
        << own;
  }
  auto read = [](const char* relative) {
    std::ifstream in(fs::path(FIBREMSS_SOURCE_DIR) / relative);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  const std::string readme = read("README.md"), docs = read("docs/bad-inputs.md");
  for (const char* code : {"0 done", "1 an internal error", "2 bad input", "3 a run", "4 a run",
                           "130 interrupted", "143 by SIGTERM"}) {
    EXPECT_NE(help.find(code), std::string::npos) << code;
    EXPECT_NE(readme.find(code), std::string::npos) << code;
  }
  for (const char* row : {"| 0 |", "| 1 |", "| 2 |", "| 3 |", "| 4 |", "| 130, 143 |"})
    EXPECT_NE(docs.find(row), std::string::npos) << row;
}
