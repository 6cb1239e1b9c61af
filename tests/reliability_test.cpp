// Reliability, second part: hostile inputs beyond the bad-input catalogue's classes. One test
// (or two: CLI and API) per row of the table; docs/bad-inputs.md
// lists them with the exit codes.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "fibremss/Error.h"
#include "fibremss/MeshIO.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Output.h"
#include "fibremss/Scene.h"
#include "support/GridMuscle.h"
#include "support/HostileFiles.h"
#include "support/Process.h"
#include "support/SolverFixtures.h"

namespace fibremss {
namespace {

namespace fs = std::filesystem;
using testing::cli;
using testing::cubeObj;
using testing::filesIn;
using testing::ProcessResult;
using testing::TemporaryDirectory;
using testing::writeFile;
using testing::writeScene;

// --- Row 1: initial_noise = 1e16 mm, a scene scaled by 1e12 --------------------------------

TEST(Reliability2, HugeInitialNoiseIsAClearErrorNotHeapCorruption) {
  const ProcessResult result = cli("run fusiform --set initial_noise=1e16 --steps 1");
  EXPECT_EQ(result.exitCode, 2) << result.output;
  EXPECT_NE(result.output.find("simulation.initial_noise"), std::string::npos) << result.output;
}

TEST(Reliability2, ASceneScaledBy1e12IsRefusedBeforeAnyTree) {
  TemporaryDirectory dir("fibremss_scaled");
  const fs::path scene = writeScene(dir.path(), 1e12);
  const ProcessResult result = cli("run " + scene.string() + " --steps 1");
  EXPECT_EQ(result.exitCode, 2) << result.output;
  EXPECT_NE(result.output.find("within 1e6 m"), std::string::npos) << result.output;
}

TEST(Reliability2, MuscleSystemRefusesPointsBeyondTheWorldBeforeBuildingTrees) {
  MuscleSystemDef noisy;
  noisy.initialNoise = btScalar(1e13);  // 1e16 mm
  EXPECT_THROW(MuscleSystem{noisy}, InputError);
  MuscleSystem system;
  auto far = testing::makeSpheres({{0, 0, 0}, {btScalar(1e13), 0, 0}}, {0.001f, 0.001f});
  EXPECT_THROW(system.addMuscle(far, {}), InputError);
  auto nanRadius = testing::makeSpheres({{0, 0, 0}}, {std::numeric_limits<btScalar>::quiet_NaN()});
  EXPECT_THROW(system.addMuscle(nanRadius, {}), InputError);
  EXPECT_THROW(system.addBone(testing::makeBone({{btScalar(1e13), 0, 0}}, {0.01f})), InputError);
  EXPECT_TRUE(system.muscles().empty());
  EXPECT_TRUE(system.bones().empty());
}

// --- Row 2: addMuscle while a bone's transform is NaN ---------------------------------------

TEST(Reliability2, AddMuscleOnABoneWithANanTransformIsAnInputError) {
  MuscleSystem system;
  const BoneHandle bone = system.addBone(testing::makeBone());
  const btScalar nan = std::numeric_limits<btScalar>::quiet_NaN();
  system.setBoneTransform(bone, btTransform(btQuaternion::getIdentity(), btVector3(nan, 0, 0)));
  auto muscle = testing::makeSpheres({{0, 0, 0}, {0.01f, 0, 0}}, {0.004f, 0.004f});
  testing::fix(*muscle, 0, 0);
  try {
    system.addMuscle(muscle, std::span(&bone, 1));
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("non-finite transform"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(system.muscles().empty());
}

// --- Row 3: scene JSON nested 100 000 levels deep -------------------------------------------

TEST(Reliability2, DeeplyNestedJsonIsRefusedWithABoundedMessage) {
  TemporaryDirectory dir("fibremss_deep");
  const std::string deep = std::string(100000, '[') + std::string(100000, ']');
  writeFile(dir.path() / "deep.json", R"({"name": )" + deep + "}");
  const ProcessResult result = cli("check " + (dir.path() / "deep.json").string());
  EXPECT_EQ(result.exitCode, 2) << result.output.substr(0, 500);
  EXPECT_NE(result.output.find("nested deeper than 100 levels"), std::string::npos);
  EXPECT_LT(result.output.size(), 2000u);
  // A deep value that is not nested too deep still prints as a bounded excerpt.
  writeFile(dir.path() / "wide.json",
            R"({"name": )" + std::string(90, '[') + std::string(90, ']') + "}");
  try {
    loadScene((dir.path() / "wide.json").string());
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(e.where(), "name");
    EXPECT_LT(e.problem().size(), 120u) << e.problem();
  }
}

// --- Row 4: a PLY header declaring 2 000 000 000 vertices -----------------------------------

TEST(Reliability2, APlyHeaderDeclaringMoreThanTheFileHoldsIsRefusedAtOnce) {
  TemporaryDirectory dir("fibremss_ply");
  const fs::path ply = dir.path() / "bone.ply";
  writeFile(ply,
            "ply\nformat binary_little_endian 1.0\nelement vertex 2000000000\nproperty float x\n"
            "property float y\nproperty float z\nelement face 1\nproperty list uchar int "
            "vertex_indices\nend_header\n" +
                std::string(200, '\0'));
  const auto start = std::chrono::steady_clock::now();
  try {
    loadSurface(ply.string(), 0.001);
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("declares 2000000000 elements"), std::string::npos)
        << e.what();
  }
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 5);
  // Through a scene, as a user meets it.
  const fs::path scene = writeScene(dir.path(), 1, "", "bone.ply");
  const ProcessResult result = cli("check " + scene.string());
  EXPECT_EQ(result.exitCode, 2) << result.output;
  EXPECT_NE(result.output.find("bytes follow the header"), std::string::npos) << result.output;
}

TEST(Reliability2, AnOffHeaderDeclaringMoreThanTheFileHoldsIsRefused) {
  TemporaryDirectory dir("fibremss_off");
  const fs::path off = dir.path() / "bone.off";
  const std::string body = "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
  writeFile(off, "OFF\n# a tetrahedron\n4 4 0\n" + body);
  EXPECT_EQ(loadSurface(off.string(), 0.001).triangles.size(), 4u);  // an honest header loads
  writeFile(off, "OFF\n# a tetrahedron\n200000000 4 0\n" + body);
  try {
    loadSurface(off.string(), 0.001);
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("declares 200000000 vertices"), std::string::npos)
        << e.what();
  }
}

// --- Row 5: VTK with 2 000 000 empty POLYGONS cells -----------------------------------------

TEST(Reliability2, SkippedVtkCellsAreCountedNotListed) {
  TemporaryDirectory dir("fibremss_vtkcells");
  constexpr int kEmpty = 2000000;
  std::string vtk =
      "# vtk DataFile Version 3.0\ncube\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n"
      "0 0 0\n10 0 0\n0 10 0\n0 0 10\n";
  vtk += "POLYGONS " + std::to_string(kEmpty + 4) + " " + std::to_string(kEmpty + 16) + "\n";
  vtk += "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
  for (int i = 0; i < kEmpty; ++i) vtk += "0\n";
  writeFile(dir.path() / "bone.vtk", vtk);
  MeshReport report;
  loadSurface((dir.path() / "bone.vtk").string(), 0.001, &report);
  EXPECT_LE(report.warnings.size(), 20u);
  bool summed = false;
  for (const std::string& warning : report.warnings)
    summed = summed || warning.find("and " + std::to_string(kEmpty - 10) + " more cells") !=
                           std::string::npos;
  EXPECT_TRUE(summed);
  // As `check` prints them: a handful of lines, not two million.
  const fs::path scene = writeScene(dir.path(), 1, "", "bone.vtk");
  const ProcessResult result = cli("check " + scene.string());
  EXPECT_EQ(result.exitCode, 0) << result.output.substr(0, 2000);
  EXPECT_LT(std::count(result.output.begin(), result.output.end(), '\n'), 60);
}

// --- Row 6: the guard with a NaN bone pose --------------------------------------------------

class NanBonePose : public ::testing::TestWithParam<FailurePolicy> {};

TEST_P(NanBonePose, MusclesStayFiniteTheStepReportsNanAndRecoversWithTheBone) {
  MuscleSystemDef parameters;
  parameters.onFailure = GetParam();
  parameters.stepSettings.iterations = 10;
  MuscleSystem system(parameters);
  const BoneHandle bones[] = {system.addBone(testing::cubeBone("left", btVector3(-0.02f, 0, 0))),
                              system.addBone(testing::cubeBone("right", btVector3(0.02f, 0, 0)))};
  const MuscleHandle muscle = system.addMuscle(testing::gridMuscle(), bones);
  system.step();
  const btScalar nan = std::numeric_limits<btScalar>::quiet_NaN();
  const btTransform moved(btQuaternion::getIdentity(), btVector3(0.002f, 0, 0));
  system.setBoneTransform(bones[1], btTransform(btQuaternion::getIdentity(), btVector3(nan, 0, 0)));
  system.step();
  const StepStats& bad = system.lastStep();
  EXPECT_TRUE(bad.nan);
  EXPECT_TRUE(bad.failed);
  EXPECT_TRUE(bad.failedNan);
  EXPECT_EQ(bad.heldBones, 1u);
  auto finite = [](const btVector3& p) { return std::isfinite(p.length2()); };
  for (const btVector3& p : system.positions(muscle)) ASSERT_TRUE(finite(p));
  EXPECT_TRUE(finite(system.boneTransform(bones[1]).getOrigin()));
  // The bone fixed: the muscle follows it again, finite, nothing reported.
  system.setBoneTransform(bones[1], moved);
  system.step();
  EXPECT_FALSE(system.lastStep().nan);
  EXPECT_FALSE(system.lastStep().failed);
  EXPECT_EQ(system.lastStep().heldBones, 0u);
  for (const btVector3& p : system.positions(muscle)) ASSERT_TRUE(finite(p));
  EXPECT_FALSE(system.frozen(muscle));
  EXPECT_EQ(system.boneTransform(bones[1]).getOrigin(), moved.getOrigin());
}

INSTANTIATE_TEST_SUITE_P(Policies, NanBonePose,
                         ::testing::Values(FailurePolicy::Retry, FailurePolicy::StopBody,
                                           FailurePolicy::Report));

// --- Row 7: values that pass in double but narrow to float 0 or inf -------------------------

TEST(Reliability2, RangesAreCheckedOnTheStoredType) {
  std::ostringstream tiny;  // positive in double, 0 or a denormal in btScalar
  tiny << std::setprecision(3) << double(std::numeric_limits<btScalar>::min()) / 1000;
  std::vector<std::pair<std::string, std::string>> cases = {
      {"dt=" + tiny.str(), "simulation.dt"}, {"density=" + tiny.str(), "model.density"}};
  if (sizeof(btScalar) == sizeof(float)) cases.push_back({"kappa=1e39", "model.kappa"});
  for (const auto& [set, field] : cases) {
    const ProcessResult result = cli("check fusiform --set '" + set + "'");
    EXPECT_EQ(result.exitCode, 2) << set << ": " << result.output;
    EXPECT_NE(result.output.find(field), std::string::npos) << set << ": " << result.output;
    EXPECT_NE(result.output.find("btScalar"), std::string::npos) << result.output;
  }
}

// --- Row 8: `run` on a scene that fails preparation writes nothing ---------------------------

TEST(Reliability2, ARunThatFailsPreparationWritesNothing) {
  TemporaryDirectory dir("fibremss_noprep");
  const fs::path out = dir.path() / "out";
  fs::create_directories(out / "frames");
  writeFile(out / "frames" / "older_00000.vtp", "an older run's frame");
  const std::vector<std::string> before = filesIn(out);
  const ProcessResult result =
      cli("run " + writeScene(dir.path()).string() + " --set neighbours=900 --out " + out.string());
  EXPECT_EQ(result.exitCode, 2) << result.output;
  EXPECT_EQ(filesIn(out), before);
  // A directory that cannot be written is refused before preparing, also writing nothing.
  const ProcessResult blocked =
      cli("run fusiform --out " + (out / "frames" / "older_00000.vtp" / "x").string());
  EXPECT_EQ(blocked.exitCode, 2) << blocked.output;
  EXPECT_EQ(blocked.output.find("preparing"), std::string::npos) << blocked.output;
}

// --- Row 9: a FIFO named bone.obj ------------------------------------------------------------

TEST(Reliability2, AFifoIsRejectedAsNotARegularFileBeforeOpening) {
  TemporaryDirectory dir("fibremss_fifo");
  const fs::path scene = writeScene(dir.path());
  fs::remove(dir.path() / "bone.obj");
  ASSERT_EQ(::mkfifo((dir.path() / "bone.obj").c_str(), 0600), 0);
  EXPECT_THROW(loadSurface((dir.path() / "bone.obj").string(), 0.001), InputError);
  const ProcessResult result = cli("check " + scene.string());  // would hang before
  EXPECT_EQ(result.exitCode, 2) << result.output;
  EXPECT_NE(result.output.find("expected a regular file"), std::string::npos) << result.output;
}

// --- Row 10: muscles named "a b" and "a_b" with check --out ----------------------------------

TEST(Reliability2, MuscleNamesThatMapToOneFileNameGetDistinctFiles) {
  TemporaryDirectory dir("fibremss_names");
  writeScene(dir.path());
  writeFile(dir.path() / "other.obj", cubeObj(20, 40));
  std::string fibres;
  for (int f = 0; f < 4; ++f)
    fibres += "v 40.5 " + std::to_string(5 + 10 * (f & 1)) + " " +
              std::to_string(5 + 10 * (f >> 1)) + "\nv 59.5 " + std::to_string(5 + 10 * (f & 1)) +
              " " + std::to_string(5 + 10 * (f >> 1)) + "\n";
  writeFile(dir.path() / "other_fibres.obj", fibres + "l 1 2\nl 3 4\nl 5 6\nl 7 8\n");
  writeFile(dir.path() / "two.json", R"({"units": "mm",
    "bones": [{"name": "cube", "mesh": {"file": "bone.obj"}}],
    "muscles": [{"name": "a b", "surface": {"file": "muscle.obj"},
                 "fibres": {"file": "fibres.obj"}, "resolution": 5, "free_end": "insertion"},
                {"name": "a_b", "surface": {"file": "other.obj"},
                 "fibres": {"file": "other_fibres.obj"}, "resolution": 5, "free_end": "both"}]})");
  const fs::path out = dir.path() / "out";
  const ProcessResult result =
      cli("check " + (dir.path() / "two.json").string() + " --out " + out.string());
  ASSERT_EQ(result.exitCode, 0) << result.output;
  int surfaces = 0;
  for (const std::string& file : filesIn(out))
    surfaces += file.find("-surface.vtp") != std::string::npos ? 1 : 0;
  EXPECT_EQ(surfaces, 2);
  std::string pvd;
  std::getline(std::ifstream(out / "rest.pvd"), pvd, '\0');
  EXPECT_NE(pvd.find("muscle-a_b-surface.vtp"), std::string::npos);
  EXPECT_NE(pvd.find("muscle-a_b-1-surface.vtp"), std::string::npos);
}

// --- Row 11: two runs into one --out at once -------------------------------------------------

TEST(Reliability2, ASecondWriterIntoALockedOutputDirectoryIsRefused) {
  TemporaryDirectory dir("fibremss_lock");
  const fs::path out = dir.path() / "out";
  {
    const OutputDirectory first(out.string());  // as a running `fibremss run` holds it
    EXPECT_THROW(OutputDirectory{out.string()}, InputError);
    const ProcessResult second = cli("run fusiform --steps 1 --out " + out.string());
    EXPECT_EQ(second.exitCode, 2) << second.output;
    EXPECT_NE(second.output.find("another fibremss process is writing"), std::string::npos)
        << second.output;
    EXPECT_FALSE(fs::exists(out / "scene.json"));
  }
  const ProcessResult after =
      cli("run fusiform --steps 1 --frame-every 0 --set resolution=6 --out " + out.string());
  EXPECT_EQ(after.exitCode, 0) << after.output;
  EXPECT_TRUE(fs::exists(out / "summary.json"));
  EXPECT_FALSE(fs::exists(out / ".fibremss.lock"));  // a clean exit leaves no lock file
}

TEST(Reliability2, EverySubcommandThatWritesADirectoryTakesItsLock) {
  TemporaryDirectory dir("fibremss_lock_all");
  const fs::path done = dir.path() / "done", out = dir.path() / "out";
  const std::string compare =
      "compare fusiform --no-fronts --no-reference --methods fibremss --set resolution=6";
  ASSERT_EQ(cli(compare + " --out " + done.string()).exitCode, 0);
  const OutputDirectory first(out.string());  // as a running writer holds it
  for (const std::string& command : std::vector<std::string>{
           compare, "reference fusiform --no-gates --set resolution=6", "merge " + done.string()}) {
    const ProcessResult second = cli(command + " --out " + out.string());
    EXPECT_EQ(second.exitCode, 2) << command << "\n" << second.output;
    EXPECT_NE(second.output.find("another fibremss process is writing"), std::string::npos)
        << command << "\n"
        << second.output;
  }
  for (const char* file : {"summary.json", "report.md", "reference.json", "stability.json"})
    EXPECT_FALSE(fs::exists(out / file)) << file;
  // Unlocked, the same summary (with its per-muscle list) merges.
  const ProcessResult merged =
      cli("merge " + done.string() + " --out " + (dir.path() / "m").string());
  EXPECT_EQ(merged.exitCode, 0) << merged.output;
}

// --- Row 12: duplicate JSON keys -------------------------------------------------------------

TEST(Reliability2, DuplicateJsonKeysAreAnErrorNamingTheKey) {
  TemporaryDirectory dir("fibremss_dupkeys");
  const fs::path scene = writeScene(dir.path(), 1, R"(, "model": {"kappa": 2, "kappa": 3})");
  try {
    loadScene(scene.string());
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(e.where(), "model.kappa");
    EXPECT_NE(e.problem().find("duplicate key"), std::string::npos);
  }
  std::string json;
  std::getline(std::ifstream(scene), json, '\0');
  json.replace(json.find("\"resolution\": 5"), 15, R"("resolution": 5, "resolution": 6)");
  writeFile(scene, json);
  const ProcessResult result = cli("check " + scene.string());
  EXPECT_EQ(result.exitCode, 2) << result.output;
  EXPECT_NE(result.output.find("muscles[0].resolution: duplicate key"), std::string::npos)
      << result.output;
}

// --- Row 13: --set with an index beyond unsigned long ----------------------------------------

TEST(Reliability2, AHugeSetIndexIsARangeError) {
  const ProcessResult result = cli("check fusiform --set muscles.99999999999999999999999.x=5");
  EXPECT_EQ(result.exitCode, 2) << result.output;
  EXPECT_NE(result.output.find("muscles has 1 elements; no [99999999999999999999999]"),
            std::string::npos)
      << result.output;
}

// --- Row 14 and the exit-code table: every usage error exits 2 with a readable range ----------

TEST(Reliability2, EveryUsageErrorExitsWithCode2) {
  const std::vector<std::string> usage = {"no-such-command",
                                          "run fusiform --steps -1",
                                          "run fusiform --threads abc",
                                          "run fusiform extra-argument",
                                          "run fusiform --frame-every 1.5",
                                          "check fusiform extra-argument",
                                          "check",
                                          "scenes --no-such-flag",
                                          "compare fusiform --fem-cells 0",
                                          "compare fusiform --method-budget -3",
                                          "merge",
                                          "fibres",
                                          "fibres muscle.obj --count 0 --out x.vtk",
                                          "stability --cell-seconds 0",
                                          "stability --dt-factors 1,-2"};
  for (const std::string& arguments : usage) {
    const ProcessResult result = cli(arguments);
    EXPECT_EQ(result.exitCode, 2) << "fibremss " << arguments << ": " << result.output;
  }
  const ProcessResult steps = cli("run fusiform --steps -1");
  EXPECT_NE(steps.output.find("expected an integer >= 0, got -1"), std::string::npos)
      << steps.output;
  EXPECT_EQ(steps.output.find("1.797"), std::string::npos) << steps.output;
  EXPECT_EQ(cli("--help").exitCode, 0);
  EXPECT_EQ(cli("run --help").exitCode, 0);
}

// --- Row 15: merge of malformed summaries ----------------------------------------------------

TEST(Reliability2, MergingMalformedSummariesIsAnInputError) {
  TemporaryDirectory dir("fibremss_merge");
  const std::vector<std::pair<std::string, std::string>> bad = {
      {R"({"runs": [{"method": "fibremss", "nan": "yes"}]})", "runs[0].nan"},
      {R"({"runs": [{"method": "fibremss", "timing": {"mss": "fast"}}]})", "runs[0].timing.mss"},
      {R"({"runs": [7]})", "runs[0]"},
      {R"({"runs": []})", "no runs"},
      {R"({"runs": [{"method": "fibremss"}], "machine": {"cpu": 5}})", "machine"},
      {R"({"runs": 3})", "runs"},
      {R"({"runs": [{"method": "fibremss", "muscles": [{"frozen": 1}]}]})",
       "runs[0].muscles[0].frozen"},
      {R"({"runs": [{"method": "fibremss", "muscles": [{"fixed_particles": {"femur": "x"}}]}]})",
       "runs[0].muscles[0].fixed_particles.femur"},
      {R"({"runs": [{"method": "fibremss", "muscles": {}}]})", "runs[0].muscles"},
      {R"({"runs": [{"method": "fibremss", "series": [{"step": 0, "time_s": "late"}]}]})",
       "runs[0].series[0].time_s"},
      {R"({"runs": [{"method": "fibremss", "series": 5}]})", "runs[0].series"},
      {"not json", "not valid JSON"}};
  for (size_t i = 0; i < bad.size(); ++i) {
    const fs::path file = dir.path() / ("summary" + std::to_string(i) + ".json");
    writeFile(file, bad[i].first);
    const fs::path out = dir.path() / ("merged" + std::to_string(i));
    const ProcessResult result = cli("merge " + file.string() + " --out " + out.string());
    EXPECT_EQ(result.exitCode, 2) << bad[i].first << ": " << result.output;
    EXPECT_NE(result.output.find(bad[i].second), std::string::npos) << result.output;
    EXPECT_FALSE(fs::exists(out)) << bad[i].first;
  }
}

// --- Row 16: stability with a bad scene file --------------------------------------------------

TEST(Reliability2, StabilityRefusesBadInputBeforeAnyWork) {
  TemporaryDirectory dir("fibremss_stability");
  writeFile(dir.path() / "bad.json", R"({"muscles": [{"resolutoin": 5}]})");
  const fs::path out = dir.path() / "out";
  const auto start = std::chrono::steady_clock::now();
  const ProcessResult result =
      cli("stability " + (dir.path() / "bad.json").string() + " --out " + out.string());
  EXPECT_EQ(result.exitCode, 2) << result.output;
  EXPECT_NE(result.output.find("bad.json: muscles[0]"), std::string::npos) << result.output;
  EXPECT_EQ(result.output.find("calibrating"), std::string::npos) << result.output;
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 30);
  EXPECT_FALSE(fs::exists(out));
}

// --- Row 17: FIBREMSS_MEMORY_LIMIT_MB that is no limit ----------------------------------------

TEST(Reliability2, AMemoryLimitThatIsNotAWholePositiveNumberIsRefused) {
  for (const std::string value : {"-5", "0", "abc", "12x", ""}) {
    const ProcessResult limited =
        testing::runProcess("FIBREMSS_MEMORY_LIMIT_MB='" + value + "' \"" + FIBREMSS_CLI +
                            "\" check fusiform --set resolution=4 2>&1");
    EXPECT_EQ(limited.exitCode, 2) << value << ": " << limited.output;
    EXPECT_NE(limited.output.find("FIBREMSS_MEMORY_LIMIT_MB"), std::string::npos) << limited.output;
  }
  const ProcessResult fine =
      testing::runProcess("FIBREMSS_MEMORY_LIMIT_MB=4096 \"" + std::string(FIBREMSS_CLI) +
                          "\" check fusiform --set resolution=4 2>&1");
  EXPECT_EQ(fine.exitCode, 0) << fine.output;
}

// --- Row 18: stop=budget, the one exception to bit-identical results --------------------------

TEST(Reliability2, TheBudgetStopRuleSaysItIsNotBitIdentical) {
  const LoadedScene scene = loadScene("fusiform", {"stop=budget"});
  bool warned = false;
  for (const std::string& warning : scene.warnings)
    warned = warned || warning.find("not bit-identical") != std::string::npos;
  EXPECT_TRUE(warned);
  for (const std::string& warning : loadScene("fusiform").warnings)
    EXPECT_EQ(warning.find("bit-identical"), std::string::npos) << warning;
  const ProcessResult result = cli("check fusiform --set stop=budget --set resolution=4");
  EXPECT_EQ(result.exitCode, 0) << result.output;
  EXPECT_NE(result.output.find("not bit-identical"), std::string::npos) << result.output;
}

// --- Row 19: the library API: dt, junk handles, removing a bone in use -----------------------

TEST(Reliability2, AFixedTimeStepOfZeroOrBelowIsAnInputError) {
  for (const btScalar dt :
       {btScalar(-0.001), btScalar(0), std::numeric_limits<btScalar>::quiet_NaN()}) {
    MuscleSystemDef parameters;
    parameters.stepSettings.adaptiveTimeStep = false;
    parameters.stepSettings.timeStep = dt;
    EXPECT_THROW(MuscleSystem{parameters}, InputError) << dt;
    MuscleSystem system;
    system.addMuscle(testing::makeSpheres({{0, 0, 0}}, {0.001f}), {});
    StepSettings settings = system.stepSettings();
    settings.adaptiveTimeStep = false;
    settings.timeStep = dt;
    EXPECT_THROW(system.setStepSettings(settings), InputError) << dt;
    EXPECT_TRUE(system.stepSettings().adaptiveTimeStep);  // the previous settings kept
    EXPECT_EQ(system.stepSettings().timeStep, StepSettings{}.timeStep);
    system.step();
    EXPECT_EQ(system.lastStep().step, 0u);
  }
}

TEST(Reliability2, AnL_BfgsHistoryBeyondItsBuffersIsAnInputError) {
  for (const int pairs : {-1, kMaxProjectiveHistory + 1}) {
    MuscleSystemDef parameters;
    parameters.projectiveHistory = pairs;
    EXPECT_THROW(MuscleSystem{parameters}, InputError) << pairs;
    parameters.projectiveHistory = kMaxProjectiveHistory;
    MuscleSystem system(parameters);
    system.addMuscle(testing::makeSpheres({{0, 0, 0}}, {0.001f}), {});
    system.step();
    EXPECT_EQ(system.lastStep().step, 0u);
  }
}

TEST(Reliability2, JunkAndStaleHandlesAreInputErrors) {
  MuscleSystem system;
  const BoneHandle bone = system.addBone(testing::makeBone());
  const MuscleHandle muscle = system.addMuscle(testing::makeSpheres({{0, 0, 0}}, {0.001f}), {});
  const MuscleHandle junk{42, 7};
  EXPECT_THROW(system.positions(junk), InputError);
  EXPECT_THROW(system.removeMuscle(junk), InputError);
  EXPECT_THROW(system.removeBone(BoneHandle{9, 0}), InputError);
  EXPECT_THROW(system.setBoneTransform(BoneHandle{bone.index, bone.generation + 1},
                                       btTransform::getIdentity()),
               InputError);
  system.removeMuscle(muscle);
  EXPECT_THROW(system.removeMuscle(muscle), InputError);  // stale: its generation moved on
  system.removeBone(bone);
  const BoneHandle reused = system.addBone(testing::makeBone());
  ASSERT_EQ(reused.index, bone.index);
  auto attached = testing::makeSpheres({{0, 0, 0}}, {0.001f});
  testing::fix(*attached, 0, 0);
  EXPECT_THROW(system.addMuscle(attached, std::span(&bone, 1)), InputError);  // the old bone
  EXPECT_NO_THROW(system.addMuscle(attached, std::span(&reused, 1)));
}

TEST(Reliability2, RemovingABoneAMuscleIsAttachedToIsAnInputError) {
  MuscleSystem system;
  const BoneHandle bone = system.addBone(testing::makeBone());
  auto settings = testing::makeSpheres({{0, 0, 0}, {0.01f, 0, 0}}, {0.004f, 0.004f});
  testing::fix(*settings, 0, 0);
  const MuscleHandle muscle = system.addMuscle(settings, std::span(&bone, 1));
  try {
    system.removeBone(bone);
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("muscle 'spheres' is attached"), std::string::npos)
        << e.what();
  }
  EXPECT_EQ(system.bones().size(), 1u);
  system.removeMuscle(muscle);
  EXPECT_NO_THROW(system.removeBone(bone));
}

// --- Row 20: temporaries a SIGKILLed run left ------------------------------------------------

TEST(Reliability2, TemporariesAKilledRunLeftAreRemovedByTheNextRun) {
  TemporaryDirectory dir("fibremss_tmp");
  const fs::path out = dir.path() / "out";
  fs::create_directories(out / "frames");
  writeFile(out / "frames" / "muscle0_box_surface_00003.vtp.tmp.4242.17", "<VTKFile half");
  writeFile(out / "summary.json.tmp.4242.18", "{");
  writeFile(out / ".fibremss.lock", "4242\n");  // the killed writer's process id
  writeFile(out / "notes.tmp.txt", "the user's own file");
  const ProcessResult result =
      cli("run fusiform --steps 1 --set resolution=6 --out " + out.string());
  EXPECT_EQ(result.exitCode, 0) << result.output;
  EXPECT_NE(result.output.find("removed 2 temporary file(s)"), std::string::npos) << result.output;
  for (const std::string& file : filesIn(out))
    EXPECT_EQ(file.find(".tmp.4242"), std::string::npos) << file;
  EXPECT_TRUE(fs::exists(out / "notes.tmp.txt"));
}

}  // namespace
}  // namespace fibremss
