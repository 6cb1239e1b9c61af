// `fibremss run`: the summary has every key with sensible values, the frames are complete
// ParaView files, Ctrl-C stops cleanly with the summary saying so, bad input is an error.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "fibremss/FibreRun.h"
#include "fibremss/ImplicitSurface.h"
#include "fibremss/Kernel.h"
#include "fibremss/Progress.h"
#include "fibremss/VtkFiles.h"
#include "support/Process.h"

namespace fibremss {
namespace {

namespace fs = std::filesystem;
using testing::runProcess;
using testing::TemporaryDirectory;

std::string readFile(const fs::path& path) {
  std::ifstream file(path, std::ios::binary);
  std::stringstream text;
  text << file.rdbuf();
  return text.str();
}

std::string trimmed(std::string text) {
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) text.pop_back();
  return text;
}

/// A .vtp is complete: a closed PolyData VTKFile with at least one point whose appended data
/// holds the Points array's compressed blocks in full (tests/frames_vtk_test.py reads the values
/// with VTK and ParaView).
void expectWellFormedVtp(const fs::path& path) {
  SCOPED_TRACE(path.string());
  const std::string text = readFile(path);
  ASSERT_NE(text.find("<VTKFile type=\"PolyData\""), std::string::npos);
  EXPECT_TRUE(trimmed(text).ends_with("</AppendedData>\n</VTKFile>"));
  std::smatch match;
  ASSERT_TRUE(std::regex_search(text, match, std::regex("NumberOfPoints=\"([0-9]+)\"")));
  EXPECT_GT(std::stoul(match[1]), 0u);
  const size_t pointsTag = text.find("<Points>");
  ASSERT_NE(pointsTag, std::string::npos);
  const std::string tag = text.substr(pointsTag, text.find("/>", pointsTag) - pointsTag);
  ASSERT_TRUE(std::regex_search(tag, match, std::regex("offset=\"([0-9]+)\"")));
  const size_t data = text.find('_', text.find("<AppendedData")) + 1 + std::stoul(match[1]);
  uint64_t header[3];  // block count, block size, partial block: then one size per block
  ASSERT_LE(data + sizeof header, text.size());
  std::memcpy(header, text.data() + data, sizeof header);
  ASSERT_GT(header[0], 0u);
  std::vector<uint64_t> sizes(header[0]);
  ASSERT_LE(data + 8 * (3 + header[0]), text.size());
  std::memcpy(sizes.data(), text.data() + data + sizeof header, 8 * header[0]);
  uint64_t total = 8 * (3 + header[0]);
  for (uint64_t size : sizes) total += size;
  EXPECT_LE(data + total, text.size());
}

/// The .pvd is a closed Collection; returns the files it lists (relative to it) by timestep.
std::multimap<double, std::string> pvdDataSets(const fs::path& pvd) {
  const std::string text = readFile(pvd);
  EXPECT_NE(text.find("<VTKFile type=\"Collection\""), std::string::npos);
  EXPECT_TRUE(trimmed(text).ends_with("</VTKFile>"));
  std::multimap<double, std::string> sets;
  const std::regex dataSet("<DataSet[^>]*timestep=\"([^\"]+)\"[^>]*file=\"([^\"]+)\"");
  for (auto it = std::sregex_iterator(text.begin(), text.end(), dataSet);
       it != std::sregex_iterator(); ++it)
    sets.emplace(std::stod((*it)[1]), (*it)[2]);
  return sets;
}

std::string cli() {
  return FIBREMSS_CLI;
}

/// The summary of two steps of fusiform: its settings and every figure finite and in range.
void expectTwoStepSummary(const nlohmann::json& summary) {
  EXPECT_EQ(summary.at("scene"), "fusiform");
  EXPECT_EQ(summary.at("method"), "fibremss");
  EXPECT_FALSE(summary.at("integrator").get<std::string>().empty());
  EXPECT_EQ(summary.at("steps"), 2);
  // simulation.threads 0: the machine's hardware threads, recorded as resolved.
  EXPECT_EQ(summary.at("threads"), std::max(1u, std::thread::hardware_concurrency()));
  for (const char* key :
       {"particles", "springs", "boundary_particles", "bone_spheres", "iterations"})
    EXPECT_GT(summary.at(key).get<double>(), 0) << key;
  EXPECT_LE(summary.at("boundary_particles").get<double>(), summary.at("particles").get<double>());
  for (const char* key : {"ms_per_iteration", "max_penetration_mm", "mean_penetration_mm",
                          "volume_change_pct", "spring_deviation_ratio"}) {
    ASSERT_TRUE(summary.at(key).is_number()) << key << " is " << summary.at(key);
    EXPECT_TRUE(std::isfinite(summary.at(key).get<double>())) << key;
  }
  EXPECT_GT(summary.at("ms_per_iteration").get<double>(), 0);
  EXPECT_GE(summary.at("max_penetration_mm").get<double>(),
            summary.at("mean_penetration_mm").get<double>());
  EXPECT_GE(summary.at("mean_penetration_mm").get<double>(), 0);
  EXPECT_GE(summary.at("spring_deviation_ratio").get<double>(), 0);
  double partSum = 0;
  for (const char* part : {"mss", "muscle_cd", "bone_cd", "response", "output"}) {
    const double ms = summary.at("timing").at(part).get<double>();
    EXPECT_TRUE(std::isfinite(ms) && ms >= 0) << part;
    partSum += ms;
  }
  EXPECT_GT(partSum, 0);
  EXPECT_EQ(summary.at("nan"), false);
  EXPECT_EQ(summary.at("interrupted"), false);
  EXPECT_EQ(summary.at("failed_step"), -1);
}

/// The frames of run.pvd in `out`: two at increasing simulated times, their times into `times`.
void expectTwoFrames(const fs::path& out, std::vector<double>& times) {
  // Two frames at increasing simulated times, each listing every part; the muscles' files new in
  // each, the still upper bar written once.
  const auto sets = pvdDataSets(out / "run.pvd");
  for (const auto& [time, file] : sets)
    if (times.empty() || times.back() != time) times.push_back(time);
  ASSERT_EQ(times.size(), 2u);
  EXPECT_GT(times[0], 0);
  EXPECT_GT(times[1], times[0]);
  EXPECT_EQ(sets.count(times[0]), sets.count(times[1]));
  std::set<std::string> files;
  for (const auto& [time, file] : sets) {
    files.insert(file);
    ASSERT_TRUE(fs::exists(out / file)) << file;
    expectWellFormedVtp(out / file);
  }
  EXPECT_EQ(files.size(), sets.size() - 1);
  EXPECT_EQ(files.count("frames/bone0_upper_00000.vtp"), 1u);
  EXPECT_FALSE(fs::exists(out / "frames/bone0_upper_00001.vtp"));
  // The complete scene is kept for reproducing the run.
  EXPECT_NO_THROW(nlohmann::json::parse(readFile(out / "scene.json")));
}

/// series.csv in `out`: the rows of the summary's "series", at the frames' `times`.
void expectSeries(const fs::path& out, const nlohmann::json& summary,
                  const std::vector<double>& times) {
  // series.csv: one row per step and muscle, the same values as summary.json's "series", the
  // times those of the frames.
  std::istringstream csv(readFile(out / "series.csv"));
  std::string line;
  ASSERT_TRUE(std::getline(csv, line));
  EXPECT_EQ(line,
            "step,pose,pose_label,time_s,muscle,volume_change_pct,mean_fibre_length_mm,"
            "max_fibre_stretch,max_penetration_mm,bone_contacts,solver_contacts,residual_rms_mm,"
            "residual_max_mm,max_belly_stretch,max_tendon_stretch,max_sphere_depth_mm,"
            "belly_strain,tendon_strain");
  const nlohmann::json& series = summary.at("series");
  ASSERT_EQ(series.size(), 2 * summary.at("muscles").size());
  for (size_t row = 0; row < series.size(); ++row) {
    ASSERT_TRUE(std::getline(csv, line)) << row;
    std::vector<std::string> fields;
    std::stringstream split(line);
    for (std::string field; std::getline(split, field, ',');) fields.push_back(field);
    if (line.back() == ',') fields.emplace_back();  // getline drops a last empty field
    ASSERT_EQ(fields.size(), 18u) << line;
    const nlohmann::json& json = series[row];
    EXPECT_EQ(std::stoi(fields[0]), json.at("step").get<int>());
    EXPECT_NEAR(std::stod(fields[3]), times[size_t(json.at("step").get<int>())], 1e-9);
    EXPECT_EQ(fields[4], json.at("muscle").get<std::string>());
    EXPECT_NEAR(std::stod(fields[5]), json.at("volume_change_pct").get<double>(), 1e-4);
    EXPECT_NEAR(std::stod(fields[7]), json.at("max_fibre_stretch").get<double>(), 1e-5);
    EXPECT_GE(std::stod(fields[7]), 1.0);  // the largest of all segments' l / L0
    // The force residual: measured at every step, the largest at least the RMS.
    EXPECT_NEAR(std::stod(fields[11]), json.at("residual_rms_mm").get<double>(), 1e-6);
    EXPECT_GE(std::stod(fields[12]), std::stod(fields[11]));
    // fusiform declares no tendon: the belly is every fibre segment, the tendon's strain empty.
    EXPECT_NEAR(std::stod(fields[16]), json.at("belly_strain").get<double>(), 1e-6);
    EXPECT_EQ(fields[17], "");
    EXPECT_TRUE(json.at("tendon_strain").is_null());
  }
  EXPECT_FALSE(std::getline(csv, line));
}

TEST(RunCli, WritesSummaryAndFramesForTwoSteps) {
  TemporaryDirectory out("fibremss_run_cli");
  const auto result =
      runProcess(cli() + " run fusiform --steps 2 --frame-every 1 --out " + out.path().string());
  ASSERT_EQ(result.exitCode, 0) << result.output;

  const nlohmann::json summary = nlohmann::json::parse(readFile(out.path() / "summary.json"));
  expectTwoStepSummary(summary);
  std::vector<double> times;
  ASSERT_NO_FATAL_FAILURE(expectTwoFrames(out.path(), times));
  expectSeries(out.path(), summary, times);
}

/// Runs fusiform for two steps into `out` with the `--set` options `sets`; its frame files.
std::vector<fs::path> fusiformFrames(const fs::path& out, const std::string& sets) {
  const auto result =
      runProcess(cli() + " run fusiform --steps 2 " + sets + " --out " + out.string());
  EXPECT_EQ(result.exitCode, 0) << result.output;
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(out / "frames")) files.push_back(entry.path());
  std::sort(files.begin(), files.end());
  return files;
}

/// The largest difference between two files' values of array `name` ("Points": coordinates).
double largestDifference(const PolyDataFile& a, const PolyDataFile& b, const std::string& name) {
  double largest = 0;
  if (name == "Points") {
    for (size_t i = 0; i < a.points.size(); ++i)
      for (int k = 0; k < 3; ++k)
        largest = std::max(largest, double(std::abs(a.points[i][k] - b.points[i][k])));
    return largest;
  }
  const std::vector<float>& x = a.array(name)->values;
  const std::vector<float>& y = b.array(name)->values;
  for (size_t i = 0; i < x.size(); ++i) largest = std::max(largest, double(std::abs(x[i] - y[i])));
  return largest;
}

TEST(RunCli, QuantisedFramesStayWithinTheirBoundAndShrink) {
  TemporaryDirectory out("fibremss_run_quantised");
  const std::vector<fs::path> exact = fusiformFrames(out.path() / "exact", "");
  const std::vector<fs::path> off =
      fusiformFrames(out.path() / "off", "--set outputs.quantise_mm=0");
  const std::vector<fs::path> rounded = fusiformFrames(
      out.path() / "on", "--set outputs.quantise_mm=0.01 --set outputs.quantise_strain=0.001");
  ASSERT_EQ(off.size(), exact.size());
  ASSERT_EQ(rounded.size(), exact.size());
  const nlohmann::json bounds =
      nlohmann::json::parse(readFile(out.path() / "on/summary.json")).at("frame_quantisation");
  const double lengthBound = bounds.at("length_error_bound_mm");  // fusiform is in mm
  EXPECT_EQ(lengthBound, 0.00390625);  // half of 2^-7 mm, the power of two below 0.01 mm
  size_t exactBytes = 0, roundedBytes = 0;
  for (size_t f = 0; f < exact.size(); ++f) {
    SCOPED_TRACE(exact[f].string());
    EXPECT_EQ(readFile(off[f]), readFile(exact[f]));
    exactBytes += fs::file_size(exact[f]);
    roundedBytes += fs::file_size(rounded[f]);
    const PolyDataFile a = readVtp(exact[f].string()), b = readVtp(rounded[f].string());
    ASSERT_EQ(a.points.size(), b.points.size());
    EXPECT_LE(largestDifference(a, b, "Points"), lengthBound);  // per coordinate
    if (a.array("displacement") == nullptr) continue;           // a bone
    EXPECT_LE(largestDifference(a, b, "displacement"), lengthBound);
    EXPECT_LE(largestDifference(a, b, "fibre_stretch"), bounds.at("strain_error_bound"));
  }
  EXPECT_LT(roundedBytes, exactBytes);
}

/// The glTF JSON chunk of a .glb file.
nlohmann::json glbJson(const fs::path& file) {
  const std::string bytes = readFile(file);
  uint32_t length = 0;
  std::memcpy(&length, bytes.data() + 12, 4);
  return nlohmann::json::parse(bytes.substr(20, length));
}

TEST(RunCli, ImplicitSurfaceFramesAreClosedInVtkAndGltf) {
  TemporaryDirectory out("fibremss_run_implicit");
  const auto result = runProcess(cli() +
                                 " run fusiform --steps 2 --format vtk,gltf --set "
                                 "outputs.surface=implicit --out " +
                                 out.path().string());
  ASSERT_EQ(result.exitCode, 0) << result.output;
  EXPECT_NE(result.output.find("implicit surface: "), std::string::npos) << result.output;
  const nlohmann::json summary = nlohmann::json::parse(readFile(out.path() / "summary.json"));
  EXPECT_GT(summary.at("implicit_surface_ms_per_frame").get<double>(), 0);
  const fs::path frames = out.path() / "frames";
  for (const char* step : {"00000", "00001"}) {
    const PolyDataFile surface =
        readVtp((frames / (std::string("muscle0_fusiform_surface_") + step + ".vtp")).string());
    ASSERT_GT(surface.triangles.size(), 100u);
    EXPECT_EQ(meshTopology({surface.points, surface.triangles}).openEdges, 0u);
    ASSERT_NE(surface.array("fibre_stretch"), nullptr);
    EXPECT_EQ(surface.array("fibre_stretch")->values.size(), surface.points.size());
    // The glTF frame holds the same surface (its first mesh, positions as an accessor).
    const nlohmann::json gltf =
        glbJson(out.path() / "gltf" / (std::string("frame_") + step + ".glb"));
    EXPECT_EQ(gltf.at("meshes").at(0).at("name"), "muscle0_fusiform");
    const int position =
        gltf.at("meshes").at(0).at("primitives").at(0).at("attributes").at("POSITION");
    EXPECT_EQ(gltf.at("accessors").at(position).at("count"), surface.points.size());
  }
  // One topology per frame: no morph targets, so no animated run.glb.
  EXPECT_FALSE(fs::exists(out.path() / "gltf" / "run.glb"));
}

TEST(Cli, VersionNamesBulletItsPrecisionTheKernelAndTheCompiler) {
  const auto result = runProcess(cli() + " --version");
  ASSERT_EQ(result.exitCode, 0) << result.output;
  EXPECT_NE(result.output.find("fibremss " FIBREMSS_VERSION "\n"), std::string::npos)
      << result.output;
  const int bullet = btGetVersion();
  EXPECT_NE(result.output.find("Bullet " + std::to_string(bullet / 100) + "." +
                               std::to_string(bullet % 100) + ", btScalar " +
                               (sizeof(btScalar) == 8 ? "double" : "float")),
            std::string::npos)
      << result.output;
  EXPECT_NE(result.output.find(std::string("spring kernel ") + activeSpringKernel() + " "),
            std::string::npos)
      << result.output;
  EXPECT_NE(result.output.find("compiler "), std::string::npos);
  // The kernel is the one chosen at runtime: the environment can choose scalar.
  const auto scalar = runProcess("FIBREMSS_SPRING_KERNEL=scalar " + cli() + " --version");
  EXPECT_NE(scalar.output.find("spring kernel scalar "), std::string::npos) << scalar.output;
}

TEST(Cli, EveryWarningIsPrefixedAndOnStderr) {
  // The time-budget stop rule is warned about (its results depend on the machine's load): check
  // and run say it the same way, on stderr only.
  TemporaryDirectory out("fibremss_warnings");
  for (const std::string command :
       {"check fusiform --set stop=budget", "run fusiform --steps 1 --set stop=budget"}) {
    SCOPED_TRACE(command);
    const fs::path log = out.path() / "stderr.txt";
    const auto result = runProcess(cli() + " " + command + " 2>" + log.string());
    ASSERT_EQ(result.exitCode, 0) << result.output;
    EXPECT_EQ(result.output.find("warning"), std::string::npos) << result.output;
    const std::string errors = readFile(log);
    EXPECT_NE(errors.find("fibremss: warning: simulation.stop = budget"), std::string::npos)
        << errors;
    std::istringstream lines(errors);
    for (std::string line; std::getline(lines, line);) {
      if (line.find("warning:") == std::string::npos && line.find("note:") == std::string::npos)
        continue;
      EXPECT_TRUE(line.starts_with("fibremss: warning: ") || line.starts_with("fibremss: note: "))
          << line;
    }
  }
}

TEST(RunCli, PrintsJsonWithoutWritingAnything) {
  const auto result = runProcess(cli() + " run fusiform --steps 1 --json");
  ASSERT_EQ(result.exitCode, 0) << result.output;
  const nlohmann::json summary = nlohmann::json::parse(result.output);
  EXPECT_EQ(summary.at("steps"), 1);
  EXPECT_GT(summary.at("iterations").get<long>(), 0);
}

TEST(RunCli, UnknownSceneIsAnErrorNamingIt) {
  const auto result = runProcess(cli() + " run no-such-scene-xyz 2>&1");
  EXPECT_NE(result.exitCode, 0);
  EXPECT_NE(result.output.find("no-such-scene-xyz"), std::string::npos) << result.output;
}

// Verlet at a fixed dt far beyond its stability bound (ω·dt ≫ 2 for these springs) must blow up.
const char* const kUnstable =
    " --set integrator=verlet --set resolution=10 --set time_step=fixed --set dt=0.05";

TEST(RunCli, AnUnstableRunFailsWithExitCode3AndSaysWhere) {
  TemporaryDirectory out("fibremss_run_cli_unstable");
  const auto result =
      runProcess(cli() + " run fusiform" + kUnstable + " --steps 5 --out " + out.path().string());
  EXPECT_EQ(result.exitCode, 3) << result.output;
  const nlohmann::json summary = nlohmann::json::parse(readFile(out.path() / "summary.json"));
  EXPECT_TRUE(summary.at("nan").get<bool>() || summary.at("exploded").get<bool>());
  const int failed = summary.at("failed_step");
  EXPECT_GE(failed, 0);
  EXPECT_EQ(summary.at("steps"), failed + 1);  // stopped at the failing step
  if (failed == 0) return;                     // no frame before the failure
  for (const auto& [time, file] : pvdDataSets(out.path() / "run.pvd")) {
    // No frame of the broken state: every file is of a step before the failure.
    std::smatch match;
    ASSERT_TRUE(std::regex_search(file, match, std::regex("_([0-9]{5})\\.vtp$"))) << file;
    EXPECT_LT(std::stoi(match[1]), failed) << file;
    expectWellFormedVtp(out.path() / file);
  }
}

TEST(RunCli, TheSummaryRecordsWhatTheNumericalGuardDid) {
  // The default policy retries with smaller steps, then freezes the muscle that still bursts.
  TemporaryDirectory out("fibremss_run_cli_guard");
  const auto result = runProcess(cli() + " run fusiform" + kUnstable +
                                 " --set max_retries=1 --steps 5 --out " + out.path().string());
  EXPECT_EQ(result.exitCode, 3) << result.output;
  EXPECT_NE(result.output.find("frozen at step"), std::string::npos) << result.output;
  const nlohmann::json summary = nlohmann::json::parse(readFile(out.path() / "summary.json"));
  const nlohmann::json& guard = summary.at("guard");
  EXPECT_EQ(guard.at("policy"), "retry");
  EXPECT_GE(guard.at("rolled_back_steps").get<int>(), 1);
  EXPECT_EQ(guard.at("retries").get<int>(), 1);  // all spent
  ASSERT_EQ(guard.at("frozen").size(), 1u);      // fusiform has one muscle
  EXPECT_EQ(guard.at("frozen")[0].at("step"), summary.at("failed_step"));

  // Only reporting: the run stops at the same kind of failure without any rollback.
  const auto reported =
      runProcess(cli() + " run fusiform" + kUnstable + " --set on_failure=report --steps 5 --json");
  EXPECT_EQ(reported.exitCode, 3) << reported.output;
  const nlohmann::json report = nlohmann::json::parse(reported.output);
  EXPECT_EQ(report.at("guard").at("rolled_back_steps"), 0);
  EXPECT_TRUE(report.at("guard").at("frozen").empty());
  EXPECT_GE(report.at("failed_step").get<int>(), 0);
}

TEST(RunCli, ALoopedRunSamplesMemoryDriftAndTiming) {
  TemporaryDirectory out("fibremss_run_cli_soak");
  const auto result = runProcess(cli() +
                                 " run fusiform --loop --steps 12 --sample-every 100 --frame-every "
                                 "0 --out " +
                                 out.path().string());
  ASSERT_EQ(result.exitCode, 0) << result.output;
  const nlohmann::json summary = nlohmann::json::parse(readFile(out.path() / "summary.json"));
  EXPECT_EQ(summary.at("steps"), 12);
  EXPECT_EQ(summary.at("loop_motion"), true);
  const nlohmann::json& soak = summary.at("soak");
  const long iterations = summary.at("iterations");
  ASSERT_GE(soak.at("samples").get<long>(), 1);
  EXPECT_LE(soak.at("samples").get<long>(), iterations / 100);
  EXPECT_EQ(soak.at("all_finite"), true);
  EXPECT_GT(soak.at("resident_mb_max").get<double>(), 0);
  EXPECT_LE(soak.at("ms_per_iteration_min").get<double>(),
            soak.at("ms_per_iteration_max").get<double>());
  // Fixed particles are put on T·rest every iteration: only rounding separates them.
  EXPECT_LT(soak.at("fixed_drift_mm_max").get<double>(), 1e-3);
  std::istringstream csv(readFile(out.path() / "soak.csv"));
  std::string line;
  size_t lines = 0;
  while (std::getline(csv, line)) ++lines;
  EXPECT_EQ(lines, soak.at("samples").get<size_t>() + 1);  // a header and one line per sample
}

TEST(RunCli, AnOutputDirectoryThatCannotBeMadeIsAnError) {
  TemporaryDirectory out("fibremss_run_cli_blocked");
  const fs::path blocker = out.path() / "file";
  std::ofstream(blocker) << "a file where the output directory should go";
  const auto result =
      runProcess(cli() + " run fusiform --steps 1 --out " + (blocker / "out").string() + " 2>&1");
  EXPECT_NE(result.exitCode, 0);
  EXPECT_NE(result.output.find("error"), std::string::npos) << result.output;
}

/// Starts the CLI with `args` in a child process, its output to /dev/null (its errors too with
/// `quietErrors`); returns the child's pid, or -1 when fork failed.
pid_t startCli(const std::vector<std::string>& args, bool quietErrors = false) {
  const std::string program = cli();
  std::vector<char*> argv{const_cast<char*>(program.c_str())};
  for (const std::string& arg : args) argv.push_back(const_cast<char*>(arg.c_str()));
  argv.push_back(nullptr);
  const pid_t child = fork();
  if (child != 0) return child;
  std::freopen("/dev/null", "w", stdout);
  if (quietErrors) std::freopen("/dev/null", "w", stderr);
  execv(program.c_str(), argv.data());
  _exit(127);
}

TEST(RunCli, InterruptKeepsTheFinishedStepsWithValidFiles) {
  TemporaryDirectory out("fibremss_run_cli_interrupt");
  const pid_t child = startCli(
      {"run", "fusiform", "--steps", "100000", "--frame-every", "1", "--out", out.path().string()});
  ASSERT_NE(child, -1);
  // Wait for the first frame, so the signal arrives while steps run (not during preparation).
  const fs::path pvd = out.path() / "run.pvd";
  for (int i = 0; i < 1200 && !fs::exists(pvd); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  const bool started = fs::exists(pvd);
  kill(child, SIGINT);
  int status = 0;
  waitpid(child, &status, 0);
  ASSERT_TRUE(started) << "no frame appeared within two minutes";
  ASSERT_TRUE(WIFEXITED(status)) << "the run did not exit by itself after SIGINT";
  EXPECT_EQ(WEXITSTATUS(status), 130);

  const nlohmann::json summary = nlohmann::json::parse(readFile(out.path() / "summary.json"));
  EXPECT_EQ(summary.at("interrupted"), true);
  EXPECT_GE(summary.at("steps").get<int>(), 1);
  EXPECT_LT(summary.at("steps").get<int>(), 100000);
  for (const auto& [time, file] : pvdDataSets(pvd)) expectWellFormedVtp(out.path() / file);
  for (const auto& entry : fs::recursive_directory_iterator(out.path()))
    EXPECT_EQ(entry.path().string().find(".tmp."), std::string::npos) << entry.path();
}

/// Whether process `pid` catches `signal` (its /proc status' SigCgt mask): `run` does while its
/// steps run (the interrupt guard), so a signal sent then reaches the step, not preparation.
bool catches(pid_t pid, int signal) {
  std::ifstream status("/proc/" + std::to_string(pid) + "/status");
  for (std::string line; std::getline(status, line);)
    if (line.starts_with("SigCgt:"))
      return (std::stoull(line.substr(7), nullptr, 16) >> (signal - 1) & 1) != 0;
  return false;
}

// SIGTERM while the first step runs its 100 million iterations: the step stops at the end of its
// running iteration, exit code 143, a summary saying interrupted with no step done, no frame.
TEST(RunCli, TerminationStopsWithinTheRunningStep) {
  TemporaryDirectory out("fibremss_run_cli_terminate");
  const pid_t child =
      startCli({"run", "fusiform", "--steps", "1", "--set", "resolution=10", "--set",
                "stop=iterations", "--set", "iterations=100000000", "--out", out.path().string()},
               true);
  ASSERT_NE(child, -1);
  bool started = false;
  int status = 0;
  pid_t ended = 0;
  for (int i = 0; i < 1200 && !(started = catches(child, SIGTERM)) && ended == 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    ended = waitpid(child, &status, WNOHANG);
  }
  if (ended == 0) kill(child, SIGTERM);
  // A step that does not stop would run for hours: two minutes, then it is killed and fails.
  for (int i = 0; i < 1200 && ended == 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    ended = waitpid(child, &status, WNOHANG);
  }
  if (ended == 0) {
    kill(child, SIGKILL);
    waitpid(child, &status, 0);
  }
  ASSERT_TRUE(started) << "the run did not start its steps within two minutes";
  ASSERT_TRUE(WIFEXITED(status)) << "the run did not exit by itself after SIGTERM";
  EXPECT_EQ(WEXITSTATUS(status), 143);
  const nlohmann::json summary = nlohmann::json::parse(readFile(out.path() / "summary.json"));
  EXPECT_EQ(summary.at("interrupted"), true);
  EXPECT_EQ(summary.at("steps"), 0);
  EXPECT_FALSE(fs::exists(out.path() / "run.pvd"));
}

TEST(Progress, LineShowsBarStepsRateAndTimeLeft) {
  // 5 of 10 steps in 2 s: 1000 iterations / 2 s, and 5 more steps at 0.4 s each.
  EXPECT_EQ(ProgressBar::format("job", 5, 10, 1000, 2.0, 10),
            "job [#####-----] 5/10 steps, 500 it/s, 2.0 s left");
  EXPECT_EQ(ProgressBar::format("job", 10, 10, 30, 12.0, 0),
            "job 10/10 steps, 2.5 it/s, 12 s in all");
  EXPECT_EQ(formatDuration(185), "3 min 05 s");
  EXPECT_EQ(formatDuration(7800), "2 h 10 min");
}

std::string written(std::FILE* file) {
  std::rewind(file);
  std::string text;
  for (int c; (c = std::fgetc(file)) != EOF;) text += static_cast<char>(c);
  return text;
}

TEST(Progress, OnePlainLinePerJobWhenNotATerminalRedrawnLineOnOne) {
  std::FILE* plain = std::tmpfile();
  ASSERT_NE(plain, nullptr);
  ProgressBar log("job", 2, plain, false);
  log.update(1, 10, 1.0);
  log.update(2, 20, 2.0);
  log.finish();
  EXPECT_EQ(written(plain), "job 2/2 steps, 10 it/s, 2.0 s in all\n");
  std::fclose(plain);

  std::FILE* terminal = std::tmpfile();
  ASSERT_NE(terminal, nullptr);
  ProgressBar bar("job", 2, terminal, true);
  bar.update(1, 10, 1.0);
  bar.update(2, 20, 2.0);  // the last step is always drawn
  bar.finish();
  const std::string text = written(terminal);
  EXPECT_EQ(std::count(text.begin(), text.end(), '\r'), 2);
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 1);
  EXPECT_TRUE(text.ends_with("2/2 steps, 10 it/s, 2.0 s in all\x1b[K\n")) << text;
  std::fclose(terminal);
}

/// The runner's API as `fibremss compare` uses it, on a small fusiform.
class FibreRunTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = new LoadedScene(loadScene("fusiform", {"resolution=10"}));
    prepared_ = new PreparedScene(prepareScene(scene_->bones, scene_->muscles, 1));
  }
  static void TearDownTestSuite() {
    delete prepared_;
    delete scene_;
  }
  static LoadedScene* scene_;
  static PreparedScene* prepared_;
};
LoadedScene* FibreRunTest::scene_ = nullptr;
PreparedScene* FibreRunTest::prepared_ = nullptr;

TEST_F(FibreRunTest, RunsOneStepPerPoseAndReportsProgress) {
  ASSERT_GE(scene_->poseCount, 2);
  std::vector<int> reported;
  FibreRunOptions options;
  options.progress = [&](const RunProgress& p) {
    reported.push_back(p.step);
    EXPECT_EQ(p.steps, scene_->poseCount);
    ASSERT_NE(p.lastStep, nullptr);
    EXPECT_EQ(p.iterations, static_cast<long>(reported.size()) * p.lastStep->iterations);
  };
  const RunMetrics metrics = runFibreMSS(*scene_, *prepared_, options);
  EXPECT_EQ(metrics.steps, scene_->poseCount);
  ASSERT_EQ(reported.size(), static_cast<size_t>(scene_->poseCount));
  for (size_t i = 0; i < reported.size(); ++i) EXPECT_EQ(reported[i], static_cast<int>(i) + 1);
  ASSERT_EQ(metrics.poseSurfaces.size(), static_cast<size_t>(scene_->poseCount));
  EXPECT_EQ(metrics.poseSurfaces.front().size(),
            prepared_->muscles.front()->restSurface.vertices.size());
  size_t particles = 0;
  for (const auto& muscle : prepared_->muscles) particles += muscle->particleCount();
  EXPECT_EQ(metrics.particles, particles);
  EXPECT_FALSE(metrics.interrupted);
  EXPECT_EQ(metrics.failedStep, -1);
}

TEST_F(FibreRunTest, StepsBeyondTheMotionHoldTheLastPoseAndTheMuscleSettles) {
  FibreRunOptions shortRun, longRun;
  shortRun.steps = scene_->poseCount;
  longRun.steps = scene_->poseCount + 6;
  const RunMetrics a = runFibreMSS(*scene_, *prepared_, shortRun);
  const RunMetrics b = runFibreMSS(*scene_, *prepared_, longRun);
  EXPECT_EQ(b.steps, longRun.steps);
  // Holding the pose, the springs relax further towards rest.
  EXPECT_LT(b.springDeviationRatio, a.springDeviationRatio);
}

TEST_F(FibreRunTest, ACancelFlagStopsAfterTheCurrentStep) {
  std::atomic<bool> cancel{false};
  FibreRunOptions options;
  options.steps = 50;
  options.cancel = &cancel;
  options.progress = [&](const RunProgress& p) {
    if (p.step == 2) cancel = true;
  };
  const RunMetrics metrics = runFibreMSS(*scene_, *prepared_, options);
  EXPECT_TRUE(metrics.interrupted);
  EXPECT_EQ(metrics.steps, 2);
}

TEST_F(FibreRunTest, FramesEveryKthStepPlusTheLast) {
  TemporaryDirectory out("fibremss_fibre_run_frames");
  FibreRunOptions options;
  options.outDir = out.path().string();
  options.steps = 6;
  options.frameEvery = 4;
  FibreRunDetails details;
  runFibreMSS(*scene_, *prepared_, options, &details);
  EXPECT_EQ(details.frames, 3);  // steps 0 and 4, and the last one, 5
  std::set<double> times;
  std::set<std::string> files;
  for (const auto& [time, file] : pvdDataSets(out.path() / "run.pvd")) {
    times.insert(time);
    files.insert(fs::path(file).filename().string());
  }
  EXPECT_EQ(times.size(), 3u);
  EXPECT_GT(*times.begin(), 0.0);  // simulated seconds at the end of step 0
  for (const char* step : {"00000", "00004", "00005"})
    EXPECT_TRUE(std::any_of(files.begin(), files.end(), [&](const std::string& name) {
      return name.ends_with(std::string("_") + step + ".vtp");
    })) << step;
}

}  // namespace
}  // namespace fibremss
