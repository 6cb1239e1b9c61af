#include "fibremss/viewer/Viewer.h"

#include <GLFW/glfw3.h>
#include <imgui.h>
#include <imgui_impl_glfw.h>
#include <imgui_impl_opengl2.h>
#include <imgui_internal.h>
#include <imgui_stdlib.h>
#include <stb_image_write.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "Colours.h"
#include "DebugDrawer.h"
#include "FramePlayer.h"
#include "LivePlayer.h"
#include "Panel.h"
#include "Renderer.h"
#include "Source.h"
#include "fibremss/Error.h"
#include "fibremss/Messages.h"
#include "fibremss/Output.h"

namespace fibremss::viewer {
namespace {

std::string glfwMessage;  ///< GLFW's last error, for the exception when no window opens

/// GLFW, a window with an OpenGL 2.1 context, and Dear ImGui on it; torn down
/// in reverse.
class Window {
 public:
  Window(int width, int height, bool visible, const std::string& title) {
    glfwSetErrorCallback([](int, const char* message) { glfwMessage = message; });
    if (!glfwInit())
      throw std::runtime_error("cannot open a window (" + glfwMessage +
                               "); without a display, run under `xvfb-run -a`");
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 2);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 1);
    glfwWindowHint(GLFW_VISIBLE, visible ? GLFW_TRUE : GLFW_FALSE);
    glfwWindowHint(GLFW_SAMPLES, 4);
    window_ = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
    if (!window_) {
      glfwTerminate();
      throw std::runtime_error("cannot open an OpenGL 2.1 window (" + glfwMessage + ")");
    }
    glfwMakeContextCurrent(window_);
    glfwSwapInterval(visible ? 1 : 0);
    ImGui::CreateContext();
    ImGui::GetIO().IniFilename = nullptr;  // no imgui.ini in the user's directory
    ImGui::StyleColorsDark();
    ImGui_ImplGlfw_InitForOpenGL(window_, true);
    ImGui_ImplOpenGL2_Init();
  }
  ~Window() {
    ImGui_ImplOpenGL2_Shutdown();
    ImGui_ImplGlfw_Shutdown();
    ImGui::DestroyContext();
    glfwDestroyWindow(window_);
    glfwTerminate();
  }
  Window(const Window&) = delete;
  Window& operator=(const Window&) = delete;

  GLFWwindow* get() const { return window_; }

 private:
  GLFWwindow* window_ = nullptr;
};

/// The viewer's state between frames.
struct Session {
  ViewerOptions options;           ///< what the window opened with
  std::unique_ptr<Source> source;  ///< what it shows
  Camera camera;
  RenderSettings render;
  Renderer renderer;
  Snapshot shown;  ///< what the window shows
  bool showUi = true;
  bool autoRange = true;  ///< colour range from the current frame
  Range extremes;         ///< the coloured array's smallest and largest value now
  DebugRequest debug;     ///< what the world's btIDebugDraw draws
  std::string openPath;   ///< the picker's text: a scene name, a .json file or a run's directory
  bool openRequested = false;        ///< the picker asked to open openPath this frame
  std::string openError;             ///< why the last pick did not open ("" when it did)
  Playback playback;                 ///< what the panel's playback part showed last
  ToolMode tool = ToolMode::Camera;  ///< what the pointer's left button does
  float panelOverflow = 0;           ///< how far the panel's widest line ran past its edge [px]
  bool quit = false;
};

/// Every bone and muscle vertex of the frame where it is drawn [m].
std::vector<Vec3> sceneVertices(const ViewFrame& frame) {
  std::vector<Vec3> points;
  auto add = [&](const ViewMesh& mesh) {
    for (const btVector3& vertex : mesh.vertices) {
      const btVector3 p = mesh.transform * vertex;
      points.push_back({float(p.x()), float(p.y()), float(p.z())});
    }
  };
  for (const ViewMesh& mesh : frame.bones) add(mesh);
  for (const ViewMesh& mesh : frame.muscles) add(mesh);
  return points;
}

/// Frames what the window shows in a view of `aspect` (width / height).
void frameScene(Session& session, float aspect) {
  session.camera.frame(sceneVertices(session.shown.frame), aspect);
}

/// The panel's width beside the scene [px] (0 when hidden).
int panelWidth(const Session& session, int windowWidth) {
  return session.showUi ? std::min(400, windowWidth / 2) : 0;
}

/// The scene's part of a width × height window: width / height.
float viewAspect(const Session& session, int width, int height) {
  return float(width - panelWidth(session, width)) / float(std::max(height, 1));
}

/// Left drag orbits (unless a tool has the left button), right or middle drag (or shift + left)
/// pans, the wheel zooms.
void moveCamera(Camera& camera, int height, ToolMode tool) {
  const ImGuiIO& io = ImGui::GetIO();
  if (io.WantCaptureMouse) return;
  const bool pan = ImGui::IsMouseDragging(1) || ImGui::IsMouseDragging(2) ||
                   (ImGui::IsMouseDragging(0) && io.KeyShift);
  if (pan)
    camera.pan(-io.MouseDelta.x / float(height), io.MouseDelta.y / float(height));
  else if (ImGui::IsMouseDragging(0) && tool == ToolMode::Camera)
    camera.orbit(-0.3f * io.MouseDelta.x, 0.3f * io.MouseDelta.y);
  if (io.MouseWheel != 0) camera.zoom(std::pow(1.15f, io.MouseWheel));
}

/// The pointer at pixel (x, y) of the scene's view, its drag plane through the camera's target.
PointerRay pointerRay(const Camera& camera, float x, float y, const ViewerResult& size, bool held) {
  const Ray ray = camera.ray(x, y, size.viewWidth, std::max(size.height, 1));
  auto bullet = [](const Vec3& v) { return btVector3(v[0], v[1], v[2]); };
  return {bullet(ray.origin), bullet(ray.direction), bullet(camera.target()), held};
}

/// Hands the pointer to the source: the script's event for window frame `frame` (and waits for
/// the step it asks for), else the mouse in the scene's view unless the panel has it.
void drivePointer(Session& session, int frame, const ViewerResult& size) {
  const std::vector<PointerEvent>& script = session.options.pointer;
  if (!script.empty()) {
    // One more step after the last event: the picture shows the muscles where it left them.
    if (frame == int(script.size())) session.source->advance(1);
    if (frame >= int(script.size())) return;
    const PointerEvent& event = script[size_t(frame)];
    session.source->setPointer(session.tool,
                               pointerRay(session.camera, event.x, event.y, size, event.held));
    session.source->advance(0);
    return;
  }
  const ImGuiIO& io = ImGui::GetIO();
  const bool held = !io.WantCaptureMouse && !io.KeyShift && ImGui::IsMouseDown(0);
  session.source->setPointer(
      session.tool,
      pointerRay(session.camera, io.MousePos.x - float(size.viewX), io.MousePos.y, size, held));
}

/// Space plays or pauses, S or → steps, R resets, F frames the scene, T switches the pointer's
/// tool, H hides the panel, Q quits.
void handleKeys(Session& session, float aspect) {
  if (ImGui::GetIO().WantCaptureKeyboard) return;
  Source& source = *session.source;
  if (ImGui::IsKeyPressed(GLFW_KEY_SPACE, false)) source.togglePlaying();
  if (ImGui::IsKeyPressed(GLFW_KEY_S) || ImGui::IsKeyPressed(GLFW_KEY_RIGHT)) source.step();
  if (ImGui::IsKeyPressed(GLFW_KEY_R, false)) source.reset();
  if (ImGui::IsKeyPressed(GLFW_KEY_F, false)) frameScene(session, aspect);
  if (ImGui::IsKeyPressed(GLFW_KEY_T, false)) session.tool = nextTool(session.tool);
  if (ImGui::IsKeyPressed(GLFW_KEY_H, false)) session.showUi = !session.showUi;
  if (ImGui::IsKeyPressed(GLFW_KEY_Q, false) || ImGui::IsKeyPressed(GLFW_KEY_ESCAPE, false))
    session.quit = true;
}

/// A horizontal colour bar from range.low to range.high, under what the values measure.
void drawLegend(const std::string& array, const Range& range, const std::string& lengthUnit) {
  if (array == "muscle_id") return;
  ImGui::TextWrapped("%s [%s]", array.c_str(), unitOf(array, lengthUnit).c_str());
  ImDrawList* list = ImGui::GetWindowDrawList();
  const ImVec2 origin = ImGui::GetCursorScreenPos();
  const float width = ImGui::GetContentRegionAvail().x, height = 14;
  constexpr int kSegments = 32;
  for (int i = 0; i < kSegments; ++i) {
    const float t0 = float(i) / kSegments, t1 = float(i + 1) / kSegments;
    auto colour = [&](float t) {
      const Rgb c = colourOf(array, range.low + t * (range.high - range.low), range);
      return ImGui::ColorConvertFloat4ToU32(ImVec4(c[0], c[1], c[2], 1));
    };
    list->AddRectFilledMultiColor(ImVec2(origin.x + t0 * width, origin.y),
                                  ImVec2(origin.x + t1 * width, origin.y + height), colour(t0),
                                  colour(t1), colour(t1), colour(t0));
  }
  ImGui::Dummy(ImVec2(width, height));
  char high[32];
  std::snprintf(high, sizeof high, "%.4g", range.high);
  ImGui::Text("%.4g", range.low);
  ImGui::SameLine(std::max(0.0f, width - ImGui::CalcTextSize(high).x));  // right-aligned
  ImGui::TextUnformatted(high);
}

void appearanceControls(Session& session) {
  RenderSettings& render = session.render;
  if (ImGui::BeginCombo("colour by", render.colourBy.c_str())) {
    for (const std::string& array : colourArrays()) {
      const auto& muscles = session.shown.frame.muscles;
      if (!muscles.empty() && !muscles.front().array(array)) continue;  // not in this source
      if (ImGui::Selectable(array.c_str(), array == render.colourBy)) render.colourBy = array;
    }
    ImGui::EndCombo();
  }
  ImGui::Checkbox("auto range (98 %)", &session.autoRange);
  if (!session.autoRange) ImGui::DragFloat2("range", &render.range.low, 0.01f);
  drawLegend(render.colourBy, render.range, session.shown.frame.lengthUnit);
  if (render.colourBy != "muscle_id")
    ImGui::Text("%s now: min %.4g, max %.4g", render.colourBy.c_str(), session.extremes.low,
                session.extremes.high);
  ImGui::SliderFloat("surface opacity", &render.surfaceOpacity, 0, 1);
  ImGui::Checkbox("bones", &render.bones);
  struct Flag {
    const char* label;
    int bit;
  };
  constexpr Flag kFlags[] = {{"particles", kDrawParticles},
                             {"fibres", kDrawFibres},
                             {"springs", kDrawSprings},
                             {"bone spheres", kDrawBoneSpheres},
                             {"contacts", kDrawContacts}};
  for (const Flag& flag : kFlags) {
    sameLineIfFits(checkboxWidth(flag.label));
    ImGui::CheckboxFlags(flag.label, &session.debug.muscleFlags, flag.bit);
  }
  sameLineIfFits(checkboxWidth("Bullet wireframe"));
  ImGui::CheckboxFlags("Bullet wireframe", &session.debug.bulletMode,
                       btIDebugDraw::DBG_DrawWireframe);
}

/// A text field and an Open button: a built-in scene, a scene .json file or a run's directory.
void drawPicker(Session& session) {
  const ImGuiStyle& style = ImGui::GetStyle();
  ImGui::PushItemWidth(
      -(ImGui::CalcTextSize("Open").x + 2 * style.FramePadding.x + style.ItemSpacing.x));
  const bool enter = ImGui::InputTextWithHint(
      "##open", "scene name, .json file or run directory", &session.openPath,
      ImGuiInputTextFlags_EnterReturnsTrue | ImGuiInputTextFlags_AutoSelectAll);
  ImGui::PopItemWidth();
  ImGui::SameLine();
  session.openRequested = (ImGui::Button("Open") || enter) && !session.openPath.empty();
  if (!session.openError.empty())
    ImGui::TextColored(ImVec4(1, 0.4f, 0.3f, 1), "%s", session.openError.c_str());
}

void drawPanel(Session& session, int width, int height) {
  ImGui::SetNextWindowPos(ImVec2(0, 0));
  ImGui::SetNextWindowSize(ImVec2(float(width), float(height)));
  ImGui::Begin("FibreMSS", nullptr,
               ImGuiWindowFlags_NoMove | ImGuiWindowFlags_NoResize | ImGuiWindowFlags_NoCollapse);
  ImGui::PushTextWrapPos(0);  // every line wraps at the panel's edge
  ImGui::PushItemWidth(-ImGui::CalcTextSize("surface opacity ").x);  // the longest label fits
  drawPicker(session);
  ImGui::Separator();
  session.playback = session.source->controls(session.shown);
  ImGui::Separator();
  appearanceControls(session);
  ImGui::Separator();
  session.source->timings(session.shown);
  ImGui::Separator();
  ImGui::TextDisabled(
      "space: play/pause | S: step | R: reset | F: frame the scene | T: pointer tool "
      "(camera, grab, probe) | H: hide this panel | Q: quit | drag: orbit or the tool | "
      "right/middle drag: pan | wheel: zoom");
  ImGui::PopItemWidth();
  ImGui::PopTextWrapPos();
  const ImGuiWindow* panel = ImGui::GetCurrentWindow();
  session.panelOverflow = std::max(0.0f, panel->DC.CursorMaxPos.x - panel->WorkRect.Max.x);
  ImGui::End();
}

/// Reads the back buffer (width × height) and writes it as a PNG, whole or not
/// at all.
void writeScreenshot(const std::string& path, int width, int height) {
  std::vector<unsigned char> pixels(size_t(3) * width * height);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadBuffer(GL_BACK);
  glReadPixels(0, 0, width, height, GL_RGB, GL_UNSIGNED_BYTE, pixels.data());
  stbi_flip_vertically_on_write(1);  // OpenGL's rows start at the bottom
  std::string png;
  auto append = [](void* to, void* data, int size) {
    static_cast<std::string*>(to)->append(static_cast<const char*>(data), size_t(size));
  };
  if (!stbi_write_png_to_func(append, &png, width, height, 3, pixels.data(), 3 * width))
    throw std::runtime_error("cannot encode the screenshot as PNG");
  writeFileAtomically(path, png);
}

/// One frame (the window's `frame`th): input, steps, panel, drawing; returns the window's and
/// the scene's size.
void renderFrame(Window& window, Session& session, int frame, ViewerResult& size) {
  ImGui_ImplOpenGL2_NewFrame();
  ImGui_ImplGlfw_NewFrame();
  ImGui::NewFrame();
  glfwGetFramebufferSize(window.get(), &size.width, &size.height);
  size.viewX = panelWidth(session, size.width);
  size.viewWidth = size.width - size.viewX;
  moveCamera(session.camera, std::max(size.height, 1), session.tool);
  handleKeys(session, viewAspect(session, size.width, size.height));
  drivePointer(session, frame, size);
  session.source->fetch(session.shown);
  const Range range = arrayRange(session.shown.frame, session.render.colourBy, session.extremes);
  if (session.autoRange) session.render.range = range;
  if (session.showUi) drawPanel(session, size.viewX, size.height);
  session.source->setDebug(session.debug);
  ImGui::Render();
  session.renderer.draw(session.shown.frame, session.shown.debug, session.camera,
                        {size.viewX, 0, size.viewWidth, size.height}, session.render);
  ImGui_ImplOpenGL2_RenderDrawData(ImGui::GetDrawData());
}

/// Whether a scene stepped live has `array` (the first three of colourArrays()).
bool liveArray(const std::string& array) {
  const auto end = colourArrays().begin() + 3;
  return std::find(colourArrays().begin(), end, array) != end;
}

/// Throws InputError when `options` ask for an array their source lacks, or for a screenshot
/// after playing without end.
void checkOptions(const ViewerOptions& options) {
  const auto& arrays = colourArrays();
  if (options.runDir.empty()
          ? !liveArray(options.colourBy)
          : std::find(arrays.begin(), arrays.end(), options.colourBy) == arrays.end())
    throw InputError("--colour-by", "",
                     options.runDir.empty()
                         ? "expected fibre_stretch, displacement or muscle_id for a scene stepped "
                           "live (spring_strain, penetration and fixed: a run's frames), got '" +
                               options.colourBy + "'"
                         : "expected fibre_stretch, displacement, muscle_id, spring_strain, "
                           "penetration or fixed, got '" +
                               options.colourBy + "'");
  if (options.play && !options.screenshot.empty() && (options.runDir.empty() || options.loop))
    throw InputError("--play", "",
                     "with --screenshot only for a run's frames without --loop (the picture shows "
                     "the last frame; a scene stepped live or a loop plays without end)");
}

/// The source `options` name (a run's frames or a scene stepped live) and the window's title.
std::unique_ptr<Source> makeSource(const ViewerOptions& options, const DebugRequest& debug,
                                   std::string& title) {
  if (!options.runDir.empty()) {
    auto frames = std::make_unique<FramePlayer>(options.runDir, debug);
    frames->loop = options.loop;
    title = "FibreMSS - " + options.runDir;
    return frames;
  }
  auto scene = std::make_unique<LiveScene>(options.scene, options.overrides);
  scene->loop = options.loop;
  title = "FibreMSS - " + scene->scene().name;
  return std::make_unique<LivePlayer>(std::move(scene), debug);
}

/// Replaces the source by what the picker names, framed in a view of `aspect`; on bad input
/// keeps the current one and says why in the panel.
void openPicked(Session& session, GLFWwindow* window, float aspect) {
  ViewerOptions options = session.options;
  options.runDir.clear();
  options.overrides.clear();  // the command line's overrides were for its scene
  std::string title;
  try {
    chooseSource(session.openPath, options);
    // An array only a run's frames have falls back to fibre stretch for a scene stepped live.
    options.colourBy = options.runDir.empty() && !liveArray(session.render.colourBy)
                           ? colourArrays().front()
                           : session.render.colourBy;
    session.source = makeSource(options, session.debug, title);
    session.render.colourBy = options.colourBy;
  } catch (const std::exception& error) {
    session.openError = error.what();
    return;
  }
  session.openError.clear();
  session.shown = Snapshot();
  session.source->fetch(session.shown);
  frameScene(session, aspect);
  glfwSetWindowTitle(window, title.c_str());
}

/// Draws frames until the window closes (or, with a screenshot path, until the PNG is written).
ViewerResult runWindow(Window& window, Session& session) {
  const ViewerOptions& options = session.options;
  ViewerResult result;
  // A screenshot takes a few frames (Dear ImGui sizes its windows in the first ones), more while
  // a run's frames play to the last.
  for (int frame = 0; !glfwWindowShouldClose(window.get()) && !session.quit; ++frame) {
    glfwPollEvents();
    renderFrame(window, session, frame, result);
    const int lastEvent = int(options.pointer.size()) - 1;
    if (!options.screenshot.empty() && frame >= std::max(2, lastEvent + 2) &&
        !session.source->playing()) {
      writeScreenshot(options.screenshot, result.width, result.height);
      break;
    }
    glfwSwapBuffers(window.get());
    if (session.openRequested)
      openPicked(session, window.get(), viewAspect(session, result.width, result.height));
  }
  result.camera = session.camera;
  result.steps = session.shown.steps;
  result.counter = session.playback.counter;
  result.slider = session.playback.slider;
  result.step = session.playback.step;
  result.stepSamples = session.shown.stepMs.size();
  result.panelOverflow = session.panelOverflow;
  result.toolForce = session.playback.toolForce;
  result.cutSprings = session.playback.cutSprings;
  result.colourLow = session.render.range.low;
  result.colourHigh = session.render.range.high;
  return result;
}

}  // namespace

const std::vector<std::string>& colourArrays() {
  // Those a scene stepped live has first.
  static const std::vector<std::string> arrays{"fibre_stretch", "displacement", "muscle_id",
                                               "spring_strain", "penetration",  "fixed"};
  return arrays;
}

std::string unitOf(const std::string& array, const std::string& lengthUnit) {
  if (array == "fibre_stretch") return "current / rest length along the fibres";
  if (array == "spring_strain") return "(l - L0) / L0 of the springs";
  if (array == "fixed") return "1 fixed, 0 free";
  if (array == "muscle_id") return "";
  return lengthUnit;  // displacement, penetration
}

std::vector<PointerEvent> dragPath(float x0, float y0, float x1, float y1) {
  constexpr int kHold = 10;  // frames held at the end
  const int moves = int(std::ceil(std::max(std::abs(x1 - x0), std::abs(y1 - y0))));
  std::vector<PointerEvent> path;
  for (int k = 0; k <= moves + kHold; ++k) {
    const float t = moves > 0 ? float(std::min(k, moves)) / float(moves) : 1;
    path.push_back({x0 + t * (x1 - x0), y0 + t * (y1 - y0), true});
  }
  return path;
}

void chooseSource(const std::string& sceneOrRun, ViewerOptions& options) {
  options.scene = sceneOrRun;
  if (!std::filesystem::is_directory(sceneOrRun)) return;
  const std::filesystem::path dir(sceneOrRun);
  if (std::filesystem::is_regular_file(dir / "run.pvd")) {
    options.runDir = sceneOrRun;
    return;
  }
  if (!std::filesystem::is_regular_file(dir / "scene.json"))
    throw InputError(sceneOrRun, "",
                     "expected a built-in scene, a scene file or a run's directory (fibremss run "
                     "--out DIR) with run.pvd or scene.json");
  printNote("no frames in " + sceneOrRun + " (run.pvd); stepping its scene (" +
            (dir / "scene.json").string() + ") live instead");
  options.scene = (dir / "scene.json").string();
}

ViewerResult runViewer(const ViewerOptions& options) {
  checkOptions(options);
  Session session;
  session.options = options;
  session.debug.muscleFlags = options.muscleDebugFlags;
  std::string title;
  session.source = makeSource(options, session.debug, title);
  const bool screenshot = !options.screenshot.empty();
  session.source->advance(screenshot ? options.steps : 0);  // a screenshot shows them taken
  session.source->fetch(session.shown);
  for (int s = 0; !screenshot && s < options.steps; ++s) session.source->step();
  if (options.play) session.source->togglePlaying();

  session.render.colourBy = options.colourBy;
  session.render.bones = options.bones;
  session.render.surfaceOpacity = options.surfaceOpacity;
  session.showUi = !options.hideUi;
  session.tool = options.tool;
  session.openPath = options.runDir.empty() ? options.scene : options.runDir;
  session.camera.setAngles(options.azimuthDeg, options.elevationDeg);
  frameScene(session, viewAspect(session, options.width, options.height));
  session.camera.zoom(options.zoom);
  Window window(options.width, options.height, !screenshot, title);
  return runWindow(window, session);
}

}  // namespace fibremss::viewer
