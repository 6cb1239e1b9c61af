// Bone motions from OpenSim motion files (.mot / .sto) and the splitting of large jumps between
// poses into sub-poses.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "fibremss/Error.h"
#include "fibremss/Scene.h"
#include "support/Process.h"

namespace fs = std::filesystem;
using fibremss::InputError;
using fibremss::LoadedScene;
using fibremss::loadScene;

namespace {

const fs::path kMotions = fs::path(FIBREMSS_SHARED_DATA_DIR) / "opensim-motions";

/// A .mot text: the header (with `headerExtra` lines), the names and the rows as given.
std::string motText(const std::string& headerExtra, const std::string& names,
                    const std::string& rows) {
  return "Coordinates\nversion=1\n" + headerExtra + "\nendheader\n" + names + "\n" + rows;
}

const std::string kNames = "time\thip_flexion_r\thip_adduction_r";
const std::string kRows = "  0.0\t  10.0\t -2.0\n  0.1\t 20.0\t -4.0\n  0.2\t 30.0\t -6.0\n";

struct SceneFiles {
  fibremss::testing::TemporaryDirectory directory{"fibremss_scene_motion"};

  std::string write(const std::string& name, const std::string& text) const {
    const fs::path path = directory.path() / name;
    std::ofstream(path) << text;
    return path.string();
  }
};

/// A femur-like box (mm) driven by `motion`; `simulation` goes into the scene as it is.
std::string boneScene(const std::string& motion, const std::string& simulation = "{}") {
  return R"({"units": "mm", "simulation": )" + simulation + R"(, "bones": [
    {"name": "femur", "mesh": {"generator": {"type": "box", "centre": [0, 0, -60], "size": [10, 10, 80]}},
     "motion": )" +
         motion + "}]}";
}

/// The angle of a rigid transform's rotation [°].
double turnDegrees(const btTransform& transform) {
  return 2 * std::acos(std::min(1.0, std::abs(double(transform.getRotation().w())))) * 180 / M_PI;
}

/// A femur-like box driven by one coordinate ("hip_flexion_r" unless `column`) of `mot`.
std::string motionScene(const SceneFiles& files, const std::string& mot,
                        const std::string& column = "hip_flexion_r") {
  const std::string path = files.write("walk.mot", mot);
  return files.write("walk.json", boneScene(R"({"type": "opensim", "file": ")" + path +
                                                R"(", "coordinates": [{"column": ")" + column +
                                                R"(", "axis": [1, 0, 0]}]})",
                                            R"({"max_step_deg": 0})"));
}

/// The InputError loading a scene on the .mot text `mot` gives (a failure when it loads).
InputError errorOf(const std::string& mot) {
  const SceneFiles files;
  try {
    loadScene(motionScene(files, mot));
  } catch (const InputError& error) {
    EXPECT_NE(error.source().find("walk.mot"), std::string::npos) << error.what();
    return error;
  }
  ADD_FAILURE() << "no InputError for:\n" << mot;
  return InputError("", "", "");
}

}  // namespace

TEST(MotFile, HeaderColumnsAndRows) {
  const SceneFiles files;
  const LoadedScene scene =
      loadScene(motionScene(files, motText("nRows=3\nnColumns=3\ninDegrees=yes", kNames, kRows)));
  ASSERT_EQ(scene.poseCount, 3);
  EXPECT_DOUBLE_EQ(scene.poseLabels[1], 0.1);  // the rows' times
  for (int p = 0; p < 3; ++p) EXPECT_NEAR(turnDegrees(scene.bonePose(0, p)), 10.0 * (p + 1), 1e-3);
  // Newer .sto files leave out the counts; CRLF line ends are read too; radians.
  const LoadedScene radians = loadScene(motionScene(
      files, "version=1\r\ninDegrees=no\r\nendheader\r\ntime\tq\r\n0 0.5\r\n1 0.25\r\n", "q"));
  ASSERT_EQ(radians.poseCount, 2);
  EXPECT_NEAR(turnDegrees(radians.bonePose(0, 1)), 0.25 * 180 / M_PI, 1e-3);
}

TEST(MotFile, BadInputNamesTheFileTheLineAndWhatWasExpected) {
  const std::string header = "nRows=3\nnColumns=3\ninDegrees=yes";
  // No endheader.
  InputError e = errorOf("Coordinates\nnRows=3\ninDegrees=yes\n");
  EXPECT_NE(e.problem().find("endheader"), std::string::npos) << e.what();
  // A count that is not a number, an unknown inDegrees, none at all.
  e = errorOf(motText("nRows=three\ninDegrees=yes", kNames, kRows));
  EXPECT_EQ(e.where(), "line 3");
  EXPECT_NE(e.problem().find("nRows"), std::string::npos) << e.what();
  e = errorOf(motText("inDegrees=maybe", kNames, kRows));
  EXPECT_NE(e.problem().find("inDegrees=yes"), std::string::npos) << e.what();
  e = errorOf(motText("nRows=3", kNames, kRows));
  EXPECT_NE(e.problem().find("degrees or radians"), std::string::npos) << e.what();
  // Names that disagree with nColumns; a row of the wrong length; a value that is no number.
  e = errorOf(motText(header, "time\thip_flexion_r", kRows));
  EXPECT_NE(e.problem().find("expected 3 column names"), std::string::npos) << e.what();
  e = errorOf(motText(header, kNames, "0 1 2\n0.1 1\n0.2 1 2\n"));
  EXPECT_EQ(e.where(), "line 9");
  EXPECT_NE(e.problem().find("expected 3 values"), std::string::npos) << e.what();
  e = errorOf(motText(header, kNames, "0 1 2\n0.1 1 x2\n0.2 1 2\n"));
  EXPECT_EQ(e.where(), "line 9");
  EXPECT_NE(e.problem().find("hip_adduction_r"), std::string::npos) << e.what();
  // Fewer rows than nRows; time going back.
  e = errorOf(motText(header, kNames, "0 1 2\n0.1 1 2\n"));
  EXPECT_NE(e.problem().find("expected 3 rows"), std::string::npos) << e.what();
  e = errorOf(motText(header, kNames, "0 1 2\n0.2 1 2\n0.1 1 2\n"));
  EXPECT_EQ(e.where(), "line 10");
  EXPECT_NE(e.problem().find("time to increase"), std::string::npos) << e.what();
}

TEST(OpenSimMotion, DegreesAndRadiansGiveTheSamePosesAboutThePivot) {
  const SceneFiles files;
  const std::string motion = R"({"type": "opensim", "file": "%s", "pivot": [0, 0, 0],
      "coordinates": [{"column": "flex", "axis": [-1, 0, 0]}, {"column": "add", "axis": [0, -1, 0]}]})";
  auto sceneFor = [&](const std::string& mot) {
    std::string text = motion;
    text.replace(text.find("%s"), 2, mot);
    return files.write(mot + ".json", boneScene(text, R"({"max_step_deg": 0})"));
  };
  files.write("deg.mot", "inDegrees=yes\nendheader\ntime\tflex\tadd\n0.5 30 0\n0.6 30 20\n");
  files.write("rad.mot", "inDegrees=no\nendheader\ntime\tflex\tadd\n0.5 " +
                             std::to_string(30 * M_PI / 180) + " 0\n0.6 " +
                             std::to_string(30 * M_PI / 180) + " " +
                             std::to_string(20 * M_PI / 180) + "\n");
  const LoadedScene degrees = loadScene(sceneFor("deg.mot"));
  const LoadedScene radians = loadScene(sceneFor("rad.mot"));
  ASSERT_EQ(degrees.poseCount, 2);
  EXPECT_DOUBLE_EQ(degrees.poseLabels[1], 0.6);  // labels are the rows' times
  const btVector3 knee(0, 0, -0.1f);
  for (int p = 0; p < 2; ++p)
    EXPECT_LT((degrees.bonePose(0, p) * knee - radians.bonePose(0, p) * knee).length(), 1e-6);
  // Flexion about -x turns the knee (below the pivot) towards -y by 30°.
  const btVector3 flexed = degrees.bonePose(0, 0) * knee;
  EXPECT_NEAR(flexed.y(), -0.1 * std::sin(M_PI / 6), 1e-6);
  EXPECT_NEAR(flexed.z(), -0.1 * std::cos(M_PI / 6), 1e-6);
  // Body-fixed order: the second coordinate turns about the axis as the first left it; the
  // knee (on the turned long axis) then swings sideways, away from the x = 0 plane.
  const btVector3 both = degrees.bonePose(0, 1) * knee;
  EXPECT_NEAR(both.length(), 0.1, 1e-6);
  EXPECT_NEAR(std::abs(both.x()), 0.1 * std::sin(M_PI / 9), 1e-6);
}

TEST(OpenSimMotion, TimeWindowEveryAndMissingColumn) {
  const SceneFiles files;
  std::string rows;
  for (int r = 0; r <= 10; ++r) rows += std::to_string(0.1 * r) + " " + std::to_string(r) + "\n";
  const std::string mot = files.write("walk.mot", "inDegrees=yes\nendheader\ntime\tq\n" + rows);
  auto motion = [&](const std::string& extra, const std::string& column = "q") {
    return R"({"type": "opensim", "file": ")" + mot + R"(", "coordinates": [{"column": ")" +
           column + R"(", "axis": [1, 0, 0]}])" + extra + "}";
  };
  const LoadedScene window = loadScene(
      files.write("window.json", boneScene(motion(R"(, "time": [0.2, 0.8], "every": 3)"))));
  ASSERT_EQ(window.poseCount, 3);  // rows at 0.2, 0.5, 0.8
  EXPECT_NEAR(window.poseLabels[2], 0.8, 1e-9);
  EXPECT_NEAR(turnDegrees(window.bonePose(0, 1)), 5.0, 1e-3);
  try {
    loadScene(files.write("missing.json", boneScene(motion("", "hip_flexion_r"))));
    ADD_FAILURE() << "no error for a missing column";
  } catch (const InputError& error) {
    EXPECT_EQ(error.where(), "bones[0].motion.coordinates[0].column");
    EXPECT_NE(error.problem().find("walk.mot"), std::string::npos) << error.what();
    EXPECT_NE(error.problem().find("its columns are: 'time', 'q'"), std::string::npos)
        << error.what();
  }
  try {
    loadScene(files.write("empty.json", boneScene(motion(R"(, "time": [5, 6])"))));
    ADD_FAILURE() << "no error for an empty window";
  } catch (const InputError& error) {
    EXPECT_EQ(error.where(), "bones[0].motion.time");
  }
  // Through the command line: exit 2 and the file named.
  const fibremss::testing::ProcessResult result =
      fibremss::testing::runProcess(std::string(FIBREMSS_CLI) + " check " +
                                    files.write("bad.json", boneScene(motion("", "nope"))));
  EXPECT_EQ(result.exitCode, 2);
}

TEST(SubPoses, JumpsFromRestAndBetweenPosesAreSplitAlongTheScrew) {
  const SceneFiles files;
  // A 40° first keyframe (from rest) about a pivot at (0, 0, 10) mm, then 2° more, then 12°.
  const std::string keyframes = R"({"type": "keyframes", "keyframes": [
      {"rotation": {"axis": [1, 0, 0], "angle_deg": 40}, "translation": [0, %A, %B], "label": 40},
      {"rotation": {"axis": [1, 0, 0], "angle_deg": 42}, "translation": [0, %C, %D], "label": 42},
      {"rotation": {"axis": [1, 0, 0], "angle_deg": 54}, "translation": [0, %E, %F], "label": 54}]})";
  // Rotation about pivot c: translation c - R c; c = (0, 0, 10) mm.
  std::string text = keyframes;
  const char* keys[] = {"%A", "%B", "%C", "%D", "%E", "%F"};
  const double angles[] = {40, 42, 54};
  for (int k = 0; k < 3; ++k) {
    const double a = angles[k] * M_PI / 180;
    const double values[2] = {10 * std::sin(a), 10 - 10 * std::cos(a)};
    for (int c = 0; c < 2; ++c)
      text.replace(text.find(keys[2 * k + c]), 2, std::to_string(values[c]));
  }
  const LoadedScene scene = loadScene(files.write("keys.json", boneScene(text)));
  // 40° from rest: 8 poses of 5°; 2°: 1; 12°: 3 of 4°.
  ASSERT_EQ(scene.poseCount, 12);
  const btVector3 pivot(0, 0, 0.01f);
  double previous = 0;
  for (int p = 0; p < scene.poseCount; ++p) {
    const btTransform pose = scene.bonePose(0, p);
    EXPECT_LT((pose * pivot - pivot).length(), 1e-6) << "pose " << p;  // the pivot stays put
    const double turn = turnDegrees(pose);
    EXPECT_LE(std::abs(turn - previous), 5.0 + 1e-3) << "pose " << p;
    // Sub-poses from rest carry the first pose's label; later ones interpolate the labels.
    EXPECT_NEAR(scene.poseLabels[size_t(p)], p < 8 ? 40 : turn, 1e-3) << "pose " << p;
    previous = turn;
  }
  EXPECT_NEAR(turnDegrees(scene.bonePose(0, 7)), 40, 1e-3);
  EXPECT_NEAR(turnDegrees(scene.bonePose(0, 11)), 54, 1e-3);
  ASSERT_FALSE(scene.notes.empty());
  EXPECT_NE(scene.notes[0].find("from rest, split into 8 sub-poses"), std::string::npos)
      << scene.notes[0];
  // max_step_deg 0 (or --set max_step_deg=0) keeps the poses as given.
  EXPECT_EQ(loadScene(files.write("keys.json", boneScene(text)), {"max_step_deg=0"}).poseCount, 3);
  EXPECT_EQ(loadScene(files.write("keys.json", boneScene(text)), {"max_step_deg=20"}).poseCount, 4);
}

TEST(OpenSimMotion, PosesAreNamedByTheirCoordinatesAndTheSubPoseRuleIsStated) {
  const SceneFiles files;
  // Flexion 0 -> 18° in 9° rows, adduction 0 -> -4°: each jump (9.2°) split into two sub-poses.
  const std::string mot = files.write(
      "flex.mot",
      motText("inDegrees=yes", kNames, "0.0\t0.0\t0.0\n0.1\t9.0\t-2.0\n0.2\t18.0\t-4.0\n"));
  const LoadedScene scene = loadScene(files.write(
      "flex.json", boneScene(R"({"type": "opensim", "file": ")" + mot + R"(", "coordinates": [
          {"column": "hip_flexion_r", "axis": [1, 0, 0]},
          {"column": "hip_adduction_r", "axis": [0, 0, 1]}]})")));
  ASSERT_EQ(scene.poseCount, 5);  // 0°, then 4.5° and 9°, then 13.5° and 18°
  EXPECT_EQ(fibremss::poseName(scene, 0), "hip_flexion_r=0°, hip_adduction_r=0°");
  EXPECT_EQ(fibremss::poseName(scene, 1), "hip_flexion_r=4.5°, hip_adduction_r=-1°");
  EXPECT_EQ(fibremss::poseName(scene, 4), "hip_flexion_r=18°, hip_adduction_r=-4°");
  EXPECT_DOUBLE_EQ(scene.poseLabels[4], 0.2);  // the labels stay the rows' times [s]
  ASSERT_FALSE(scene.notes.empty());
  EXPECT_NE(scene.notes[0].find("pose 1 (hip_flexion_r=9°, hip_adduction_r=-2°)"),
            std::string::npos)
      << scene.notes[0];
  EXPECT_NE(scene.notes.back().find("no bone turns more than 5° per step"), std::string::npos)
      << scene.notes.back();
  // A sweep's poses are named by their labels.
  const LoadedScene sweep =
      loadScene(files.write("sweep.json", boneScene(R"({"type": "sweep", "end_deg": 20})")));
  EXPECT_EQ(fibremss::poseName(sweep, 1), "label 5");
}

TEST(OpenSimMotion, SharedGaitFile) {
  const fs::path mot = kMotions / "subject01_walk1_ik_gait2392.mot";
  if (!fs::exists(mot)) GTEST_SKIP() << "shared data not found: " << mot;
  const SceneFiles files;
  const LoadedScene scene = loadScene(files.write(
      "gait.json",
      boneScene(R"({"type": "opensim", "file": ")" + mot.string() +
                    R"(", "coordinates": [{"column": "hip_flexion_r", "axis": [-1, 0, 0]}]})",
                R"({"max_step_deg": 0})")));
  ASSERT_EQ(scene.poseCount, 211);
  EXPECT_DOUBLE_EQ(scene.poseLabels.front(), 0.5);
  EXPECT_DOUBLE_EQ(scene.poseLabels.back(), 4.0);
  double largest = 0;
  for (int p = 0; p < scene.poseCount; ++p)
    largest = std::max(largest, turnDegrees(scene.bonePose(0, p)));
  // The README's range, computed from the file by another tool: -22.32 ... +21.91 degrees.
  EXPECT_NEAR(largest, 22.32, 0.01);
}

TEST(MotFile, ADeviceAFifoADirectoryOrALinkLoopIsRefusedBeforeReading) {
  const SceneFiles files;
  const fs::path dir = files.directory.path();
  ASSERT_EQ(::mkfifo((dir / "fifo.mot").c_str(), 0644), 0);
  fs::create_directory(dir / "folder.mot");
  fs::create_symlink(dir / "loop.mot", dir / "loop.mot");
  for (const std::string& path : {std::string("/dev/zero"), (dir / "fifo.mot").string(),
                                  (dir / "folder.mot").string(), (dir / "loop.mot").string()}) {
    const std::string scene = files.write(
        "scene.json", boneScene(R"({"type": "opensim", "file": ")" + path +
                                R"(", "coordinates": [{"column": "q", "axis": [1, 0, 0]}]})"));
    try {
      loadScene(scene);
      ADD_FAILURE() << path << " accepted";
    } catch (const InputError& error) {
      EXPECT_NE(std::string(error.what()).find(path), std::string::npos) << error.what();
      EXPECT_NE(error.problem().find("cannot open"), std::string::npos) << error.what();
    }
  }
}

TEST(OpenSimMotion, AbsurdAnglesAndPositionsAreRefusedAtLoadNamingTheField) {
  const InputError angle = errorOf(motText("inDegrees=yes", kNames, "0 1e300 0\n0.1 10 0\n"));
  EXPECT_EQ(angle.where(), "row 1, column hip_flexion_r") << angle.what();
  EXPECT_NE(angle.problem().find("within ±3600°"), std::string::npos) << angle.what();
  const SceneFiles files;
  const std::vector<std::pair<std::string, std::string>> far = {
      {R"({"type": "keyframes", "keyframes": [{}, {"translation": [1e38, 0, 0]}]})",
       "bones[0].motion.keyframes[1]"},
      {R"({"type": "sweep", "pivot": [0, 1e38, 0], "end_deg": 10})", "bones[0].motion.pivot"}};
  for (const auto& [motion, field] : far) {
    try {
      loadScene(files.write("far.json", boneScene(motion)));
      ADD_FAILURE() << motion << " accepted";
    } catch (const InputError& error) {
      EXPECT_EQ(error.where(), field) << error.what();
      EXPECT_NE(error.problem().find("beyond the world"), std::string::npos) << error.what();
    }
  }
}

TEST(SubPoses, SplittingIsCappedLikeThePoseCountAndColumnsAreLookedUpByName) {
  const SceneFiles files;
  // Two rows 180° apart split into turns of 0.001°: 180 000 poses, over the cap.
  const std::string mot =
      files.write("turn.mot", "inDegrees=yes\nendheader\ntime\tq\n0 0\n1 180\n");
  const std::string scene = files.write(
      "turn.json", boneScene(R"({"type": "opensim", "file": ")" + mot +
                                 R"(", "coordinates": [{"column": "q", "axis": [1, 0, 0]}]})",
                             R"({"max_step_deg": 0.001})"));
  try {
    loadScene(scene);
    ADD_FAILURE() << "180 000 poses accepted";
  } catch (const InputError& error) {
    EXPECT_EQ(error.where(), "simulation.max_step_deg") << error.what();
    EXPECT_NE(error.problem().find("at most 100000"), std::string::npos) << error.what();
  }
  // 100 000 columns, the last one used: found by name without comparing every pair.
  std::string names = "time", row = "0";
  for (int c = 0; c < 99999; ++c) names += "\tc" + std::to_string(c), row += " 0";
  const std::string wide = files.write("wide.mot", "inDegrees=yes\nendheader\n" + names + "\n" +
                                                       row + "\n0.1" + row.substr(1) + "\n");
  const LoadedScene loaded = loadScene(files.write(
      "wide.json", boneScene(R"({"type": "opensim", "file": ")" + wide +
                             R"(", "coordinates": [{"column": "c99998", "axis": [1, 0, 0]}]})")));
  EXPECT_EQ(loaded.poseCount, 2);
}
