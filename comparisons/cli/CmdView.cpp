// `fibremss view SCENE|RUN_DIR`: the interactive viewer (comparisons/viewer), or with
// --screenshot a PNG after some steps.
#include <algorithm>
#include <cstdio>
#include <memory>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "Commands.h"
#include "SceneArgs.h"
#include "Validators.h"
#include "fibremss/Error.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/viewer/Viewer.h"

namespace fibremss::cli {
namespace {

/// DebugDrawFlag bits from a comma-separated list of names.
int drawFlags(const std::string& list) {
  static const std::vector<std::pair<std::string, int>> kNames{{"particles", kDrawParticles},
                                                               {"springs", kDrawSprings},
                                                               {"fibres", kDrawFibres},
                                                               {"bone-spheres", kDrawBoneSpheres},
                                                               {"contacts", kDrawContacts}};
  int flags = 0;
  std::stringstream names(list);
  for (std::string name; std::getline(names, name, ',');) {
    if (name.empty() || name == "none") continue;
    auto it = std::find_if(kNames.begin(), kNames.end(),
                           [&](const auto& entry) { return entry.first == name; });
    if (it == kNames.end())
      throw InputError("--draw", "",
                       "expected particles, springs, fibres, bone-spheres, contacts or none, "
                       "got '" +
                           name + "'");
    flags |= it->second;
  }
  return flags;
}

struct ViewArgs {
  SceneArgs scene;
  viewer::ViewerOptions options;
  std::string draw = "none";      ///< --draw list
  std::vector<float> camera;      ///< --camera AZIMUTH,ELEVATION[,ZOOM]
  std::string size = "1280x800";  ///< --size WxH
  std::string tool = "camera";    ///< --tool
  std::vector<float> drag;        ///< --drag X0,Y0,X1,Y1
};

void view(ViewArgs& args) {
  viewer::ViewerOptions& options = args.options;
  viewer::chooseSource(args.scene.scene, options);
  options.overrides = args.scene.overrides;
  options.muscleDebugFlags = drawFlags(args.draw);
  if (args.camera.size() < 2 || args.camera.size() > 3)
    throw InputError("--camera", "", "expected AZIMUTH,ELEVATION[,ZOOM] (degrees)");
  options.tool = args.tool == "grab"    ? viewer::ToolMode::Grab
                 : args.tool == "probe" ? viewer::ToolMode::Probe
                 : args.tool == "blade" ? viewer::ToolMode::Blade
                                        : viewer::ToolMode::Camera;
  if (!args.drag.empty() && args.drag.size() != 4)
    throw InputError("--drag", "", "expected X0,Y0,X1,Y1 (pixels of the scene's view)");
  if (!args.drag.empty())
    options.pointer = viewer::dragPath(args.drag[0], args.drag[1], args.drag[2], args.drag[3]);
  options.azimuthDeg = args.camera[0];
  options.elevationDeg = args.camera[1];
  if (args.camera.size() == 3) options.zoom = args.camera[2];
  char x = 0;
  std::istringstream size(args.size);
  if (!(size >> options.width >> x >> options.height) || x != 'x' || options.width < 16 ||
      options.height < 16 || options.width > 8192 || options.height > 8192)
    throw InputError("--size", "",
                     "expected WIDTHxHEIGHT in pixels (16 to 8192), got '" + args.size + "'");
  const viewer::ViewerResult result = viewer::runViewer(options);
  if (options.screenshot.empty()) return;
  const std::string what = options.runDir.empty()
                               ? "after " + std::to_string(result.steps) + " steps"
                               : "frame " + std::to_string(result.steps);  // from 0, as --frames
  std::printf("wrote %s (%dx%d, %s)\n", options.screenshot.c_str(), result.width, result.height,
              what.c_str());
}

}  // namespace

void addViewCommand(CLI::App& app) {
  auto args = std::make_shared<ViewArgs>();
  args->camera = {args->options.azimuthDeg, args->options.elevationDeg, args->options.zoom};
  CLI::App* command = app.add_subcommand(
      "view",
      "Watch a scene step live, or play a run's frames: bones, muscles coloured by an array, "
      "particles, fibres, contacts, the per-part timings");
  command->footer(
      "In the window: space plays or pauses, S or the right arrow steps (a frame of a run), R "
      "resets, the slider scrubs a run's frames (counted from 0, as --frames), the field at the "
      "top opens another scene or run, F frames the scene, H hides the panel, Q quits; "
      "drag to orbit, right or middle drag (or shift+drag) "
      "to pan, the wheel zooms. Without a display, --screenshot works under `xvfb-run -a`.");
  addSceneArgs(*command, args->scene);
  command->get_option("scene")->description(
      "Built-in scene name (see `fibremss scenes`), .json file, or a run's directory (`fibremss "
      "run --out DIR`: its frames are played; without frames its scene.json is stepped live)");
  command->add_option("--screenshot", args->options.screenshot,
                      "Write this PNG after --frames steps and exit (no interaction)");
  command
      ->add_option(
          "--frames", args->options.steps,
          "Steps to take (frames to advance, for a run) before the first picture (default 0: the "
          "scene at rest, the run's first frame)")
      ->check(nonNegativeInteger());
  command
      ->add_option("--colour-by,--color-by", args->options.colourBy,
                   "Colour muscles by fibre_stretch (current/rest length along the fibres), "
                   "displacement (|current - rest|, scene units) or muscle_id; a run's frames also "
                   "by spring_strain, penetration (scene units) or fixed")
      ->capture_default_str();
  command
      ->add_option("--draw", args->draw,
                   "Also draw through the world's btIDebugDraw, comma-separated: particles, "
                   "springs, fibres, bone-spheres, contacts")
      ->capture_default_str();
  command
      ->add_option("--opacity", args->options.surfaceOpacity,
                   "Muscle surfaces' opacity (0 hides them, < 1 shows the particles inside)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  command
      ->add_option("--camera", args->camera,
                   "AZIMUTH,ELEVATION[,ZOOM]: degrees about the up (y) axis and above the "
                   "horizontal, zoom > 1 closer")
      ->delimiter(',')
      ->capture_default_str();
  command->add_option("--size", args->size, "Window size WIDTHxHEIGHT [px]")->capture_default_str();
  command
      ->add_option("--tool", args->tool,
                   "What the left button does at the start (T switches): turn the camera, grab "
                   "a particle, drive a probe or a blade (which cuts) along the view plane")
      ->check(oneOf({"camera", "grab", "probe", "blade"}))
      ->capture_default_str();
  command
      ->add_option("--drag", args->drag,
                   "X0,Y0,X1,Y1: the pointer pressed at X0,Y0 of the scene's view and dragged "
                   "to X1,Y1 with the --tool (a script, one pixel step per frame; with "
                   "--screenshot the PNG follows it)")
      ->delimiter(',');
  command->add_flag("--hide-ui", args->options.hideUi, "Start without the panel (H shows it)");
  command->add_flag(
      "--no-bones", [args](int64_t) { args->options.bones = false; },
      "Do not draw the bone meshes");
  command->add_flag("--play", args->options.play,
                    "Start playing; with --screenshot (a run's frames) the PNG shows the last "
                    "frame, where playing stopped");
  command->add_flag("--loop", args->options.loop,
                    "Past the last pose, sweep the motion back to the first and forth again");
  command->callback([args] { view(*args); });
}

}  // namespace fibremss::cli
