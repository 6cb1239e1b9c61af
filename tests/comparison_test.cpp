// The comparison runner, its report and the `compare` / `merge` commands.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "fibremss/Compare.h"
#include "fibremss/CompareReport.h"
#include "fibremss/Error.h"
#include "fibremss/Methods.h"
#include "fibremss/PlotLayout.h"
#include "support/Process.h"

namespace fibremss {
namespace {

namespace fs = std::filesystem;

std::string readFile(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

/// A fresh directory in the tests' build directory, wherever the test is run from (kept after the
/// test for a person to look at; run from the source root, the test once left them in the tree).
fs::path scratch(const std::string& name) {
  const fs::path dir = fs::path(FIBREMSS_TEST_BINARY_DIR) / ("comparison_test_" + name);
  fs::remove_all(dir);
  return dir;
}

/// Runs the fibremss tool with `arguments`: its exit code and all it printed (stderr too).
testing::ProcessResult runCli(const std::string& arguments) {
  return testing::runProcess(std::string(FIBREMSS_CLI) + " " + arguments + " 2>&1");
}

/// Skips the comment, CDATA section, declaration or doctype starting at `i`: whether one starts
/// there; `problem` names it when it is unterminated (`i` then stays at its start).
bool skipMarkup(const std::string& xml, size_t& i, std::string& problem) {
  static const char* const kinds[][3] = {{"<!--", "-->", "comment"},
                                         {"<![CDATA[", "]]>", "CDATA"},
                                         {"<?", "?>", "declaration"},
                                         {"<!", ">", "doctype"}};
  for (const auto& [start, end, what] : kinds) {
    if (xml.compare(i, std::char_traits<char>::length(start), start) != 0) continue;
    const size_t found = xml.find(end, i);
    if (found == std::string::npos) {
      problem = std::string("unterminated ") + what;
    } else {
      i = found + std::char_traits<char>::length(end);
    }
    return true;
  }
  return false;
}

/// The '>' closing the tag that opens at `i`, outside quotes; npos with `problem` set when
/// there is none or a '<' comes first.
size_t tagEnd(const std::string& xml, size_t i, std::string& problem) {
  size_t j = i + 1;
  char quote = 0;
  for (; j < xml.size() && (quote || xml[j] != '>'); ++j) {
    if (quote && xml[j] == quote) {
      quote = 0;
    } else if (!quote && (xml[j] == '"' || xml[j] == '\'')) {
      quote = xml[j];
    } else if (!quote && xml[j] == '<') {
      problem = "'<' inside a tag";
      return std::string::npos;
    }
  }
  if (j >= xml.size()) {
    problem = "unterminated tag";
    return std::string::npos;
  }
  return j;
}

/// XML well-formedness: one root, every tag closed in order, quoted attributes, valid
/// references; declarations, comments, CDATA and doctype skipped.
bool wellFormedXml(const std::string& xml, std::string& problem) {
  std::vector<std::string> open;
  bool rootSeen = false;
  size_t i = 0;
  auto fail = [&](const std::string& what) {
    problem = what + " at offset " + std::to_string(i);
    return false;
  };
  while (i < xml.size()) {
    if (xml[i] == '&') {
      const size_t end = xml.find(';', i);
      if (end == std::string::npos || end - i > 10) return fail("bad reference");
      const std::string name = xml.substr(i + 1, end - i - 1);
      if (name != "lt" && name != "gt" && name != "amp" && name != "quot" && name != "apos" &&
          (name.empty() || name[0] != '#')) {
        return fail("unknown entity &" + name + ";");
      }
      i = end + 1;
      continue;
    }
    if (xml[i] != '<') {
      if (open.empty() && !std::isspace(static_cast<unsigned char>(xml[i]))) {
        return fail("text outside the root");
      }
      ++i;
      continue;
    }
    std::string unterminated;
    if (skipMarkup(xml, i, unterminated)) {
      if (!unterminated.empty()) return fail(unterminated);
      continue;
    }
    std::string tagProblem;
    const size_t j = tagEnd(xml, i, tagProblem);
    if (j == std::string::npos) return fail(tagProblem);
    std::string tag = xml.substr(i + 1, j - i - 1);
    const bool closing = !tag.empty() && tag[0] == '/';
    const bool selfClosing = !tag.empty() && tag.back() == '/';
    std::string name = tag.substr(closing ? 1 : 0);
    name = name.substr(0, name.find_first_of(" \t\r\n/"));
    if (name.empty()) return fail("tag without a name");
    if (closing) {
      if (open.empty() || open.back() != name) return fail("</" + name + "> does not match");
      open.pop_back();
    } else {
      if (open.empty() && rootSeen) return fail("second root element <" + name + ">");
      rootSeen = true;
      if (!selfClosing) open.push_back(name);
    }
    i = j + 1;
  }
  if (!open.empty()) return fail("<" + open.back() + "> never closed");
  if (!rootSeen) return fail("no element");
  return true;
}

TEST(WellFormedXml, AcceptsAndRejectsKnownDocuments) {
  std::string problem;
  EXPECT_TRUE(wellFormedXml(
      "<?xml version=\"1.0\"?>\n<!-- c --><svg a=\"1 > 0\"><g><text>x &amp; y</text></g><p/></svg>",
      problem))
      << problem;
  EXPECT_FALSE(wellFormedXml("<svg><g></svg></g>", problem));
  EXPECT_FALSE(wellFormedXml("<svg><g></g>", problem));
  EXPECT_FALSE(wellFormedXml("<svg>a & b</svg>", problem));
  EXPECT_FALSE(wellFormedXml("<a></a><b></b>", problem));
}

TEST(ParseMethod, KnowsTheFamiliesAndVariants) {
  EXPECT_EQ(parseMethod("fem").family, "fem");
  const MethodSpec variant = parseMethod("fibremss:integrator=semi-implicit-euler+iterations=200");
  EXPECT_EQ(variant.family, "fibremss");
  EXPECT_EQ(variant.overrides,
            (std::vector<std::string>{"integrator=semi-implicit-euler", "iterations=200"}));
  EXPECT_THROW(parseMethod("bullet"), InputError);
  EXPECT_THROW(parseMethod("fem:iterations=3"), InputError);
  EXPECT_THROW(parseMethod("fibremss:iterations"), InputError);
}

TEST(SummaryJson, EachRunStatesTheOverridesItRanWith) {
  Comparison comparison;
  comparison.overrides = {"resolution=20", "seed=3"};
  comparison.resolution = 20;
  for (const char* method : {"fibremss", "fibremss:resolution=10+iterations=5", "btsoftbody"}) {
    comparison.runs.emplace_back();
    comparison.runs.back().method = method;
  }
  const nlohmann::json runs = summaryJson(comparison, "compare").at("runs");
  using Strings = std::vector<std::string>;
  EXPECT_EQ(runs[0].at("scene_overrides").get<Strings>(), comparison.overrides);
  EXPECT_EQ(runs[1].at("scene_overrides").get<Strings>(),
            (Strings{"seed=3", "resolution=10", "iterations=5"}));
  EXPECT_EQ(runs[2].at("scene_overrides").get<Strings>(), comparison.overrides);
  EXPECT_EQ(runs[0].at("resolution"), 20);
  EXPECT_EQ(runs[1].at("resolution"), 10);
}

TEST(RmsBetweenRuns, CombinesPosesAsTheRootMeanSquare) {
  // Pose 0 shifted by 1 mm, pose 1 by 3 mm: sqrt((1 + 9) / 2) mm.
  RunMetrics a, b;
  const std::vector<btVector3> rest = {{0, 0, 0}, {0.01f, 0, 0}, {0, 0.02f, 0}};
  for (const btScalar shift : {0.001f, 0.003f}) {
    a.poseSurfaces.push_back(rest);
    std::vector<btVector3> moved;
    for (const btVector3& p : rest) moved.push_back(p + btVector3(0, 0, shift));
    b.poseSurfaces.push_back(moved);
  }
  EXPECT_NEAR(rmsBetweenRuns(a, b), std::sqrt(5.0), 1e-4);
  b.poseSurfaces.pop_back();  // only the common pose counts
  EXPECT_NEAR(rmsBetweenRuns(a, b), 1.0, 1e-4);
  EXPECT_TRUE(std::isnan(rmsBetweenRuns(a, RunMetrics{})));

  std::vector<RunMetrics> runs(2);
  runs[0].method = "fibremss";
  runs[0].poseSurfaces = b.poseSurfaces;
  runs[1].method = "calculix";
  runs[1].poseSurfaces = a.poseSurfaces;
  fillRms(runs);
  EXPECT_NEAR(runs[0].rmsToReferenceMm, 1.0, 1e-4);
  EXPECT_EQ(runs[0].rmsToReferencePoses, 1) << "the reference's second pose has no partner";
  EXPECT_EQ(runs[1].rmsToReferenceMm, 0.0);
  EXPECT_EQ(runs[1].rmsToReferencePoses, 2);
  EXPECT_TRUE(std::isnan(runs[0].rmsToSelfReferenceMm));
}

void expectFinite(double value, const std::string& what) {
  EXPECT_TRUE(std::isfinite(value)) << what << " = " << value;
}

class EveryMethod : public ::testing::TestWithParam<const char*> {};

TEST_P(EveryMethod, GivesFiniteMetrics) {
  // sphere-planes runs each of its 3 poses to convergence (up to 5000 iterations, the
  // self-reference 8× that): capped here, where finite metrics are the point.
  std::vector<std::string> overrides;
  if (std::string(GetParam()) == "sphere-planes") overrides = {"simulation.iterations=500"};
  const LoadedScene scene = loadScene(GetParam(), overrides);
  CompareOptions options;         // all four methods
  options.withReference = false;  // the reference has its own tests (calculix_test)
  options.fronts = false;         // one run per method
  const Comparison comparison = runComparison(GetParam(), overrides, options);
  ASSERT_EQ(comparison.runs.size(), 4u);
  for (const RunMetrics& run : comparison.runs) {
    SCOPED_TRACE(run.method);
    EXPECT_EQ(run.steps, std::max(scene.poseCount, 1));
    EXPECT_EQ(run.poses, run.steps);
    EXPECT_FALSE(run.nan);
    EXPECT_FALSE(run.exploded);
    EXPECT_EQ(run.failedStep, -1);
    EXPECT_GT(run.particles, 0u);
    EXPECT_GT(run.msPerStep, 0);
    expectFinite(run.msPerIteration, "ms per iteration");
    expectFinite(run.maxPenetrationMm, "max penetration");
    expectFinite(run.meanPenetrationMm, "mean penetration");
    expectFinite(run.volumeChangePct, "volume change");
    expectFinite(run.rmsToSelfReferenceMm, "RMS to self-reference");
    expectFinite(run.peakMemoryMb, "peak memory");
    EXPECT_GE(run.maxPenetrationMm, run.meanPenetrationMm);
    if (run.method == "fem") {
      EXPECT_TRUE(std::isnan(run.springDeviationRatio)) << "FEM has no springs";
    } else {
      expectFinite(run.springDeviationRatio, "spring deviation");
    }
    ASSERT_EQ(run.poseSurfaces.size(), static_cast<size_t>(run.steps));
  }
}

INSTANTIATE_TEST_SUITE_P(BuiltInScenes, EveryMethod, ::testing::Values("fusiform", "sphere-planes"),
                         [](const auto& param) {
                           std::string name = param.param;
                           std::erase(name, '-');
                           return name;
                         });

// The equilibrium method stops each pose on the force residual: every pose of its run is below
// kEquilibriumResidual (none at the cap), and the default run, 70 iterations, is further from
// equilibrium by both measures.
TEST(EquilibriumMethod, StopsEveryPoseBelowTheResidualTolerance) {
  CompareOptions options;
  options.methods = {"equilibrium", "fibremss"};
  options.withReference = false;
  options.fronts = false;
  const Comparison comparison = runComparison("fusiform", {"resolution=12"}, options);
  ASSERT_EQ(comparison.runs.size(), 2u);
  const RunMetrics& equilibrium = comparison.runs[0];
  const RunMetrics& fibre = comparison.runs[1];
  EXPECT_EQ(equilibrium.unconvergedPoses, 0);
  ASSERT_EQ(equilibrium.residualRmsMmPerPose.size(), static_cast<size_t>(equilibrium.steps));
  for (double rms : equilibrium.residualRmsMmPerPose) EXPECT_LT(rms, 1000 * kEquilibriumResidual);
  EXPECT_GT(fibre.residualRmsMm, equilibrium.residualRmsMm);
  EXPECT_GT(fibre.rmsToEquilibriumMm, 0);
  EXPECT_EQ(equilibrium.rmsToEquilibriumMm, 0);
}

// --equilibrium-cap raises the cap without changing the path: the bones still move over the
// scene's own motion iterations (70 × 0.5 = 35).
TEST(EquilibriumMethod, ACapKeepsTheBonesMotionIterations) {
  MuscleSystemDef scene;
  scene.stepSettings.iterations = 70;
  scene.stepSettings.motionFraction = 0.5f;
  const MuscleSystemDef usual = equilibriumSettings(scene);
  const MuscleSystemDef longer = equilibriumSettings(scene, 12000);
  EXPECT_EQ(usual.stepSettings.iterations, kEquilibriumIterations);
  EXPECT_EQ(longer.stepSettings.iterations, 12000);
  EXPECT_NEAR(usual.stepSettings.motionFraction * btScalar(usual.stepSettings.iterations), 35,
              1e-2);
  EXPECT_NEAR(longer.stepSettings.motionFraction * btScalar(longer.stepSettings.iterations), 35,
              1e-2);
  EXPECT_EQ(longer.stepSettings.stopRule, StopRule::Residual);
  EXPECT_EQ(longer.projectiveRho, usual.projectiveRho);
}

TEST(CompareCommand, WritesReportJsonAndWellFormedPlots) {
  const fs::path out = scratch("cli");
  const testing::ProcessResult result = runCli(
      "compare fusiform --set resolution=12 --methods fibremss,fem --no-fronts --no-reference "
      "--out " +
      out.string());
  ASSERT_EQ(result.exitCode, 0) << result.output;
  for (const char* file :
       {"summary.json", "report.md", "speed_vs_error.png", "speed_vs_error.svg"}) {
    ASSERT_TRUE(fs::exists(out / file)) << file;
    EXPECT_GT(fs::file_size(out / file), 0u) << file;
  }
  const nlohmann::json summary = nlohmann::json::parse(readFile(out / "summary.json"));
  EXPECT_EQ(summary["scene"], "fusiform");
  EXPECT_TRUE(summary["machine"].contains("cpu"));
  EXPECT_GT(summary["machine"]["cores"].get<int>(), 0);
  EXPECT_NE(summary["command"].get<std::string>().find("compare fusiform"), std::string::npos);
  ASSERT_EQ(summary["runs"].size(), 2u);
  const nlohmann::json expectedKeys = toJson(RunMetrics{});
  for (const auto& run : summary["runs"]) {
    for (const auto& [key, value] : expectedKeys.items()) EXPECT_TRUE(run.contains(key)) << key;
    for (const char* key : {"scene_overrides", "resolution", "step_deg"}) {
      EXPECT_TRUE(run.contains(key)) << key;
    }
    EXPECT_EQ(run["resolution"], 12);
    EXPECT_TRUE(run["ms_per_step"].is_number());
  }
  EXPECT_EQ(summary["runs"][0]["method"], "fibremss");
  EXPECT_TRUE(summary["runs"][0]["rms_to_reference_mm"].is_null()) << "no reference";
  // The FibreMSS run's series, one row per pose (one muscle), as `fibremss run` writes it; the
  // FEM run has none.
  const nlohmann::json& series = summary["runs"][0]["series"];
  EXPECT_EQ(series.size(), summary["runs"][0]["steps"].get<size_t>());
  EXPECT_TRUE(summary["runs"][1]["series"].empty());
  EXPECT_EQ(readFile(out / "series_0_fibremss.csv"), seriesCsv(seriesFromJson(series)));
  EXPECT_FALSE(fs::exists(out / "series_1_fem.csv"));
  // The FibreMSS run's force residual after every pose, its worst pose's in the headline; none
  // for FEM (null, "—" in the report).
  const nlohmann::json& fibre = summary["runs"][0];
  EXPECT_EQ(fibre["residual_rms_mm_per_pose"].size(), fibre["steps"].get<size_t>());
  EXPECT_GT(fibre["residual_rms_mm"].get<double>(), 0);
  EXPECT_GE(fibre["residual_max_mm"].get<double>(), fibre["residual_rms_mm"].get<double>());
  EXPECT_GE(fibre["residual_worst_pose"].get<int>(), 0);
  EXPECT_TRUE(summary["runs"][1]["residual_rms_mm"].is_null());

  std::string problem;
  EXPECT_TRUE(wellFormedXml(readFile(out / "speed_vs_error.svg"), problem)) << problem;
  const std::string png = readFile(out / "speed_vs_error.png");
  EXPECT_EQ(png.substr(1, 3), "PNG");
  const std::string report = readFile(out / "report.md");
  EXPECT_NE(report.find("| fibremss |"), std::string::npos);
  EXPECT_NE(report.find("| fem |"), std::string::npos);
  EXPECT_NE(report.find("compare fusiform"), std::string::npos);
  EXPECT_NE(report.find("How each method was measured"), std::string::npos);
}

TEST(CompareCommand, HipSweepWritesThePenetrationAgainstStepPlot) {
  // hip-extension is a sweep: its step_deg (here overridden to 20) reaches summary.json and a
  // second plot, penetration against step_deg, is written beside speed against error.
  const fs::path out = scratch("hip_sweep");
  const testing::ProcessResult result = runCli(
      "compare hip-extension --set step_deg=20 --methods fibremss --no-fronts --no-reference "
      "--out " +
      out.string());
  ASSERT_EQ(result.exitCode, 0) << result.output;
  const nlohmann::json summary = nlohmann::json::parse(readFile(out / "summary.json"));
  EXPECT_EQ(summary["runs"][0]["step_deg"], 20.0);
  std::string problem;
  ASSERT_TRUE(fs::exists(out / "penetration_vs_step.svg"));
  EXPECT_TRUE(wellFormedXml(readFile(out / "penetration_vs_step.svg"), problem)) << problem;
  EXPECT_NE(readFile(out / "report.md").find("penetration_vs_step.png"), std::string::npos);
}

TEST(CompareCommand, StatesTheRatioToBtSoftBodyWithTheThreadCounts) {
  // FibreMSS on the one thread --threads asks for, btSoftBody on Bullet's one: report.md and
  // summary.json state the ratio of the two runs' ms per step with both thread counts.
  const fs::path out = scratch("softbody_ratio");
  const testing::ProcessResult result = runCli(
      "compare fusiform --set resolution=8 --threads 1 --methods fibremss,btsoftbody --no-fronts "
      "--no-reference --out " +
      out.string());
  ASSERT_EQ(result.exitCode, 0) << result.output;
  const nlohmann::json summary = nlohmann::json::parse(readFile(out / "summary.json"));
  ASSERT_EQ(summary["runs"].size(), 2u);
  const nlohmann::json &fibre = summary["runs"][0], &softBody = summary["runs"][1];
  EXPECT_EQ(fibre["threads"], 1);
  EXPECT_EQ(softBody["threads"], 1);
  ASSERT_EQ(summary["btsoftbody_ratio"].size(), 1u);
  const nlohmann::json& ratio = summary["btsoftbody_ratio"][0];
  const double expected =
      softBody["ms_per_step"].get<double>() / fibre["ms_per_step"].get<double>();
  EXPECT_NEAR(ratio["ratio"].get<double>(), expected, 1e-9 * expected);
  EXPECT_EQ(ratio["fibremss_threads"], 1);
  EXPECT_EQ(ratio["btsoftbody_threads"], 1);
  EXPECT_EQ(ratio["poses"], fibre["steps"]);
  EXPECT_EQ(ratio["of"], fibre["poses"]);
  // A time step: FibreMSS's iteration; btSoftBody's world substep, several per pose.
  EXPECT_EQ(fibre["ms_per_time_step"], fibre["ms_per_iteration"]);
  EXPECT_LT(softBody["ms_per_time_step"].get<double>(), softBody["ms_per_step"].get<double>());
  EXPECT_GT(softBody["ms_per_time_step"].get<double>(), softBody["ms_per_iteration"].get<double>());
  const double perTimeStep =
      softBody["ms_per_time_step"].get<double>() / fibre["ms_per_time_step"].get<double>();
  EXPECT_NEAR(ratio["time_step_ratio"].get<double>(), perTimeStep, 1e-9 * perTimeStep);
  char line[240];
  std::snprintf(line, sizeof line,
                "FibreMSS (1 thread) vs btSoftBody (Bullet, 1 thread): %.1f× per simulated step "
                "(one pose), %.1f× per time step (a FibreMSS iteration against a Bullet substep) "
                "(fusiform, resolution 8, %d/%d poses)",
                expected, perTimeStep, fibre["steps"].get<int>(), fibre["poses"].get<int>());
  EXPECT_EQ(ratio["statement"], line);
  EXPECT_NE(readFile(out / "report.md").find(std::string("- ") + line + "\n"), std::string::npos)
      << readFile(out / "report.md");
}

TEST(CompareCommand, RejectsAnUnknownMethodWithExitCode2) {
  const fs::path out = scratch("bad_method");
  const std::string command = std::string(FIBREMSS_CLI) +
                              " compare fusiform --methods fibremss,nonsense --out " +
                              out.string() + " > /dev/null 2>&1";
  const int status = std::system(command.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 2);
  EXPECT_FALSE(fs::exists(out / "summary.json"));
}

/// A hand-made summary: thigh13 at `resolution` with known part timings, and a sweep run.
nlohmann::json madeSummary(double stepDeg, double msPerIteration, int resolution = 20) {
  RunMetrics run;
  run.scene = "thigh13";
  run.method = "fibremss";
  run.msPerStep = 70 * msPerIteration;
  run.msPerIteration = run.msPerTimeStep = msPerIteration;
  run.timing = {10, 2, 4, 1, 0.5};
  run.maxPenetrationMm = stepDeg / 2;
  run.rmsToReferenceMm = 3;
  nlohmann::json object = toJson(run);
  object["scene_overrides"] = {"resolution=" + std::to_string(resolution)};
  object["resolution"] = resolution;
  object["step_deg"] = stepDeg;
  return {{"scene", "thigh13"},
          {"machine", machineJson()},
          {"command", "fibremss compare thigh13 --set step_deg=" + std::to_string(stepDeg)},
          {"runs", {object}}};
}

TEST(MergeAndReport, MergedReportHasTable1RatiosAndTheSweepPlot) {
  const fs::path a = scratch("merge_a"), b = scratch("merge_b"), out = scratch("merged");
  writeComparison(madeSummary(2, 20), a.string());
  writeComparison(madeSummary(10, 20), b.string());
  const std::string command = std::string(FIBREMSS_CLI) + " merge " + a.string() + " " +
                              (b / "summary.json").string() + " --out " + out.string() +
                              " > /dev/null 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0);
  const nlohmann::json merged = nlohmann::json::parse(readFile(out / "summary.json"));
  ASSERT_EQ(merged["runs"].size(), 2u);
  EXPECT_EQ(merged["command"].size(), 2u);
  std::string problem;
  for (const char* svg : {"speed_vs_error.svg", "penetration_vs_step.svg"}) {
    ASSERT_TRUE(fs::exists(out / svg)) << svg;
    EXPECT_TRUE(wellFormedXml(readFile(out / svg), problem)) << svg << ": " << problem;
  }
  // MSS 10 ms per iteration → 5 s per 500; thesis 18.66 s → ratio 3.73.
  const std::string report = readFile(out / "report.md");
  EXPECT_NE(report.find("The thesis' timings (seed 004 Table 1)"), std::string::npos);
  EXPECT_NE(report.find("| MSS | 5 / 18.66 (3.73×) |"), std::string::npos) << report;
  EXPECT_NE(report.find("| total | 10 / 56.84 (5.68×) |"), std::string::npos) << report;
}

TEST(MusclesToEquilibrium, NamesTheWorstMuscleOverThePosesAndTheWorstMuscleAtAPose) {
  // Muscle a (2 vertices) is 3 mm off at both poses, b (1 vertex) 0 then 4 mm: a is worst over
  // the poses (3 against sqrt(8) = 2.83 mm), b at pose 1 the worst single muscle and pose.
  const std::vector<btVector3> rest = {{0, 0, 0}, {0.01f, 0, 0}, {0, 0.02f, 0}};
  std::vector<RunMetrics> runs(2);
  runs[0].method = "equilibrium";
  runs[1].method = "fibremss";
  for (const btScalar b : {0.0f, 0.004f}) {
    runs[0].poseSurfaces.push_back(rest);
    runs[1].poseSurfaces.push_back({rest[0] + btVector3(0.003f, 0, 0),
                                    rest[1] + btVector3(0, 0.003f, 0),
                                    rest[2] + btVector3(0, 0, b)});
  }
  const std::vector<SurfaceBlock> blocks = {{"a", 2}, {"b", 1}};
  fillRms(runs);
  fillMusclesToEquilibrium(runs, blocks);
  const RunMetrics& run = runs[1];
  ASSERT_EQ(run.rmsToEquilibriumPerPoseMm.size(), 2u);
  EXPECT_NEAR(run.rmsToEquilibriumPerPoseMm[0], std::sqrt(6.0), 1e-4);
  EXPECT_NEAR(run.rmsToEquilibriumPerPoseMm[1], std::sqrt(34.0 / 3), 1e-4);
  EXPECT_EQ(run.worstPoseToEquilibrium, 1);
  EXPECT_NEAR(run.worstPoseRmsToEquilibriumMm, run.rmsToEquilibriumPerPoseMm[1], 1e-9);
  ASSERT_EQ(run.musclesToEquilibrium.size(), 2u);
  EXPECT_EQ(run.musclesToEquilibrium[1].muscle, "b");
  EXPECT_NEAR(run.musclesToEquilibrium[1].perPoseMm[0], 0.0, 1e-4);
  EXPECT_NEAR(run.musclesToEquilibrium[1].rmsMm, std::sqrt(8.0), 1e-4);
  EXPECT_EQ(run.worstMuscleToEquilibrium, "a");
  EXPECT_NEAR(run.worstMuscleRmsToEquilibriumMm, 3.0, 1e-4);
  EXPECT_EQ(run.worstMusclePoseToEquilibrium.muscle, "b");
  EXPECT_EQ(run.worstMusclePoseToEquilibrium.pose, 1);
  EXPECT_NEAR(run.worstMusclePoseToEquilibrium.rmsMm, 4.0, 1e-4);
  EXPECT_EQ(runs[0].worstMuscleRmsToEquilibriumMm, 0.0) << "the equilibrium run against itself";

  // summary.json keeps them; a summary written before them reads back as not measured.
  const RunMetrics read = runMetricsFromJson(toJson(run));
  EXPECT_EQ(read.worstMusclePoseToEquilibrium.muscle, "b");
  EXPECT_EQ(read.worstMusclePoseToEquilibrium.pose, 1);
  EXPECT_EQ(read.musclesToEquilibrium[0].perPoseMm, run.musclesToEquilibrium[0].perPoseMm);
  EXPECT_EQ(read.worstPoseToEquilibrium, 1);
  nlohmann::json old = toJson(run);
  for (const char* key : {"muscles_to_equilibrium", "worst_muscle_pose_to_equilibrium",
                          "worst_pose_to_equilibrium", "worst_muscle_rms_to_equilibrium_mm"})
    old.erase(key);
  const RunMetrics before = runMetricsFromJson(old);
  EXPECT_TRUE(before.musclesToEquilibrium.empty());
  EXPECT_EQ(before.worstPoseToEquilibrium, -1);
  EXPECT_TRUE(std::isnan(before.worstMuscleRmsToEquilibriumMm));

  // The report's table names both; blocks that do not split the surfaces leave a run without.
  nlohmann::json summary = madeSummary(2, 20);
  summary["runs"] = {toJson(runs[0]), toJson(run)};
  const fs::path out = scratch("muscles_to_equilibrium");
  writeComparison(summary, out.string());
  const std::string report = readFile(out / "report.md");
  EXPECT_NE(report.find("| 3.37 (pose 1) | a 3; b at pose 1 4 |"), std::string::npos) << report;
  std::vector<RunMetrics> mismatched(2);
  mismatched[0] = runs[0], mismatched[1].method = "fibremss";
  mismatched[1].poseSurfaces = runs[1].poseSurfaces;
  fillMusclesToEquilibrium(mismatched, std::vector<SurfaceBlock>{{"a", 2}, {"b", 2}});
  EXPECT_TRUE(mismatched[1].musclesToEquilibrium.empty());
  EXPECT_EQ(mismatched[1].worstPoseToEquilibrium, -1);
}

TEST(MergeAndReport, TablesEachRunsRmsToTheReferencePerPoseAndPerMuscle) {
  RunMetrics reference, run;
  reference.method = kReferenceMethod;
  run.method = "fibremss";
  run.rmsToReferenceMm = 2;
  run.rmsToReferencePerPoseMm = {0, 1.5, 2.5};
  run.musclesToReference = {{"vastus", 0.25, {0, 0.5, 0}}, {"gracilis", 7.5, {0, 2, 12.5}}};
  nlohmann::json summary = madeSummary(2, 20);
  summary["runs"] = {toJson(reference), toJson(run)};
  const fs::path out = scratch("per_pose_and_muscle");
  writeComparison(summary, out.string());
  const std::string report = readFile(out / "report.md");
  const size_t section = report.find("## RMS to the reference per pose and per muscle");
  ASSERT_NE(section, std::string::npos) << report;
  const std::string tables = report.substr(section, report.find("\n## ", section + 1) - section);
  EXPECT_NE(tables.find("| fibremss | 0 | 1.5 | 2.5 |"), std::string::npos) << tables;
  EXPECT_NE(tables.find("| gracilis | 7.5 |"), std::string::npos) << tables;
  EXPECT_EQ(tables.find("| calculix |"), std::string::npos) << "not the reference itself";
  EXPECT_EQ(runMetricsFromJson(toJson(run)).musclesToReference[1].perPoseMm,
            run.musclesToReference[1].perPoseMm);

  run.musclesToReference.resize(1);  // one muscle: its row would repeat the per-pose table
  summary["runs"] = {toJson(reference), toJson(run)};
  writeComparison(summary, out.string());
  EXPECT_EQ(readFile(out / "report.md").find("| vastus |"), std::string::npos);
}

TEST(MergeAndReport, SaysWhenRmsToTheReferenceCoversFewerPosesThanTheRun) {
  // ccx did not solve the reference's pose 1 of 13: FibreMSS's RMS to it covers pose 0 only.
  nlohmann::json summary = madeSummary(2, 20);
  summary["runs"][0]["poses"] = 13;
  summary["runs"][0]["steps"] = 13;
  summary["runs"][0]["rms_to_reference_poses"] = 1;
  RunMetrics reference;
  reference.scene = "thigh13";
  reference.method = "calculix";
  reference.msPerStep = 5000;
  reference.rmsToReferenceMm = 0;
  reference.failedStep = 1;
  reference.steps = 1;
  reference.poses = 13;
  reference.rmsToReferencePoses = 1;
  summary["runs"].push_back(toJson(reference));
  const fs::path out = scratch("partial_reference");
  writeComparison(summary, out.string());
  const std::string report = readFile(out / "report.md");
  EXPECT_NE(report.find("RMS to the reference covers fewer poses than the runs"), std::string::npos)
      << report;
  EXPECT_NE(report.find("fibremss (1/13 poses)"), std::string::npos) << report;
  EXPECT_NE(report.find("ccx did not solve the reference's pose 1"), std::string::npos) << report;
  EXPECT_NE(report.find("| 3 (1/13 poses) |"), std::string::npos) << "table cell: " << report;
  const std::string script = readFile(out / "speed_vs_error.gp");
  EXPECT_NE(script.find("(1/13 poses)"), std::string::npos) << "point label or note: " << script;
  std::string problem;
  EXPECT_TRUE(wellFormedXml(readFile(out / "speed_vs_error.svg"), problem)) << problem;

  // Every pose covered: no note.
  summary["runs"][0]["rms_to_reference_poses"] = 13;
  summary["runs"][1]["rms_to_reference_poses"] = 13;
  writeComparison(summary, out.string());
  EXPECT_EQ(readFile(out / "report.md").find("covers fewer poses"), std::string::npos);
}

TEST(MergeAndReport, SaysOverHowManyPosesARunStoppedByItsBudgetIsMeasured) {
  // No reference (the main job without its cache): a run stopped by its time budget after 3
  // of 13 poses has an RMS to the self-reference over those 3, and says so.
  nlohmann::json summary = madeSummary(2, 20);
  nlohmann::json& run = summary["runs"][0];
  run["rms_to_reference_mm"] = nullptr;
  run["poses"] = 13;
  run["steps"] = 3;
  run["interrupted"] = true;
  run["rms_to_self_reference_mm"] = 4.8;
  run["rms_to_self_reference_poses"] = 3;
  const fs::path out = scratch("budget_stopped");
  writeComparison(summary, out.string());
  const std::string report = readFile(out / "report.md");
  EXPECT_NE(report.find("| 4.8 (3/13 poses) |"), std::string::npos) << report;
  EXPECT_NE(report.find("stopped (time budget)"), std::string::npos) << report;
  EXPECT_NE(readFile(out / "speed_vs_error.gp").find("(3/13 poses)"), std::string::npos)
      << "point label or note";
}

TEST(MergeAndReport, FourResolutionsGiveTable1ColumnsInOrder) {
  const fs::path out = scratch("merged_resolutions");
  std::vector<nlohmann::json> cells;
  std::vector<std::string> sources;
  for (int resolution : {80, 40, 20, 60}) {  // cells finish in any order
    cells.push_back(madeSummary(2, 10, resolution));
    sources.push_back(std::string("r").append(std::to_string(resolution)));
  }
  writeComparison(mergeSummaries(cells, sources), out.string());
  const std::string report = readFile(out / "report.md");
  EXPECT_NE(report.find("| part | resolution 20 | resolution 40 | resolution 60 | resolution 80 |"),
            std::string::npos)
      << report;
  // bone CD 4 ms per iteration → 2 s per 500; thesis 30.03 / 37.43 / 56.03 / 67.10.
  EXPECT_NE(report.find("| bone CD | 2 / 30.03 (15×) | 2 / 37.43 (18.7×) | 2 / 56.03 (28×) | "
                        "2 / 67.10 (33.5×) |"),
            std::string::npos)
      << report;
}

TEST(MergeAndReport, SaysWhichPosesTheBtSoftBodyRatioCovers) {
  // btSoftBody exploded at step 3 of 13 at resolution 40: its median covers 4 poses, and the
  // ratio says so in its own section and in the scaling table, with FibreMSS's threads.
  nlohmann::json two = madeSummary(2, 1.5, 40), one = madeSummary(2, 2.5, 40);
  two["runs"][0]["threads"] = 2;  // 105 ms per step
  one["runs"][0]["method"] = "fibremss:threads=1";
  one["runs"][0]["threads"] = 1;  // 175 ms per step
  RunMetrics softBody;
  softBody.scene = "thigh13";
  softBody.method = "btsoftbody";
  softBody.msPerStep = 2100;
  softBody.msPerTimeStep = 210;  // 10 world substeps per pose
  softBody.threads = 1;
  softBody.steps = 4;
  softBody.poses = 13;
  softBody.exploded = true;
  softBody.failedStep = 3;
  nlohmann::json softBodyRun = toJson(softBody);
  softBodyRun["resolution"] = 40;
  for (nlohmann::json* run : {&two["runs"][0], &one["runs"][0]}) {
    (*run)["steps"] = 13;
    (*run)["poses"] = 13;
  }
  two["runs"].push_back(softBodyRun);
  const nlohmann::json merged = mergeSummaries({two, one}, {"two", "one"});
  ASSERT_EQ(merged["btsoftbody_ratio"].size(), 2u);
  EXPECT_NEAR(merged["btsoftbody_ratio"][0]["ratio"].get<double>(), 20.0, 1e-9);
  EXPECT_EQ(merged["btsoftbody_ratio"][0]["poses"], 4);
  EXPECT_EQ(merged["btsoftbody_ratio"][0]["of"], 13);
  const fs::path out = scratch("softbody_partial");
  writeComparison(merged, out.string());
  const std::string report = readFile(out / "report.md");
  EXPECT_NE(report.find("- FibreMSS (2 threads) vs btSoftBody (Bullet, 1 thread): 20.0× per "
                        "simulated step (one pose), 140.0× per time step (a FibreMSS iteration "
                        "against a Bullet substep) (thigh13, resolution 40, 4/13 poses: "
                        "btsoftbody exploded (a link past 3×) at step 3; the ratio covers those "
                        "poses only)"),
            std::string::npos)
      << report;
  EXPECT_NE(report.find("- FibreMSS (1 thread) vs btSoftBody (Bullet, 1 thread): 12.0×"),
            std::string::npos)
      << report;
  // The scaling table: rows by threads, each with its own ratio and the poses it covers.
  EXPECT_NE(report.find("| 2.1e+03 | 175 | 12.0× (4/13 poses) | 84× |"), std::string::npos)
      << report;
  EXPECT_NE(report.find("| 2.1e+03 | 105 | 20.0× (4/13 poses) | 140× |"), std::string::npos)
      << report;
}

TEST(MergeAndReport, TakesAnAnalyticScenesMeasuresAndNamesABadField) {
  RunMetrics run;
  run.scene = run.analytic.type = "sphere-planes";
  run.method = "fibremss";
  run.analytic.contact.push_back({.pose = 1, .approachMm = 2, .radiusMm = 5, .exactRadiusMm = 5.5});
  nlohmann::json summary = {
      {"scene", "sphere-planes"}, {"machine", machineJson()}, {"runs", {toJson(run)}}};
  const nlohmann::json merged = mergeSummaries({summary, summary}, {"a", "b"});
  ASSERT_EQ(merged["runs"].size(), 2u);
  EXPECT_EQ(merged["runs"][1]["analytic"], toJson(run)["analytic"]);
  summary["runs"][0]["analytic"]["contact"][0]["radius_mm"] = "wide";
  try {
    mergeSummaries({summary}, {"a"});
    FAIL() << "a text where a radius belongs was taken";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("runs[0].analytic.contact[0].radius_mm"),
              std::string::npos)
        << e.what();
  }
}

TEST(MergeAndReport, RejectsSomethingThatIsNotASummary) {
  const fs::path dir = scratch("not_summary");
  fs::create_directories(dir);
  std::ofstream(dir / "summary.json") << "{\"scene\": \"x\"}";
  EXPECT_THROW(mergeSummaries({readSummary(dir.string())}, {dir.string()}), InputError);
  EXPECT_THROW(readSummary((dir / "missing").string()), InputError);
}

/// pinch's fronts as measured (ms per pose, RMS to the reference [mm]): fourteen
/// points within 7–600 ms and 0.9–2.3 mm, seven of them within a factor 2 in time.
nlohmann::json pinchLikeSummary() {
  const std::tuple<const char*, double, double, int> runs[] = {
      {"calculix", 13214, 0, 1},
      {"fibremss:iterations=35", 7.38, 2.153, 2},
      {"fibremss", 11.7, 1.985, 2},
      {"fibremss:iterations=140", 25.8, 1.939, 2},
      {"fibremss:iterations=280", 45.2, 2.161, 2},
      {"fibremss:resolution=20", 6.80, 2.236, 2},
      {"fibremss:resolution=80", 24.9, 1.849, 2},
      {"self-reference", 92.5, 1.971, 2},
      {"btsoftbody:iterations=8", 80.1, 1.247, 1},
      {"btsoftbody", 95.6, 1.090, 1},
      {"btsoftbody:iterations=32", 126.7, 0.927, 1},
      {"fem:substeps=75", 88.4, 1.835, 1},
      {"fem", 183.5, 1.995, 1},
      {"fem:substeps=300", 605.5, 2.140, 1}};
  nlohmann::json list = nlohmann::json::array();
  for (const auto& [method, ms, rms, threads] : runs) {
    RunMetrics run;
    run.scene = "pinch";
    run.method = method;
    run.msPerStep = ms;
    run.rmsToReferenceMm = rms;
    run.threads = threads;
    list.push_back(toJson(run));
  }
  return {{"scene", "pinch"},
          {"reference",
           {{"gates", {{"refinement_mm", 0.289}, {"increments_mm", 0.143}, {"passed", true}}}}},
          {"runs", list}};
}

TEST(PlotLayout, LogRangesPutTheValuesWithinTheirMarginsAndTicsInsideThem) {
  const LogRange range = logRangeOver({0.93, 2.24, 0.289, NAN, -1}, 0.1, 0.2);
  EXPECT_NEAR(range.fraction(0.289), 0.1, 1e-9);
  EXPECT_NEAR(range.fraction(2.24), 0.8, 1e-9);
  for (const double tic : logTics(range)) {
    EXPECT_GE(tic, range.low);
    EXPECT_LE(tic, range.high);
  }
  // 1.27 decades from 0.216 to 4.0 mm: 0.2 and 5 fall outside.
  EXPECT_EQ(logTics(range), (std::vector<double>{0.5, 1, 2}));
  // One value: half a decade around it, so its neighbours' tics still show.
  const LogRange one = logRangeOver({3.0}, 0, 0);
  EXPECT_NEAR(std::log10(one.high / one.low), 0.5, 1e-9);
  EXPECT_NEAR(one.fraction(3.0), 0.5, 1e-9);
  EXPECT_EQ(logTics(logRangeOver({1e-3, 1e3}, 0, 0)).size(), 7u) << "over 4 decades: 10^k only";
}

TEST(PlotLayout, CrowdedLabelsCoverNoOtherLabelNorPointAndStayInsideThePlot) {
  // Seven points within a label's width of each other, on two lines.
  std::vector<LabelledPoint> points;
  std::vector<std::vector<LabelledPoint>> lines(2);
  for (int i = 0; i < 7; ++i) {
    points.push_back(
        {0.2 + 0.02 * i, 0.5 + 0.01 * (i % 3), "iterations=" + std::to_string(35 << i)});
    lines[static_cast<size_t>(i % 2)].push_back(points.back());
  }
  const PlotBox note = labelBox("the reference FAILS a gate", 0.5, 0.96, "center");
  const std::vector<PlotLabel> labels = placeLabels(points, lines, {note});
  ASSERT_EQ(labels.size(), points.size());
  for (size_t a = 0; a < labels.size(); ++a) {
    const PlotBox& box = labels[a].box;
    EXPECT_GE(box.left, 0);
    EXPECT_LE(box.right, 1);
    EXPECT_GE(box.bottom, 0);
    EXPECT_LE(box.top, 1);
    EXPECT_EQ(overlapArea(box, note), 0);
    for (size_t b = a + 1; b < labels.size(); ++b)
      EXPECT_EQ(overlapArea(box, labels[b].box), 0) << labels[a].text << " / " << labels[b].text;
    for (const LabelledPoint& p : points)
      EXPECT_FALSE(p.x > box.left && p.x < box.right && p.y > box.bottom && p.y < box.top)
          << labels[a].text << " covers the point of " << p.text;
  }
}

TEST(PlotLayout, EachPointIsLabelledOnceWithItsVariantAndTheBandIsTheLargerGate) {
  const fs::path out = scratch("pinch_like_plot");
  writeComparison(pinchLikeSummary(), out.string());
  const std::string script = readFile(out / "speed_vs_error.gp");
  // The default runs join every line of their family but are labelled once (per terminal).
  const auto count = [&](const std::string& text) {
    size_t n = 0;
    for (size_t at = 0; (at = script.find(text, at)) != std::string::npos; at += text.size()) ++n;
    return n;
  };
  EXPECT_EQ(count(" \"fibremss\" at graph"), 2u) << script;
  EXPECT_EQ(count("\"iterations=140\" at graph"), 2u) << "the variant: the legend names the family";
  EXPECT_EQ(count("fibremss:iterations"), 0u) << script;
  EXPECT_EQ(count("first 0.289"), 2u) << "the band: the larger of the two gates' moves";
  EXPECT_NE(script.find("set yrange"), std::string::npos);
  std::string problem;
  EXPECT_TRUE(wellFormedXml(readFile(out / "speed_vs_error.svg"), problem)) << problem;
}

TEST(MergeAndReport, RanksOnlyWhenTheIncrementGateIsComputedAndPasses) {
  nlohmann::json summary = pinchLikeSummary();
  nlohmann::json& gates = summary["reference"]["gates"];
  gates = {{"return_mm", 0},           {"refinement_mm", 0.289}, {"refinement_poses", 2},
           {"spread_mm", 1.04},        {"solved_poses", 2},      {"poses", 7},
           {"increments_scale", 0.125}};
  // Written before the increment gate existed (or not in the cache): not computed, no ranking.
  std::string report = reportMarkdown(summary, {});
  EXPECT_NE(report.find("- increments halved (x0.125 of the default 2.5 deg / 1 mm): moves it — "
                        "RMS: not computed"),
            std::string::npos)
      << report;
  EXPECT_NE(report.find("**No ranking**"), std::string::npos);
  gates["increments_mm"] = 0.143;
  gates["increments_poses"] = 2;
  report = reportMarkdown(summary, {});
  EXPECT_NE(report.find("moves it 0.143 mm RMS over 2/7 poses against a third of the methods' "
                        "spread 0.347 mm: passes"),
            std::string::npos)
      << report;
  EXPECT_NE(report.find("**Ranking**"), std::string::npos) << report;
  gates["increments_mm"] = 0.35;  // above a third of the spread
  report = reportMarkdown(summary, {});
  EXPECT_NE(report.find("spread 0.347 mm: FAILS"), std::string::npos) << report;
  EXPECT_NE(report.find("**No ranking**"), std::string::npos);
}

}  // namespace
}  // namespace fibremss

namespace fibremss {
namespace {

/// A run for a synthetic summary: its method, ms per pose and RMS to the reference (NaN: none).
nlohmann::json madeRun(const std::string& method, double ms, double rmsToReference) {
  RunMetrics run;
  run.scene = "fusiform";
  run.method = method;
  run.msPerStep = ms;
  run.rmsToReferenceMm = rmsToReference;
  run.threads = 1;
  return toJson(run);
}

/// The report's verdict: from its heading to the next one.
std::string verdictOf(const std::string& report) {
  const size_t start = report.find("## Verdict");
  return start == std::string::npos ? ""
                                    : report.substr(start, report.find("\n## ", start + 1) - start);
}

TEST(Verdict, RanksNothingByTheDistanceToFibreMSSsOwnRunWithoutAReference) {
  // No reference: FibreMSS, btSoftBody and the FEM only have their distance to FibreMSS's own
  // run at dt/8, which is FibreMSS's convergence and ranks no method.
  nlohmann::json summary = {
      {"scene", "thigh13"}, {"machine", machineJson()}, {"runs", nlohmann::json::array()}};
  const std::pair<const char*, double> distances[] = {{"fibremss", 1.13},
                                                      {"fibremss:integrator=rk4+iterations=9", 2},
                                                      {"btsoftbody", 5.42},
                                                      {"fem", 9.58}};
  for (const auto& [method, rms] : distances) {
    nlohmann::json run = madeRun(method, 100, NAN);
    run["rms_to_self_reference_mm"] = rms;
    summary["runs"].push_back(run);
  }
  const fs::path out = scratch("no_reference_verdict");
  writeComparison(summary, out.string());
  const std::string report = readFile(out / "report.md");
  const std::string verdict = verdictOf(report);
  EXPECT_EQ(report.find("## Verdict"), report.find("\n## ") + 1) << "the report opens with it";
  EXPECT_NE(verdict.find("**No accuracy ranking on this scene**: no CalculiX reference"),
            std::string::npos)
      << verdict;
  EXPECT_EQ(verdict.find("most accurate"), std::string::npos) << verdict;
  EXPECT_EQ(report.find("**Ranking**"), std::string::npos) << report;
  EXPECT_NE(report.find("RMS to self-ref. [mm] (FibreMSS's convergence)"), std::string::npos);
  const std::string script = readFile(out / "speed_vs_error.gp");
  EXPECT_NE(script.find("FibreMSS's convergence, not accuracy"), std::string::npos) << script;
  EXPECT_NE(script.find("integrator=rk4+iterations=9"), std::string::npos) << "FibreMSS's variant";
  EXPECT_EQ(script.find("btsoftbody"), std::string::npos) << "drawn against FibreMSS's own run";
  EXPECT_EQ(script.find("\"fem"), std::string::npos) << script;
}

TEST(Verdict, NamesTheMostAccurateRunAndThoseMostAccuratePerMillisecondWhenTheGatesPass) {
  nlohmann::json summary = pinchLikeSummary();
  summary["reference"]["gates"] = {
      {"return_mm", 0},    {"refinement_mm", 0.289}, {"increments_mm", 0.1}, {"spread_mm", 1.3},
      {"solved_poses", 2}, {"refinement_poses", 2},  {"increments_poses", 2}};
  const std::string verdict = verdictOf(reportMarkdown(summary, {}));
  EXPECT_NE(verdict.find("Against the CalculiX reference (every gate passes)**: most accurate "
                         "**btsoftbody:iterations=32** (RMS to the reference 0.927 mm, 127 ms "
                         "per pose)"),
            std::string::npos)
      << verdict;
  // The front, fastest first: resolution 20 (6.8 ms), then each run more accurate than every
  // faster one; the FEM runs and iterations=280 are slower and farther than some other run.
  const size_t front = verdict.find("Most accurate per millisecond");
  ASSERT_NE(front, std::string::npos) << verdict;
  const std::string line = verdict.substr(front);
  EXPECT_LT(line.find("fibremss:resolution=20 (6.8 ms"), line.find("fibremss (11.7 ms"));
  EXPECT_LT(line.find("fibremss (11.7 ms"), line.find("btsoftbody:iterations=8 (80.1 ms"));
  EXPECT_EQ(line.find("fem"), std::string::npos) << "every FEM run is beaten: " << line;
  EXPECT_EQ(line.find("iterations=280"), std::string::npos) << line;
}

TEST(Verdict, SaysTheGatesWereNotComputedRatherThanThatTheyFail) {
  // `--no-gates`: the return step is solved with the reference, the other gates are not.
  nlohmann::json summary = pinchLikeSummary();
  summary["reference"]["gates"] = {{"return_mm", 1e-6}, {"spread_mm", 1.3}, {"solved_poses", 2}};
  const fs::path out = scratch("no_gates");
  writeComparison(summary, out.string());
  std::string report = readFile(out / "report.md");
  EXPECT_NE(verdictOf(report).find("gates were not computed"), std::string::npos) << report;
  EXPECT_EQ(report.find("fails a gate"), std::string::npos) << report;
  std::string script = readFile(out / "speed_vs_error.gp");
  EXPECT_EQ(script.find("FAILS"), std::string::npos) << script;
  EXPECT_NE(script.find("gates were not computed"), std::string::npos) << script;

  summary["reference"]["gates"]["refinement_mm"] = 0.5;  // above a third of the spread
  summary["reference"]["gates"]["refinement_poses"] = 2;
  writeComparison(summary, out.string());
  report = readFile(out / "report.md");
  EXPECT_NE(verdictOf(report).find("fails a gate"), std::string::npos) << report;
  script = readFile(out / "speed_vs_error.gp");
  EXPECT_NE(script.find("the reference fails a gate"), std::string::npos) << script;

  // A pose ccx did not solve, gates not computed: both said, neither called a failed gate.
  summary["reference"]["gates"] = {{"spread_mm", 1.3},
                                   {"solved_poses", 1},
                                   {"failures", "reference pose 1: muscle m: ccx stopped"}};
  writeComparison(summary, out.string());
  report = readFile(out / "report.md");
  EXPECT_NE(verdictOf(report).find("ccx did not solve every pose"), std::string::npos) << report;
  EXPECT_NE(verdictOf(report).find("gates were not computed"), std::string::npos) << report;
  EXPECT_EQ(report.find("fails a gate"), std::string::npos) << report;

  // A gate's cells partly stored: the verdict says which gate and how far it is.
  summary["reference"]["gates"] = {
      {"return_mm", 1e-6},
      {"spread_mm", 1.3},
      {"solved_poses", 2},
      {"not_computed", "one level finer: 2 of 13 muscles' cells stored"}};
  writeComparison(summary, out.string());
  report = readFile(out / "report.md");
  EXPECT_NE(verdictOf(report).find("gates were not computed (one level finer: 2 of 13 muscles' "
                                   "cells stored)"),
            std::string::npos)
      << report;
}

/// Why ccx stopped stoppedReferenceSummary's reference at pose 6.
const std::string kStopWhy = "muscle iliacus: *ERROR: increment size smaller than minimum";

/// hip-pelvis-like: ccx solved poses 0-5 of 19 and stopped at pose 6 after its retry (kStopWhy);
/// every gate over those poses passes.
nlohmann::json stoppedReferenceSummary() {
  nlohmann::json summary = pinchLikeSummary();
  const std::string& why = kStopWhy;
  summary["reference"]["gates"] = {
      {"return_not_applicable", "ccx stopped the reference at pose 6, before the motion's end"},
      {"refinement_mm", 0.289},
      {"increments_mm", 0.1},
      {"spread_mm", 1.3},
      {"poses", 19},
      {"solved_poses", 6},
      {"refinement_poses", 6},
      {"increments_poses", 6},
      {"stopped", why}};
  summary["reference"]["poses"] = nlohmann::json::array();
  for (int p = 0; p < 19; ++p)
    summary["reference"]["poses"].push_back({{"solved", p < 6}, {"failure", p < 6 ? "" : why}});
  return summary;
}

TEST(Verdict, NamesAMuscleAJudgedGatesSolveStoppedAloneWhereverItRanks) {
  // The one-level-finer solve stopped one muscle alone at pose 2: the others keep poses 0-5, and
  // wherever it ranks the limited muscle is named with its poses, read back from the gates.
  nlohmann::json summary = stoppedReferenceSummary();
  for (auto& run : summary["runs"]) run["rms_to_reference_poses"] = 6;
  const fs::path out = scratch("limited_muscle");
  const std::string ranked =
      "ranked over poses 0\u20135 of 19: ccx did not solve pose 6 (" + kStopWhy + ") or later";
  summary["reference"]["gates"]["limited_muscles"] = {{{"muscle", "psoas"},
                                                       {"index", 1},
                                                       {"poses", 2},
                                                       {"solve", "one level finer"},
                                                       {"why", "muscle psoas: ccx stopped"}}};
  writeComparison(summary, out.string());
  const std::string limited = readFile(out / "report.md");
  const std::string muscle =
      ranked +
      "; psoas over poses 0\u20131: ccx did not solve its pose 2 in the one level finer solve "
      "(muscle psoas: ccx stopped)";
  EXPECT_NE(verdictOf(limited).find(muscle + ")**: most accurate"), std::string::npos)
      << verdictOf(limited);
  EXPECT_NE(limited.find("finished every pose it covers; " + muscle), std::string::npos) << limited;
  EXPECT_NE(readFile(out / "speed_vs_error.gp").find(muscle), std::string::npos)
      << "the plot's note";
}

TEST(MergeAndReport, ThePlotSaysPosesAreCutOnlyWhereTheReferenceItselfIsCut) {
  // ccx stopped the reference at pose 6 and a gate's solve (attachment x1.5) has a continuum cut
  // of its own: the gate's cut is no reason for the reference's unsolved poses.
  nlohmann::json summary = stoppedReferenceSummary();
  summary["reference"]["gates"]["excluded"] =
      "attachment distance x1.5: poses 5 to 18 of 19: no continuum equilibrium";
  const fs::path out = scratch("gate_cut");
  writeComparison(summary, out.string());
  const std::string cut = "poses (the others: no continuum equilibrium";
  EXPECT_EQ(readFile(out / "speed_vs_error.gp").find(cut), std::string::npos);

  // The reference's own cut from pose 6: said.
  for (int p = 6; p < 19; ++p)
    summary["reference"]["poses"][p] = {
        {"solved", false}, {"failure", ""}, {"excluded", "no continuum equilibrium"}};
  summary["reference"]["gates"].erase("stopped");
  writeComparison(summary, out.string());
  EXPECT_NE(readFile(out / "speed_vs_error.gp").find("reference: 6/19 " + cut), std::string::npos)
      << readFile(out / "speed_vs_error.gp");
}

TEST(Verdict, RanksOverThePosesBeforeWhereCcxStoppedTheReferenceAndSaysSoWhereverItRanks) {
  nlohmann::json summary = stoppedReferenceSummary();
  const std::string& why = kStopWhy;
  // The FEM runs stopped on their time budget: `fem` after the ranked poses is ranked over them,
  // `fem:substeps=75` before their end is not.
  for (auto& run : summary["runs"]) {
    const std::string method = run["method"];
    if (method.rfind("fem", 0) == 0) run["interrupted"] = true;
    run["rms_to_reference_poses"] = method == "fem:substeps=75" ? 3 : 6;
  }
  const fs::path out = scratch("stopped_reference");
  writeComparison(summary, out.string());
  const std::string report = readFile(out / "report.md");
  const std::string ranked =
      "ranked over poses 0\u20135 of 19: ccx did not solve pose 6 (" + why + ") or later";
  EXPECT_NE(verdictOf(report).find("Against the CalculiX reference (every gate passes; " + ranked +
                                   ")**: most accurate **btsoftbody:iterations=32**"),
            std::string::npos)
      << verdictOf(report);
  EXPECT_NE(report.find("**Ranking** by each method's best RMS to the reference over the runs "
                        "that finished every pose it covers; " +
                        ranked),
            std::string::npos)
      << report;
  EXPECT_NE(report.find("Poses solved: 6/19 (13 not solved: ccx stopped at pose 6, see below)"),
            std::string::npos)
      << report;
  EXPECT_EQ(report.find("- pose 7 not solved"), std::string::npos) << "the stop is said once";
  EXPECT_EQ(report.find("No ranking"), std::string::npos) << report;
  const size_t start = report.find("**Ranking**");
  const std::string ranking = report.substr(start, report.find("\n## ", start) - start);
  EXPECT_NE(ranking.find(". fem: 2 mm"), std::string::npos) << ranking;
  EXPECT_EQ(ranking.find("fem:substeps=75"), std::string::npos) << ranking;
  EXPECT_NE(readFile(out / "speed_vs_error.gp").find(ranked), std::string::npos)
      << "the plot's note";

  // The one-level-finer solve stopped at pose 2: the ranking covers poses 0-1, read back from
  // the summary's gates.
  summary["reference"]["gates"]["refinement_poses"] = 2;
  summary["reference"]["gates"]["gated_poses"] = 2;
  summary["reference"]["gates"]["gate_stop"] = "one level finer pose 2: " + why;
  writeComparison(summary, out.string());
  const std::string gated = readFile(out / "report.md");
  EXPECT_NE(verdictOf(gated).find("ranked over poses 0\u20131 of 19: no judged gate covers pose "
                                  "2 or later (ccx did not solve it in the one level finer pose 2"),
            std::string::npos)
      << verdictOf(gated);
  summary["reference"]["gates"].erase("gated_poses");
  writeComparison(summary, out.string());
  EXPECT_NE(verdictOf(readFile(out / "report.md")).find("the reference fails a gate"),
            std::string::npos)
      << "without the stop said, a finer solve over fewer poses fails its gate";
  summary["reference"]["gates"]["refinement_poses"] = 6;

  // Stopped in the first posed pose: nothing to rank over.
  summary["reference"]["gates"]["solved_poses"] =
      summary["reference"]["gates"]["refinement_poses"] =
          summary["reference"]["gates"]["increments_poses"] = 1;
  writeComparison(summary, out.string());
  EXPECT_NE(verdictOf(readFile(out / "report.md"))
                .find("ccx stopped the reference at pose 1, before 2 poses to rank over"),
            std::string::npos)
      << verdictOf(readFile(out / "report.md"));
}

/// A cylinder-stretch run: effective ν and volume change [%] at its last pose.
nlohmann::json stretchRun(const std::string& method, double ms, double nu, double volumePct) {
  RunMetrics run;
  run.scene = run.analytic.type = "cylinder-stretch";
  run.method = method;
  run.msPerStep = ms;
  run.analytic.poissonRatio = nu;
  run.analytic.exactPoissonRatio = 0.49;
  run.analytic.volumeChangePct = volumePct;
  run.analytic.exactVolumeChangePct = 0.19;
  return toJson(run);
}

TEST(Verdict, RanksAnAnalyticCaseByTheEffectivePoissonRatioAsWellAsTheVolume) {
  // A run stopped short of its state keeps the volume nearest the exact answer (0.06 points)
  // but its sides have barely contracted (ν 0.2): by volume alone it would rank first.
  const nlohmann::json summary = {
      {"scene", "cylinder-stretch"},
      {"machine", machineJson()},
      {"runs",
       {stretchRun("fibremss:iterations=5", 10, 0.2, 0.25),
        stretchRun("fibremss", 275, 0.489, 0.61), stretchRun("btsoftbody", 98, 0.268, 4.6)}}};
  const std::string report = reportMarkdown(summary, {});
  EXPECT_NE(report.find("1. fibremss: effective ν off exact 0.001, volume off exact 0.42 points"),
            std::string::npos)
      << report;
  EXPECT_NE(report.find("2. btsoftbody:"), std::string::npos) << report;
  EXPECT_NE(verdictOf(report).find("most accurate **fibremss** (effective ν off exact 0.001"),
            std::string::npos)
      << verdictOf(report);
  EXPECT_NE(verdictOf(report).find("By the CalculiX reference: no ranking"), std::string::npos);
}

TEST(ErrorDecomposition, SplitsEachRunsErrorIntoModelSolverAndDiscretisation) {
  nlohmann::json summary = pinchLikeSummary();
  summary["reference"]["gates"] = {
      {"return_mm", 0},    {"refinement_mm", 0.1},  {"increments_mm", 0.1}, {"spread_mm", 1.3},
      {"solved_poses", 2}, {"refinement_poses", 2}, {"increments_poses", 2}};
  nlohmann::json equilibrium = madeRun("equilibrium", 900, 0.39);
  equilibrium["rms_to_equilibrium_mm"] = 0;
  summary["runs"].push_back(equilibrium);
  for (auto& run : summary["runs"]) {
    if (run["method"] == "fibremss") {
      run["rms_to_reference_mm"] = 2.5;
      run["rms_to_equilibrium_mm"] = 1.9;
      run["rms_to_finer_resolution_mm"] = 0.21;
    }
    if (run["method"] == "fibremss:resolution=80") run["rms_to_equilibrium_mm"] = 1.7;
  }
  const std::string report = reportMarkdown(summary, {});
  EXPECT_NE(report.find("| fibremss | 11.7 | 2.5 | 0.39 | 1.9 | 0.21 |"), std::string::npos)
      << report;
  EXPECT_NE(report.find("| fibremss:iterations=140 | 25.8 | 1.94 | 0.39 | — (no shared pose) | — "
                        "(no run at twice its resolution) |"),
            std::string::npos)
      << report;
  EXPECT_NE(report.find("| fibremss:resolution=80 | 24.9 | 1.85 | — (another model"),
            std::string::npos)
      << "its converged state is not the equilibrium run's: " << report;
  EXPECT_NE(report.find("| btsoftbody | 95.6 | 1.09 | — (no converged run of this method's model)"),
            std::string::npos)
      << report;
  // Without the equilibrium run, the dt/8 self-reference's figures stand beside the dash.
  nlohmann::json withoutEquilibrium = summary;
  withoutEquilibrium["runs"].erase(withoutEquilibrium["runs"].size() - 1);
  withoutEquilibrium["runs"][2]["rms_to_self_reference_mm"] = 1.2;
  EXPECT_NE(reportMarkdown(withoutEquilibrium, {})
                .find("| fibremss | 11.7 | 2.5 | — (no `equilibrium` run; the dt/8 "
                      "self-reference's 1.97) | — (no `equilibrium` run; to the dt/8 "
                      "self-reference 1.2) | 0.21 |"),
            std::string::npos)
      << reportMarkdown(withoutEquilibrium, {});
  summary.erase("reference");
  for (auto& run : summary["runs"]) run["rms_to_reference_mm"] = nullptr;
  EXPECT_NE(reportMarkdown(summary, {})
                .find("| fibremss | 11.7 | — (no reference) | — (no "
                      "reference) | 1.9 | 0.21 |"),
            std::string::npos);
}

TEST(ErrorDecomposition, TakesAVariantOfTheModelSectionsDampingForASolverSetting) {
  nlohmann::json summary = pinchLikeSummary();
  nlohmann::json equilibrium = madeRun("equilibrium", 900, 0.39);
  equilibrium["rms_to_equilibrium_mm"] = 0;
  summary["runs"].push_back(equilibrium);
  for (const char* method : {"fibremss:model.damping=5", "fibremss:simulation.iterations=70",
                             "fibremss:model.density=2000"}) {
    nlohmann::json run = madeRun(method, 30, 1.5);
    run["rms_to_equilibrium_mm"] = 1.25;
    summary["runs"].push_back(run);
  }
  const std::string report = reportMarkdown(summary, {});
  EXPECT_NE(report.find("| fibremss:model.damping=5 | 30 | 1.5 | 0.39 | 1.25 |"), std::string::npos)
      << "damping slows the muscles, not where they settle: " << report;
  EXPECT_NE(report.find("| fibremss:simulation.iterations=70 | 30 | 1.5 | 0.39 | 1.25 |"),
            std::string::npos)
      << report;
  EXPECT_NE(report.find("| fibremss:model.density=2000 | 30 | 1.5 | — (another model"),
            std::string::npos)
      << report;
}

TEST(ErrorDecomposition, MeasuresEachResolutionAgainstTheRunAtTwiceIt) {
  std::vector<RunMetrics> runs(3);
  const std::vector<btVector3> surface = {{0, 0, 0}, {0.01f, 0, 0}};
  for (size_t r = 0; r < runs.size(); ++r) {
    runs[r].method =
        std::vector<std::string>{"fibremss:resolution=20", "fibremss", "fibremss:resolution=80"}[r];
    std::vector<btVector3> moved;
    for (const btVector3& p : surface) moved.push_back(p + btVector3(0, 0, 0.001f * btScalar(r)));
    runs[r].poseSurfaces.push_back(moved);
  }
  fillFinerResolution(runs, 40);
  EXPECT_NEAR(runs[0].rmsToFinerResolutionMm, 1.0, 1e-4) << "resolution 20 against the default 40";
  EXPECT_NEAR(runs[1].rmsToFinerResolutionMm, 1.0, 1e-4) << "40 against 80";
  EXPECT_TRUE(std::isnan(runs[2].rmsToFinerResolutionMm)) << "no run at 160";
}

TEST(Verdict, TimeToAccuracyIsFibreMSSsOwnConvergenceNotAnotherModelsDistanceToIt) {
  // btSoftBody lies 0.3 mm from FibreMSS's converged state and is faster than FibreMSS's run
  // 0.4 mm from it; only the latter converges to that state.
  nlohmann::json summary = {{"scene", "fusiform"}, {"runs", nlohmann::json::array()}};
  summary["runs"].push_back(madeRun("equilibrium", 500, NAN));
  const std::tuple<const char*, double, double> runs[] = {{"btsoftbody", 50, 0.3},
                                                          {"fibremss:iterations=140", 80, 0.4}};
  for (const auto& [method, ms, worst] : runs) {
    nlohmann::json run = madeRun(method, ms, NAN);
    run["rms_to_equilibrium_mm"] = run["worst_pose_rms_to_equilibrium_mm"] = worst;
    summary["runs"].push_back(run);
  }
  const std::string report = reportMarkdown(summary, {});
  EXPECT_NE(report.find("of it): **80 ms per pose** (fibremss:iterations=140)"), std::string::npos)
      << report;
  EXPECT_NE(report.find("FibreMSS's own convergence, not its accuracy"), std::string::npos);
}

TEST(FrontMethods, SweepTheKnobThatEndsTheDefaultSolversIterations) {
  const MuscleSystemDef defaults{};
  const std::vector<std::string> front = frontMethods({"fibremss"}, defaults);
  EXPECT_NE(std::find(front.begin(), front.end(),
                      "fibremss:" + fibreCostKnob(defaults.stepSettings).key + "=x2"),
            front.end());
  MuscleSystemDef counted;
  counted.stepSettings.stopRule = StopRule::Iterations;
  EXPECT_EQ(frontMethods({"fibremss"}, counted),
            (std::vector<std::string>{"fibremss:iterations=x0.5", "fibremss",
                                      "fibremss:iterations=x2", "fibremss:iterations=x4",
                                      "fibremss:resolution=x0.5", "fibremss:resolution=x2"}));
  MuscleSystemDef residual;
  residual.integrator = Integrator::Projective;
  residual.stepSettings.stopRule = StopRule::Residual;
  EXPECT_EQ(frontMethods({"fibremss", "fem"}, residual),
            (std::vector<std::string>{"fibremss:tolerance=x2", "fibremss",
                                      "fibremss:tolerance=x0.5", "fibremss:tolerance=x0.25",
                                      "fibremss:resolution=x0.5", "fibremss:resolution=x2",
                                      "fem:substeps=x0.5", "fem", "fem:substeps=x2"}))
      << "a tolerance costs more the smaller it is; the iterations are only its cap";
}

}  // namespace
TEST(Methods, EachMethodParsesWithItsOwnKnobsOnly) {
  for (const Method& method : methods()) {
    const std::string name = method.name;
    EXPECT_EQ(parseMethod(name).family, name);
    EXPECT_EQ(methodOf(name + ":iterations=2"), &method);
    EXPECT_NE(methodsHelp().find(name), std::string::npos) << name;
    if (method.sceneVariants) continue;
    for (const std::string& knob : method.knobs)
      EXPECT_EQ(parseMethod(name + ":" + knob + "=x2").overrides,
                std::vector<std::string>{knob + "=x2"});
    EXPECT_THROW(parseMethod(name + ":no_such_knob=2"), InputError) << name;
  }
  EXPECT_THROW(parseMethod("equilibrium:iterations=2"), InputError);
  EXPECT_EQ(defaultMethods(),
            (std::vector<std::string>{"fibremss", "self-reference", "btsoftbody", "fem"}));
}

TEST(Methods, EachRoleButComparedIsOneRunsAndTakesNoVariants) {
  EXPECT_EQ(roleOf(kReferenceMethod), MethodRole::Reference);
  EXPECT_EQ(findMethod(kReferenceMethod), nullptr) << "the reference is no method";
  for (const MethodRole role : {MethodRole::SelfReference, MethodRole::Equilibrium})
    EXPECT_EQ(std::ranges::count(methods(), role, &Method::role), 1);
  for (const Method& method : methods()) {
    const std::string name = method.name;
    EXPECT_EQ(roleOf(name), method.role) << name;
    EXPECT_EQ(roleOf(name + ":iterations=2"), MethodRole::Compared) << name;
    if (method.role == MethodRole::Compared) continue;
    EXPECT_TRUE(method.knobs.empty() && !method.sceneVariants) << name;
  }
}

TEST(Methods, EachFrontHoldsItsMethodAndVariantsOfItsOwnKnobs) {
  const MuscleSystemDef defaults{};
  for (const Method& method : methods()) {
    if (!method.front) continue;
    const std::vector<std::string> front = method.front(defaults);
    EXPECT_NE(std::find(front.begin(), front.end(), method.name), front.end()) << method.name;
    for (const std::string& point : front) {
      if (point == method.name) continue;
      const MethodSpec spec = parseMethod(point);
      EXPECT_EQ(spec.family, method.name);
      ASSERT_EQ(spec.overrides.size(), 1u) << point;
      const std::string key = spec.overrides[0].substr(0, spec.overrides[0].find('='));
      EXPECT_NE(std::find(method.knobs.begin(), method.knobs.end(), key), method.knobs.end())
          << point << ": the plot draws no line for its knob";
    }
  }
}

}  // namespace fibremss
