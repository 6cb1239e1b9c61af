#pragma once
// `fibremss view`: an interactive window (GLFW, OpenGL, Dear ImGui) that steps a scene live
// or plays a run's frames:
// bones, muscle surfaces coloured by an array, particles, fibres, springs, bone spheres and
// contacts through the world's btIDebugDraw, play/pause/step/pose, the per-part timings, an
// orbit/pan/zoom camera. With a screenshot path it renders once after some steps, writes a
// PNG and returns (under Xvfb where there is no display).
#include <string>
#include <vector>

#include "fibremss/viewer/Camera.h"

namespace fibremss::viewer {

/// What the pointer's left button does in the scene (T cycles them in the window): turn the
/// camera, grab a muscle particle and drag it along the view plane, drive a probe (a sphere the
/// muscles collide with) along the view plane, or drive a blade (an edge along the view direction)
/// along it, which cuts the springs it sweeps across (MuscleSystem::addBlade). A scene stepped
/// live only.
enum class ToolMode { Camera, Grab, Probe, Blade };

/// One window frame of a scripted pointer (played instead of the mouse, one event per frame).
struct PointerEvent {
  float x = 0;        ///< column from the scene view's left edge [px]
  float y = 0;        ///< row from the top [px]
  bool held = false;  ///< the left button is down
};

/// A pointer pressed at (x0, y0) and dragged to (x1, y1) at most a pixel per frame, held there
/// for ten more frames [px of the scene's view].
std::vector<PointerEvent> dragPath(float x0, float y0, float x1, float y1);

/// What to show and how; the defaults open a window on the scene at rest.
struct ViewerOptions {
  std::string scene;  ///< built-in scene name or .json path
  /// Play the frames of this run's directory (DIR/run.pvd, as `fibremss run --out DIR` wrote
  /// them) instead of stepping `scene` ("": step `scene` live).
  std::string runDir;
  std::vector<std::string> overrides;  ///< key=value scene overrides, in order
  std::string screenshot;  ///< write this PNG after `steps` steps and return ("": interactive)
  int steps = 0;           ///< steps taken (frames advanced) before the first picture
  int width = 1280;        ///< window width [px]
  int height = 800;        ///< window height [px]
  std::string colourBy = "fibre_stretch";  ///< one of colourArrays()
  int muscleDebugFlags = 0;                ///< DebugDrawFlag bits drawn through the world's drawer
  bool bones = true;                       ///< draw the bone meshes
  float surfaceOpacity = 1;                ///< muscle surfaces' opacity (0 hides them)
  float azimuthDeg = 30;                   ///< camera angle about the up (y) axis [deg]
  float elevationDeg = 15;                 ///< camera angle above the horizontal plane [deg]
  float zoom = 1;                          ///< > 1 closer than the framed view
  bool hideUi = false;                     ///< no panel (H toggles it in the window)
  bool loop = false;                       ///< sweep the motion back and forth past its last pose
  /// Start playing; with a screenshot (a run's frames only) the picture shows where it stopped.
  bool play = false;
  ToolMode tool = ToolMode::Camera;  ///< what the pointer does at the start
  /// Pointer events played one per window frame from the first instead of the mouse (each
  /// waits for the step it asks for); with a screenshot, the picture follows the last.
  std::vector<PointerEvent> pointer;
};

/// What a viewer session ended with, to check a screenshot against.
struct ViewerResult {
  Camera camera;      ///< the camera of the last picture
  int width = 0;      ///< its size [px]
  int height = 0;     ///< [px]
  int viewX = 0;      ///< the scene is drawn right of this column (left of it: the panel) [px]
  int viewWidth = 0;  ///< in this many columns, the full height [px]
  int steps = 0;      ///< steps taken (live) or the frame shown, from 0 (a run's frames)
  int counter = 0;    ///< the frame (a run's) or pose the panel's text named, from 0
  int slider = 0;     ///< the panel's slider: that frame (a run's) or the next pose, from 0
  int step = -1;      ///< the step the panel's text named (-1: a run's frame not in its summary)
  size_t stepSamples = 0;   ///< steps in the panel's step-time graph
  float panelOverflow = 0;  ///< how far the panel's widest line ran past its edge [px] (0: fits)
  float toolForce = 0;      ///< |force| on the probe (or the grab's pull) the panel showed [N]
  size_t cutSprings = 0;    ///< springs the blade had cut in the muscles, as the panel showed
  float colourLow = 0;      ///< the value the colour bar's first colour stood for (its unit)
  float colourHigh = 0;     ///< the value its last colour stood for (its unit)
};

/// Opens the window and runs until it is closed (or, with a screenshot path, until the PNG is
/// written). Throws InputError for a bad scene, std::runtime_error when no window can be
/// opened or the PNG not written.
ViewerResult runViewer(const ViewerOptions& options);

/// Sets what `sceneOrRun` opens in `options`: a run's directory with frames (DIR/run.pvd) is
/// played; one without (--frame-every 0) steps the scene it ran (DIR/scene.json) live; anything
/// else is a scene to step live. InputError for a directory with neither.
void chooseSource(const std::string& sceneOrRun, ViewerOptions& options);

/// The arrays muscles can be coloured by (a scene stepped live has fibre_stretch, displacement
/// and muscle_id; a run's frames all of them).
const std::vector<std::string>& colourArrays();

/// What `array`'s values measure, written beside the colour bar: a ratio's definition, or for a
/// distance (displacement, penetration) `lengthUnit`, the scene's unit; empty for muscle_id.
std::string unitOf(const std::string& array, const std::string& lengthUnit);

}  // namespace fibremss::viewer
