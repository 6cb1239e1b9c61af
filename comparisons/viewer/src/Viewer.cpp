#include "fibremss/viewer/Viewer.h"

#include <GLFW/glfw3.h>
#include <imgui.h>
#include <imgui_impl_glfw.h>
#include <imgui_impl_opengl2.h>
#include <stb_image_write.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>

#include "Colours.h"
#include "DebugDrawer.h"
#include "FramePlayer.h"
#include "LivePlayer.h"
#include "Renderer.h"
#include "Source.h"
#include "fibremss/Error.h"
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
  Camera camera;
  RenderSettings render;
  Renderer renderer;
  Snapshot shown;         ///< what the window shows
  Vec3 lower{}, upper{};  ///< the scene's bounds in its first snapshot
  bool showUi = true;
  bool autoRange = true;  ///< colour range from the current frame
  Range extremes;         ///< the coloured array's smallest and largest value now
  DebugRequest debug;     ///< what the world's btIDebugDraw draws
  bool quit = false;
};

/// The box around every bone and muscle vertex of the frame [m].
void frameBounds(const ViewFrame& frame, Vec3& lower, Vec3& upper) {
  lower.fill(std::numeric_limits<float>::max());
  upper.fill(std::numeric_limits<float>::lowest());
  auto grow = [&](const ViewMesh& mesh) {
    for (const btVector3& vertex : mesh.vertices) {
      const btVector3 p = mesh.transform * vertex;
      for (int k = 0; k < 3; ++k) {
        lower[k] = std::min(lower[k], float(p[k]));
        upper[k] = std::max(upper[k], float(p[k]));
      }
    }
  };
  for (const ViewMesh& mesh : frame.bones) grow(mesh);
  for (const ViewMesh& mesh : frame.muscles) grow(mesh);
  if (lower[0] > upper[0]) lower = upper = Vec3{0, 0, 0};
}

/// Left drag orbits, right or middle drag (or shift + left) pans, the wheel
/// zooms.
void moveCamera(Camera& camera, int height) {
  const ImGuiIO& io = ImGui::GetIO();
  if (io.WantCaptureMouse) return;
  const bool pan = ImGui::IsMouseDragging(1) || ImGui::IsMouseDragging(2) ||
                   (ImGui::IsMouseDragging(0) && io.KeyShift);
  if (pan)
    camera.pan(-io.MouseDelta.x / float(height), io.MouseDelta.y / float(height));
  else if (ImGui::IsMouseDragging(0))
    camera.orbit(-0.3f * io.MouseDelta.x, 0.3f * io.MouseDelta.y);
  if (io.MouseWheel != 0) camera.zoom(std::pow(1.15f, io.MouseWheel));
}

/// Space plays or pauses, S or → steps, R resets, F frames the scene, H hides
/// the panel, Q quits.
void handleKeys(Session& session, Source& source) {
  if (ImGui::GetIO().WantCaptureKeyboard) return;
  if (ImGui::IsKeyPressed(GLFW_KEY_SPACE, false)) source.togglePlaying();
  if (ImGui::IsKeyPressed(GLFW_KEY_S) || ImGui::IsKeyPressed(GLFW_KEY_RIGHT)) source.step();
  if (ImGui::IsKeyPressed(GLFW_KEY_R, false)) source.reset();
  if (ImGui::IsKeyPressed(GLFW_KEY_F, false)) session.camera.frame(session.lower, session.upper);
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
  ImGui::Checkbox("auto range (98 % of the values)", &session.autoRange);
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
    if (flag.bit != kDrawSprings) ImGui::SameLine();  // two rows
    ImGui::CheckboxFlags(flag.label, &session.debug.muscleFlags, flag.bit);
  }
  ImGui::CheckboxFlags("Bullet wireframe", &session.debug.bulletMode,
                       btIDebugDraw::DBG_DrawWireframe);
}

/// The panel's width beside the scene [px] (0 when hidden).
int panelWidth(const Session& session, int windowWidth) {
  return session.showUi ? std::min(400, windowWidth / 2) : 0;
}

void drawPanel(Session& session, Source& source, int width, int height) {
  ImGui::SetNextWindowPos(ImVec2(0, 0));
  ImGui::SetNextWindowSize(ImVec2(float(width), float(height)));
  ImGui::Begin("FibreMSS", nullptr,
               ImGuiWindowFlags_NoMove | ImGuiWindowFlags_NoResize | ImGuiWindowFlags_NoCollapse);
  source.controls(session.shown);
  ImGui::Separator();
  appearanceControls(session);
  ImGui::Separator();
  source.timings(session.shown);
  ImGui::Separator();
  ImGui::TextDisabled("drag: orbit | right/middle drag: pan | wheel: zoom");
  ImGui::TextDisabled("F: frame the scene | H: hide this panel | Q: quit");
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

/// One frame: input, steps, panel, drawing; returns the window's and the
/// scene's size.
void renderFrame(Window& window, Session& session, Source& source, ViewerResult& size) {
  ImGui_ImplOpenGL2_NewFrame();
  ImGui_ImplGlfw_NewFrame();
  ImGui::NewFrame();
  glfwGetFramebufferSize(window.get(), &size.width, &size.height);
  size.viewX = panelWidth(session, size.width);
  size.viewWidth = size.width - size.viewX;
  moveCamera(session.camera, std::max(size.height, 1));
  handleKeys(session, source);
  source.fetch(session.shown);
  const Range range = arrayRange(session.shown.frame, session.render.colourBy, session.extremes);
  if (session.autoRange) session.render.range = range;
  if (session.showUi) drawPanel(session, source, size.viewX, size.height);
  source.setDebug(session.debug);
  ImGui::Render();
  session.renderer.draw(session.shown.frame, session.shown.debug, session.camera,
                        {size.viewX, 0, size.viewWidth, size.height}, session.render);
  ImGui_ImplOpenGL2_RenderDrawData(ImGui::GetDrawData());
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

ViewerResult runViewer(const ViewerOptions& options) {
  const auto& arrays = colourArrays();
  // A scene stepped live has the first three; a run's frames all of them.
  const auto end = options.runDir.empty() ? arrays.begin() + 3 : arrays.end();
  if (std::find(arrays.begin(), end, options.colourBy) == end)
    throw InputError("--colour-by", "",
                     options.runDir.empty()
                         ? "expected fibre_stretch, displacement or muscle_id for a scene stepped "
                           "live (spring_strain, penetration and fixed: a run's frames), got '" +
                               options.colourBy + "'"
                         : "expected fibre_stretch, displacement, muscle_id, spring_strain, "
                           "penetration or fixed, got '" +
                               options.colourBy + "'");
  Session session;
  session.debug.muscleFlags = options.muscleDebugFlags;
  std::string title;
  std::unique_ptr<Source> source;
  if (!options.runDir.empty()) {
    auto frames = std::make_unique<FramePlayer>(options.runDir, session.debug);
    frames->loop = options.loop;
    source = std::move(frames);
    title = "FibreMSS - " + options.runDir;
  } else {
    auto scene = std::make_unique<LiveScene>(options.scene, options.overrides);
    scene->loop = options.loop;
    title = "FibreMSS - " + scene->scene().name;
    source = std::make_unique<LivePlayer>(std::move(scene), session.debug);
  }
  const bool screenshot = !options.screenshot.empty();
  source->advance(screenshot ? options.steps : 0);  // a screenshot shows the scene after them
  source->fetch(session.shown);
  for (int s = 0; !screenshot && s < options.steps; ++s) source->step();

  frameBounds(session.shown.frame, session.lower, session.upper);
  session.camera.frame(session.lower, session.upper);
  session.camera.setView(options.azimuthDeg, options.elevationDeg, options.zoom);
  session.render.colourBy = options.colourBy;
  session.render.bones = options.bones;
  session.render.surfaceOpacity = options.surfaceOpacity;
  session.showUi = !options.hideUi;
  Window window(options.width, options.height, !screenshot, title);

  ViewerResult result;
  // A screenshot takes a few frames: Dear ImGui sizes its windows in the first
  // ones.
  for (int frame = 0; !glfwWindowShouldClose(window.get()) && !session.quit; ++frame) {
    glfwPollEvents();
    renderFrame(window, session, *source, result);
    if (screenshot && frame == 2) {
      writeScreenshot(options.screenshot, result.width, result.height);
      break;
    }
    glfwSwapBuffers(window.get());
  }
  result.camera = session.camera;
  result.steps = session.shown.steps;
  return result;
}

}  // namespace fibremss::viewer
