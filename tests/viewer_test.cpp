// `fibremss view`: the camera's projection, and screenshots rendered by the real viewer
// (GLFW, OpenGL through Mesa, under Xvfb in CI) read back with stb: each muscle is drawn
// where an independent simulation of the same steps puts it, the background elsewhere.
#include "fibremss/viewer/Viewer.h"

#include <gtest/gtest.h>
#include <stb_image.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "fibremss/MuscleSystem.h"
#include "fibremss/Scene.h"
#include "fibremss/VtkFiles.h"
#include "support/Process.h"

namespace fibremss {
namespace {

using testing::runProcess;
using testing::TemporaryDirectory;
using viewer::Camera;
using viewer::Vec3;

/// An 8-bit RGB image read back from a PNG file by stb_image.
struct Image {
  int width = 0, height = 0;
  std::vector<unsigned char> rgb;

  explicit Image(const std::string& path) {
    int channels = 0;
    unsigned char* data = stbi_load(path.c_str(), &width, &height, &channels, 3);
    if (!data) return;
    rgb.assign(data, data + size_t(3) * width * height);
    stbi_image_free(data);
  }
  std::array<int, 3> at(int x, int y) const {
    const size_t i = 3 * (size_t(y) * width + x);
    return {rgb[i], rgb[i + 1], rgb[i + 2]};
  }
};

/// The viewer's background (RenderSettings::background) in 8 bits.
bool isBackground(const std::array<int, 3>& c) {
  const std::array<int, 3> background{41, 43, 51};
  for (int k = 0; k < 3; ++k)
    if (std::abs(c[k] - background[k]) > 3) return false;
  return true;
}

/// The first muscle's palette colour is red; lit, it stays clearly red (bones are ivory).
bool isFirstMuscleColour(const std::array<int, 3>& c) {
  return c[0] > c[1] + 40 && c[0] > c[2] + 40;
}

/// The first muscle's colour at `point`'s pixel and the pixels 2 px around it.
void expectFirstMuscleAround(const Image& image, const Camera& camera, const Vec3& point) {
  const viewer::Pixel pixel = camera.project(point, image.width, image.height);
  ASSERT_TRUE(pixel.visible);
  for (int dx : {-2, 0, 2})
    for (int dy : {-2, 0, 2}) {
      const std::array<int, 3> c = image.at(int(pixel.x) + dx, int(pixel.y) + dy);
      EXPECT_TRUE(isFirstMuscleColour(c)) << "at " << pixel.x + dx << "," << pixel.y + dy << ": "
                                          << c[0] << " " << c[1] << " " << c[2];
    }
}

/// The eight corners of the box [lower, upper].
std::vector<Vec3> corners(const Vec3& lower, const Vec3& upper) {
  std::vector<Vec3> points;
  for (int corner = 0; corner < 8; ++corner)
    points.push_back({corner & 1 ? upper[0] : lower[0], corner & 2 ? upper[1] : lower[1],
                      corner & 4 ? upper[2] : lower[2]});
  return points;
}

TEST(ViewerCamera, FramesPointsCentredAndFillingNineTenthsOfTheBindingSide) {
  Camera camera;
  const std::vector<Vec3> box = corners({-1, 0, 2}, {3, 1, 4});
  // A wide image, a square one and a narrow one (the view beside a wide panel).
  for (const auto& [width, height] :
       std::vector<std::pair<int, int>>{{640, 480}, {300, 300}, {200, 600}})
    for (float azimuth : {0.0f, 70.0f, 200.0f}) {
      camera.setAngles(azimuth, 25);
      camera.frame(box, float(width) / float(height));
      float left = 1e9f, right = -1e9f, top = 1e9f, bottom = -1e9f;
      for (const Vec3& p : box) {
        const viewer::Pixel pixel = camera.project(p, width, height);
        ASSERT_TRUE(pixel.visible) << width << "x" << height << " azimuth " << azimuth;
        left = std::min(left, pixel.x);
        right = std::max(right, pixel.x);
        top = std::min(top, pixel.y);
        bottom = std::max(bottom, pixel.y);
      }
      EXPECT_NEAR(left + right, float(width), 0.5f) << width << "x" << height << " " << azimuth;
      EXPECT_NEAR(top + bottom, float(height), 0.5f) << width << "x" << height << " " << azimuth;
      EXPECT_NEAR(std::max((right - left) / float(width), (bottom - top) / float(height)), 0.9f,
                  1e-3f)
          << width << "x" << height << " azimuth " << azimuth;
    }
  // Up in the world is up in the image; behind the eye is not visible.
  camera.setAngles(0, 0);
  camera.frame(box, 640.0f / 480);
  EXPECT_LT(camera.project({1, 1, 3}, 640, 480).y, camera.project({1, 0, 3}, 640, 480).y);
  const Vec3 eye = camera.eye();
  EXPECT_FALSE(
      camera.project({2 * eye[0] - 1, 2 * eye[1] - 0.5f, 2 * eye[2] - 3}, 640, 480).visible);
}

/// The box around the pixels of `image` that are not background, in columns [fromX, width).
struct Drawn {
  int left = 1 << 30, right = -1, top = 1 << 30, bottom = -1;
};
Drawn drawnBox(const Image& image, int fromX) {
  Drawn box;
  for (int y = 0; y < image.height; ++y)
    for (int x = fromX; x < image.width; ++x)
      if (!isBackground(image.at(x, y))) {
        box.left = std::min(box.left, x);
        box.right = std::max(box.right, x);
        box.top = std::min(box.top, y);
        box.bottom = std::max(box.bottom, y);
      }
  return box;
}

/// The scene drawn in the view (columns viewX to the image's width) is centred in it and spans
/// 85 to 95 % of its binding side (framed at 90 %, the pixels' edges blurred).
void expectFramed(const Image& image, int viewX) {
  const Drawn box = drawnBox(image, viewX);
  const float width = float(image.width - viewX), height = float(image.height);
  ASSERT_GE(box.right, box.left);
  EXPECT_NEAR(0.5f * float(box.left + box.right + 1) - float(viewX), width / 2, 0.03f * width);
  EXPECT_NEAR(0.5f * float(box.top + box.bottom + 1), height / 2, 0.03f * height);
  const float fill =
      std::max(float(box.right - box.left + 1) / width, float(box.bottom - box.top + 1) / height);
  EXPECT_GT(fill, 0.85f);
  EXPECT_LT(fill, 0.95f);
}

/// Each muscle's surface centroid after `steps` steps of `scene`, simulated here the way
/// `fibremss run` steps (one pose per step), independently of the viewer.
std::vector<Vec3> muscleCentroids(const std::string& name, int steps) {
  const LoadedScene scene = loadScene(name);
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  MuscleSystem system(scene.simulation);
  std::vector<BoneHandle> bones;
  for (const auto& bone : prepared.bones) bones.push_back(system.addBone(bone));
  std::vector<MuscleHandle> muscles;
  for (const auto& muscle : prepared.muscles) muscles.push_back(system.addMuscle(muscle, bones));
  for (int s = 0; s < steps; ++s) {
    for (size_t b = 0; b < bones.size(); ++b)
      system.setBoneTransform(bones[b], scene.bonePose(b, std::min(s, scene.poseCount - 1)));
    system.step();
  }
  std::vector<Vec3> centroids;
  for (MuscleHandle muscle : muscles) {
    btVector3 sum(0, 0, 0);
    for (const btVector3& v : system.surface(muscle)) sum += v;
    sum /= btScalar(system.surface(muscle).size());
    centroids.push_back({float(sum.x()), float(sum.y()), float(sum.z())});
  }
  return centroids;
}

/// A 320 × 240 screenshot without the panel, muscles coloured by muscle_id, after `steps`.
viewer::ViewerOptions screenshotOptions(const std::string& png, int steps) {
  viewer::ViewerOptions options;
  options.steps = steps;
  options.screenshot = png;
  options.width = 320;
  options.height = 240;
  options.colourBy = "muscle_id";
  options.hideUi = true;
  options.azimuthDeg = 20;
  options.elevationDeg = 10;
  return options;
}

TEST(Viewer, ScreenshotDrawsTheMuscleWhereTheSimulationPutsItAndBackgroundElsewhere) {
  TemporaryDirectory directory("fibremss_viewer_test");
  viewer::ViewerOptions options =
      screenshotOptions((directory.path() / "fusiform.png").string(), 3);
  options.scene = "fusiform";
  const viewer::ViewerResult result = viewer::runViewer(options);
  EXPECT_EQ(result.steps, 3);

  const Image image(options.screenshot);
  ASSERT_EQ(image.width, result.width);
  ASSERT_EQ(image.height, result.height);
  for (const auto& [x, y] : std::vector<std::pair<int, int>>{{1, 1},
                                                             {image.width - 2, 1},
                                                             {1, image.height - 2},
                                                             {image.width - 2, image.height - 2}})
    EXPECT_TRUE(isBackground(image.at(x, y))) << "corner " << x << "," << y;

  const std::vector<Vec3> centroids = muscleCentroids("fusiform", 3);
  ASSERT_EQ(centroids.size(), 1u);
  ASSERT_EQ(result.viewX, 0);  // no panel
  ASSERT_EQ(result.viewWidth, image.width);
  // The muscle covers its projected centroid and a few pixels around it.
  expectFirstMuscleAround(image, result.camera, centroids[0]);
  // And it is a shape, not a smear: a minority of the image.
  size_t muscle = 0;
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) muscle += isFirstMuscleColour(image.at(x, y)) ? 1 : 0;
  EXPECT_GT(muscle, 200u);
  EXPECT_LT(muscle, size_t(image.width) * image.height / 2);
  expectFramed(image, 0);
}

/// Dear ImGui's dark style draws histograms in this orange (ImGuiCol_PlotHistogram).
bool isHistogramColour(const std::array<int, 3>& c) {
  return std::abs(c[0] - 230) < 12 && std::abs(c[1] - 179) < 12 && c[2] < 20;
}

TEST(Viewer, ThePanelGraphsEveryStepFitsItsTextAndTheSceneIsFramedBesideIt) {
  TemporaryDirectory directory("fibremss_viewer_panel_test");
  viewer::ViewerOptions options = screenshotOptions((directory.path() / "panel.png").string(), 3);
  options.scene = "fusiform";
  options.hideUi = false;
  options.width = 560;  // a panel of 280 px: long lines must wrap
  options.height = 720;
  options.azimuthDeg = 90;  // the bars across: a wide scene in a narrow view
  options.elevationDeg = 30;
  const viewer::ViewerResult result = viewer::runViewer(options);
  EXPECT_EQ(result.stepSamples, 3u);
  EXPECT_EQ(result.panelOverflow, 0.0f);
  EXPECT_EQ(result.counter, 2);  // the third step moved the bones to pose 2
  const Image image(options.screenshot);
  ASSERT_EQ(image.width, 560);
  ASSERT_EQ(result.viewX, 280);
  size_t bars = 0;
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < result.viewX; ++x) bars += isHistogramColour(image.at(x, y)) ? 1 : 0;
  EXPECT_GT(bars, 300u);  // three bars of the step-time graph
  expectFramed(image, result.viewX);
}

TEST(Viewer, CommandWritesAScreenshotColouredByFibreStretchWithThePanel) {
  TemporaryDirectory directory("fibremss_view_cli_test");
  const std::string png = (directory.path() / "view.png").string();
  const auto run = runProcess(
      std::string(FIBREMSS_CLI) + " view fusiform --frames 2 --size 400x300 " +
      "--colour-by fibre_stretch --draw particles,fibres --opacity 0.6 " + "--screenshot " + png);
  ASSERT_EQ(run.exitCode, 0) << run.output;
  EXPECT_NE(run.output.find("wrote " + png + " (400x300, after 2 steps)"), std::string::npos)
      << run.output;
  const Image image(png);
  ASSERT_EQ(image.width, 400);
  ASSERT_EQ(image.height, 300);
  std::set<std::array<int, 3>> colours;
  size_t background = 0;
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) {
      colours.insert(image.at(x, y));
      background += isBackground(image.at(x, y)) ? 1 : 0;
    }
  EXPECT_GT(colours.size(), 50u);  // shaded surfaces, the colour map, the panel's text
  EXPECT_GT(background, size_t(image.width) * image.height / 10);
}

TEST(Viewer, DrawsParticlesAndFibresThroughTheWorldsDebugDrawer) {
  TemporaryDirectory directory("fibremss_view_debug_test");
  auto changedPixels = [&](const std::string& draw) {
    const std::string png = (directory.path() / (draw + ".png")).string();
    const auto run = runProcess(std::string(FIBREMSS_CLI) + " view fusiform --opacity 0 " +
                                "--hide-ui --size 300x200 --draw " + draw + " --screenshot " + png);
    EXPECT_EQ(run.exitCode, 0);
    const Image image(png);
    size_t count = 0;
    for (int y = 0; y < image.height; ++y)
      for (int x = 0; x < image.width; ++x) count += isBackground(image.at(x, y)) ? 0 : 1;
    return count;
  };
  // Surfaces hidden: the bones alone, then the bones with the particles and fibres in between.
  EXPECT_GT(changedPixels("particles,fibres"), changedPixels("none") + 100);
}

TEST(Viewer, ARunsDirectoryShowsTheSceneItRan) {
  TemporaryDirectory directory("fibremss_view_run_test");
  const std::string out = (directory.path() / "run").string();
  const std::string png = (directory.path() / "run.png").string();
  ASSERT_EQ(runProcess(std::string(FIBREMSS_CLI) + " run fusiform --steps 1 --frame-every 0 " +
                       "--out " + out + " > /dev/null")
                .exitCode,
            0);
  const auto view = runProcess(std::string(FIBREMSS_CLI) + " view " + out +
                               " --frames 1 --size 200x150 --screenshot " + png);
  ASSERT_EQ(view.exitCode, 0);
  EXPECT_NE(view.output.find("wrote " + png + " (200x150, after 1 steps)"), std::string::npos)
      << view.output;
  // A directory that is not a run's is bad input.
  EXPECT_EQ(runProcess(std::string(FIBREMSS_CLI) + " view " + directory.path().string() +
                       " --screenshot " + png)
                .exitCode,
            2);
}

TEST(Viewer, PlaysARunsFramesAndDrawsTheMuscleWhereTheFrameSaysWithoutItsScene) {
  TemporaryDirectory directory("fibremss_view_frames_test");
  const std::filesystem::path out = directory.path() / "run";
  ASSERT_EQ(runProcess(std::string(FIBREMSS_CLI) + " run fusiform --steps 3 --frame-every 1 " +
                       "--out " + out.string() + " > /dev/null 2>&1")
                .exitCode,
            0);
  // The frames alone: nothing left to simulate from.
  std::filesystem::remove(out / "scene.json");
  const PolyDataFile frame = readVtp((out / "frames/muscle0_fusiform_surface_00002.vtp").string());
  btVector3 sum(0, 0, 0);
  for (const btVector3& v : frame.points) sum += v;
  sum /= btScalar(frame.points.size());
  const Vec3 centroid{float(sum.x()), float(sum.y()), float(sum.z())};

  // The third frame.
  viewer::ViewerOptions options = screenshotOptions((directory.path() / "frames.png").string(), 2);
  options.runDir = out.string();
  const viewer::ViewerResult result = viewer::runViewer(options);
  EXPECT_EQ(result.steps, 2);
  const Image image(options.screenshot);
  ASSERT_EQ(image.width, 320);
  EXPECT_TRUE(isBackground(image.at(1, 1)));
  expectFirstMuscleAround(image, result.camera, centroid);
  // Through the command: frames beyond the last show the last, coloured by an array only the
  // frames have; a collection without frames is bad input.
  const std::string png = (directory.path() / "cli.png").string();
  const auto view =
      runProcess(std::string(FIBREMSS_CLI) + " view " + out.string() +
                 " --frames 9 --colour-by penetration --size 200x150 --screenshot " + png);
  ASSERT_EQ(view.exitCode, 0) << view.output;
  EXPECT_NE(view.output.find("(200x150, frame 2)"), std::string::npos) << view.output;
  // Played from the first frame to the end, the panel's counter and slider both say the last,
  // counted from 0 as --frames counts; the run's long path wraps inside the panel.
  options.steps = 0;
  options.play = true;
  options.hideUi = false;
  options.width = 520;
  const viewer::ViewerResult played = viewer::runViewer(options);
  EXPECT_EQ(played.steps, 2);
  EXPECT_EQ(played.counter, 2);
  EXPECT_EQ(played.slider, 2);
  EXPECT_EQ(played.step, 2);  // the run's summary names the frame's step (at its exact time)
  EXPECT_EQ(played.panelOverflow, 0.0f);
  std::ofstream(out / "run.pvd") << "<VTKFile type=\"Collection\"><Collection/></VTKFile>";
  EXPECT_EQ(runProcess(std::string(FIBREMSS_CLI) + " view " + out.string() + " --screenshot " +
                       png + " 2>/dev/null")
                .exitCode,
            2);
}

TEST(ViewerColourBar, EveryArrayStatesWhatItMeasures) {
  for (const std::string& array : viewer::colourArrays())
    EXPECT_EQ(viewer::unitOf(array, "mm").empty(), array == "muscle_id") << array;
  EXPECT_EQ(viewer::unitOf("displacement", "mm"), "mm");
  EXPECT_EQ(viewer::unitOf("penetration", "m"), "m");
  EXPECT_EQ(viewer::unitOf("fibre_stretch", "mm"), "current / rest length along the fibres");
}

TEST(ViewerColourBar, AStretchRangeIsSymmetricInItsLogarithmAndStaysAboveZero) {
  // The tear scene stretches its cylinder far past 2 before it parts: a range symmetric about
  // 1 in the stretch itself would reach below 0, where no stretch can lie.
  TemporaryDirectory directory("fibremss_view_stretch_test");
  const std::filesystem::path out = directory.path() / "run";
  ASSERT_EQ(runProcess(std::string(FIBREMSS_CLI) + " run tear --out " + out.string() +
                       " > /dev/null 2>&1")
                .exitCode,
            0);
  viewer::ViewerOptions options = screenshotOptions((directory.path() / "tear.png").string(), 40);
  options.runDir = out.string();
  options.colourBy = "fibre_stretch";
  const viewer::ViewerResult result = viewer::runViewer(options);
  EXPECT_GT(result.colourHigh, 2.0f);
  EXPECT_GT(result.colourLow, 0.0f);
  EXPECT_NEAR(result.colourLow * result.colourHigh, 1.0f, 1e-5f);
}

/// The probe's colour (RenderSettings::toolColour), lit: green above red and blue.
bool isToolColour(const std::array<int, 3>& c) {
  return c[1] > c[0] + 40 && c[1] > c[2] + 40;
}

/// The rightmost column of row `y` in the first muscle's colour (-1: none).
int rightmostMuscleColumn(const Image& image, int y) {
  for (int x = image.width - 1; x >= 0; --x)
    if (isFirstMuscleColour(image.at(x, y))) return x;
  return -1;
}

/// fusiform from the front at its last pose, with the panel: undisturbed, and with the pointer's
/// `tool` pressed at `fromMm` right of the belly's axis and dragged to `toMm` in the view plane
/// (as many steps on each).
struct PointerShots {
  viewer::ViewerResult undisturbed, touched;  ///< the two sessions
  std::string undisturbedPng, touchedPng;     ///< their screenshots
  viewer::Pixel to;                           ///< where the pointer ended, in the scene's view
};
PointerShots pointerShots(const TemporaryDirectory& directory, viewer::ToolMode tool, float fromMm,
                          float toMm) {
  viewer::ViewerOptions options = screenshotOptions("", 3);
  options.scene = "fusiform";
  options.width = 720;
  options.height = 480;
  options.hideUi = false;
  options.azimuthDeg = 0;
  options.elevationDeg = 0;
  viewer::ViewerOptions framing = options;
  framing.screenshot = (directory.path() / "framing.png").string();
  const viewer::ViewerResult framed = viewer::runViewer(framing);
  auto pixel = [&](float xMm) {  // the belly's middle at the last pose: y = -15 mm
    return framed.camera.project({xMm * 1e-3f, -0.015f, 0}, framed.viewWidth, framed.height);
  };
  const viewer::Pixel from = pixel(fromMm);
  PointerShots shots;
  shots.to = pixel(toMm);
  EXPECT_TRUE(from.visible && shots.to.visible);
  options.tool = tool;
  options.pointer = viewer::dragPath(from.x, from.y, shots.to.x, shots.to.y);
  viewer::ViewerOptions still = options;
  still.tool = viewer::ToolMode::Camera;
  still.pointer.clear();
  still.steps = 3 + int(options.pointer.size()) + 1;
  shots.undisturbedPng = still.screenshot = (directory.path() / "undisturbed.png").string();
  shots.undisturbed = viewer::runViewer(still);
  shots.touchedPng = options.screenshot = (directory.path() / "touched.png").string();
  shots.touched = viewer::runViewer(options);
  return shots;
}

TEST(Viewer, AProbeDrivenByThePointerPressesTheMuscleAndThePanelShowsItsForce) {
  TemporaryDirectory directory("fibremss_viewer_test");
  // From 40 mm right of the axis to 12 mm: the 5 mm probe 13 mm into the 20 mm belly.
  const PointerShots shots = pointerShots(directory, viewer::ToolMode::Probe, 40, 12);
  EXPECT_GT(shots.touched.toolForce, 0) << "the panel showed no force on the probe";
  EXPECT_EQ(shots.undisturbed.toolForce, 0);
  const Image before(shots.undisturbedPng), after(shots.touchedPng);
  ASSERT_EQ(before.width, after.width);
  const int row = int(shots.to.y), probeColumn = shots.touched.viewX + int(shots.to.x);
  // The probe is drawn where the pointer left it.
  EXPECT_TRUE(isToolColour(after.at(probeColumn, row)));
  // The muscle's edge on the probe's row moved in, under the probe (by at least 3 px).
  const int edgeBefore = rightmostMuscleColumn(before, row);
  const int edgeAfter = rightmostMuscleColumn(after, row);
  ASSERT_GT(edgeBefore, shots.touched.viewX);
  EXPECT_GT(edgeBefore, probeColumn);  // undisturbed, the belly reaches past the probe's centre
  EXPECT_LT(edgeAfter, edgeBefore - 3);
}

TEST(Viewer, TheGrabPullsTheParticleUnderThePointerAlongTheViewPlane) {
  TemporaryDirectory directory("fibremss_viewer_test");
  // Pressed on the belly's axis, dragged 30 mm right.
  const PointerShots shots = pointerShots(directory, viewer::ToolMode::Grab, 0, 30);
  EXPECT_GT(shots.touched.toolForce, 0) << "the panel showed no pull";
  const Image before(shots.undisturbedPng), after(shots.touchedPng);
  const int row = int(shots.to.y);
  // The belly follows the pointer: its edge on that row moved right (by at least 3 px).
  EXPECT_GT(rightmostMuscleColumn(after, row), rightmostMuscleColumn(before, row) + 3);
}

TEST(Viewer, TheBladeDrivenByThePointerAcrossTheBellyCutsItsSprings) {
  TemporaryDirectory directory("fibremss_viewer_test");
  // From 40 mm right of the axis to 40 mm left of it, across the 20 mm belly: the blade's edge,
  // along the view direction, sweeps a plane across the muscle.
  const PointerShots shots = pointerShots(directory, viewer::ToolMode::Blade, 40, -40);
  RecordProperty("cut_springs", std::to_string(shots.touched.cutSprings));
  EXPECT_GT(shots.touched.cutSprings, 0u) << "the panel showed no spring cut";
  EXPECT_EQ(shots.undisturbed.cutSprings, 0u);
}

TEST(Viewer, BadArgumentsAreInputErrorsBeforeAnyWindowOpens) {
  const std::string cli = std::string(FIBREMSS_CLI) + " view ";
  EXPECT_EQ(runProcess(cli + "no-such-scene --screenshot /tmp/x.png").exitCode, 2);
  EXPECT_EQ(runProcess(cli + "fusiform --colour-by pressure --screenshot /tmp/x.png").exitCode, 2);
  // Penetration is in a run's frames, not in a scene stepped live.
  EXPECT_EQ(runProcess(cli + "fusiform --colour-by penetration --screenshot /tmp/x.png").exitCode,
            2);
  EXPECT_EQ(runProcess(cli + "fusiform --draw sparks --screenshot /tmp/x.png").exitCode, 2);
  EXPECT_EQ(runProcess(cli + "fusiform --size 12 --screenshot /tmp/x.png").exitCode, 2);
  EXPECT_EQ(runProcess(cli + "fusiform --camera 1 --screenshot /tmp/x.png").exitCode, 2);
  // A scene stepped live plays without end: no picture to take after it.
  EXPECT_EQ(runProcess(cli + "fusiform --play --screenshot /tmp/x.png").exitCode, 2);
  EXPECT_EQ(runProcess(cli + "fusiform --tool scalpel --screenshot /tmp/x.png").exitCode, 2);
  EXPECT_EQ(runProcess(cli + "fusiform --drag 1,2,3 --screenshot /tmp/x.png").exitCode, 2);
}

}  // namespace
}  // namespace fibremss
