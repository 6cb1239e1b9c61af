#include "LivePlayer.h"

#include <imgui.h>

#include <algorithm>
#include <cfloat>
#include <cstdio>
#include <string>
#include <utility>

#include "Panel.h"

namespace fibremss::viewer {
namespace {

/// The pose's label (e.g. the joint angle) as text.
std::string poseLabel(const LoadedScene& scene, int pose) {
  char text[32];
  std::snprintf(text, sizeof text, "%.4g",
                pose < int(scene.poseLabels.size()) ? scene.poseLabels[pose] : double(pose));
  return text;
}

}  // namespace

LivePlayer::LivePlayer(std::unique_ptr<LiveScene> scene, const DebugRequest& debug)
    : scene_(std::move(scene)), loop_(scene_->loop), debug_(debug), worker_([this] { work(); }) {}

LivePlayer::~LivePlayer() {
  {
    std::lock_guard lock(mutex_);
    quit_ = true;
  }
  wake_.notify_one();
  worker_.join();
}

bool LivePlayer::fetch(Snapshot& into) {
  {
    std::lock_guard lock(mutex_);
    if (newest_.snapshot.version <= into.version) return false;
    shown_ = newest_;
  }
  into = shown_.snapshot;
  return true;
}

Playback LivePlayer::controls(const Snapshot& shown) {
  const LoadedScene& scene = scene_->scene();
  const int last = std::max(scene.poseCount, 1) - 1;
  ImGui::Text("%s: step %d, pose %d (0 to %d), label %s", scene.name.c_str(), shown.steps,
              shown_.shownPose, last, poseLabel(scene, shown_.shownPose).c_str());
  bool loop = false;
  {
    std::lock_guard lock(mutex_);
    loop = loop_;
  }
  if (playbackButtons(*this, loop)) {
    std::lock_guard lock(mutex_);
    loop_ = loop;
  }
  int pose = shown_.nextPose;
  const std::string format = "%d (" + poseLabel(scene, pose) + ")";
  if (ImGui::SliderInt("next pose", &pose, 0, last, format.c_str())) {
    {
      std::lock_guard lock(mutex_);
      pose_ = pose;
    }
    wake_.notify_one();
  }
  const ToolReading& tool = shown_.tool;
  const btVector3& f = tool.force;
  ImGui::Text("pointer (T): %s", toolName(tool.mode));
  if (tool.engaged && tool.mode == ToolMode::Probe)
    ImGui::Text("  force on the probe %.4g N (%.3g, %.3g, %.3g), %zu contacts", f.length(), f.x(),
                f.y(), f.z(), tool.contacts);
  else if (tool.mode == ToolMode::Blade)
    ImGui::Text("  springs cut %zu", tool.cutSprings);
  else if (tool.engaged)
    ImGui::Text("  pull on the particle %.4g N (%.3g, %.3g, %.3g)", f.length(), f.x(), f.y(),
                f.z());
  return {shown_.shownPose, pose, shown.steps, float(f.length()), tool.cutSprings};
}

void LivePlayer::timings(const Snapshot& shown) {
  const StepStats& stats = shown_.stats;
  ImGui::Text("last step: %d iterations, %zu contacts, %zu candidates", stats.iterations,
              stats.contacts, stats.candidates);
  const StepTiming& t = stats.timing;
  partTimes("last step, ms:", {t.mss, t.muscleCd, t.boneCd, t.response, t.output});
  ImGui::Text("  total %.3g (%.3g per iteration)", t.total,
              t.total / std::max(stats.iterations, 1));
  if (!shown.stepMs.empty()) {
    char overlay[48];
    std::snprintf(overlay, sizeof overlay, "step ms, %zu steps", shown.stepMs.size());
    ImGui::PlotHistogram(
        "##step ms", shown.stepMs.data(), int(shown.stepMs.size()), 0, overlay, 0, FLT_MAX,
        ImVec2(ImGui::GetContentRegionAvail().x, 40));  // a negative width hides it
  }
  if (stats.failed || stats.frozenMuscles > 0)
    ImGui::TextColored(ImVec4(1, 0.4f, 0.3f, 1), "numerical guard: %zu muscle(s) frozen%s",
                       stats.frozenMuscles, stats.failed ? ", step failed" : "");
}

bool LivePlayer::playing() const {
  std::lock_guard lock(mutex_);
  return playing_;
}

void LivePlayer::togglePlaying() {
  {
    std::lock_guard lock(mutex_);
    playing_ = !playing_;
  }
  wake_.notify_one();
}

void LivePlayer::requestSteps(int steps) {
  {
    std::lock_guard lock(mutex_);
    stepsRequested_ += steps;
  }
  wake_.notify_one();
}

void LivePlayer::reset() {
  {
    std::lock_guard lock(mutex_);
    reset_ = true;
    stepsRequested_ = 0;
  }
  wake_.notify_one();
}

void LivePlayer::setDebug(const DebugRequest& debug) {
  {
    std::lock_guard lock(mutex_);
    if (debug == debug_) return;
    debug_ = debug;
    redraw_ = true;
  }
  wake_.notify_one();
}

void LivePlayer::advance(int steps) {
  int target = 0;
  {
    std::lock_guard lock(mutex_);
    target = newest_.snapshot.steps + stepsRequested_ + steps;
  }
  requestSteps(steps);
  std::unique_lock lock(mutex_);
  published_.wait(
      lock, [&] { return newest_.snapshot.version >= 0 && newest_.snapshot.steps >= target; });
}

void LivePlayer::setPointer(ToolMode mode, const PointerRay& ray) {
  {
    std::lock_guard lock(mutex_);
    // A pointer that moves without the button changes nothing in the scene.
    const bool wasHeld = pointer_.held;
    pointer_ = ray;
    if (mode == toolMode_ && !ray.held && !wasHeld) return;
    // A tool held (or let go of) moves the muscles: a step shows it.
    if (mode != ToolMode::Camera && mode == toolMode_)
      stepsRequested_ = std::max(stepsRequested_, 1);
    toolMode_ = mode;
    pointerChanged_ = true;
  }
  wake_.notify_one();
}

bool LivePlayer::hasWork() const {
  return quit_ || playing_ || stepsRequested_ > 0 || reset_ || pose_ >= 0 || redraw_ ||
         pointerChanged_;
}

void LivePlayer::work() {
  std::unique_lock lock(mutex_);
  while (true) {
    wake_.wait(lock, [this] { return hasWork(); });
    if (quit_) return;
    const bool reset = std::exchange(reset_, false);
    const int pose = std::exchange(pose_, -1);
    const bool step = playing_ || stepsRequested_ > 0;
    if (!playing_ && stepsRequested_ > 0) --stepsRequested_;
    redraw_ = false;
    scene_->loop = loop_;
    const DebugRequest debug = debug_;
    const bool pointer = std::exchange(pointerChanged_, false);
    const ToolMode mode = toolMode_;
    const PointerRay ray = pointer_;
    lock.unlock();  // the step runs while the window draws and takes requests
    if (reset) {
      scene_->reset();
      stepMs_.clear();
    }
    if (pose >= 0) scene_->setPose(pose);
    if (pointer) scene_->applyPointer(mode, ray);
    if (step) stepScene();
    publish(debug);
    lock.lock();
  }
}

void LivePlayer::stepScene() {
  scene_->step();
  stepMs_.push_back(float(scene_->lastStep().timing.total));
  constexpr size_t kGraphSteps = 200;  // the steps the graph shows
  if (stepMs_.size() > kGraphSteps) stepMs_.erase(stepMs_.begin());
}

void LivePlayer::publish(const DebugRequest& debug) {
  drawer_.clear();
  // MuscleWorld draws the muscles when the mode asks for wireframes, AABBs or normals; normals
  // alone make Bullet draw nothing of its own (no soft bodies here).
  drawer_.setDebugMode(debug.bulletMode |
                       (debug.muscleFlags != 0 ? btIDebugDraw::DBG_DrawNormals : 0));
  scene_->world().setDebugDrawer(&drawer_);
  scene_->world().setMuscleDebugFlags(debug.muscleFlags);
  scene_->world().debugDrawWorld();
  Published next;
  next.snapshot.frame = scene_->frame();
  next.snapshot.debug = drawer_.geometry();
  next.snapshot.steps = scene_->steps();
  next.snapshot.stepMs = stepMs_;
  next.stats = scene_->lastStep();
  next.shownPose = scene_->shownPose();
  next.nextPose = scene_->pose();
  next.tool = scene_->toolReading();
  {
    std::lock_guard lock(mutex_);
    next.snapshot.version = newest_.snapshot.version + 1;
    newest_ = std::move(next);
  }
  published_.notify_all();
}

}  // namespace fibremss::viewer
