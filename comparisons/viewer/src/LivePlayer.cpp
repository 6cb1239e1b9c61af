#include "LivePlayer.h"

namespace fibremss::viewer {

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

void LivePlayer::setPlaying(bool playing) {
  {
    std::lock_guard lock(mutex_);
    playing_ = playing;
  }
  wake_.notify_one();
}

bool LivePlayer::playing() const {
  std::lock_guard lock(mutex_);
  return playing_;
}

void LivePlayer::requestSteps(int steps) {
  {
    std::lock_guard lock(mutex_);
    stepsRequested_ += steps;
  }
  wake_.notify_one();
}

void LivePlayer::requestReset() {
  {
    std::lock_guard lock(mutex_);
    reset_ = true;
    stepsRequested_ = 0;
  }
  wake_.notify_one();
}

void LivePlayer::requestPose(int pose) {
  {
    std::lock_guard lock(mutex_);
    pose_ = pose;
  }
  wake_.notify_one();
}

void LivePlayer::setLoop(bool loop) {
  {
    std::lock_guard lock(mutex_);
    loop_ = loop;
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

bool LivePlayer::fetch(Snapshot& into) {
  std::lock_guard lock(mutex_);
  if (snapshot_.version <= into.version) return false;
  into = snapshot_;
  return true;
}

void LivePlayer::waitForSteps(int steps) {
  std::unique_lock lock(mutex_);
  published_.wait(lock, [&] { return snapshot_.steps >= steps; });
}

bool LivePlayer::hasWork() const {
  return quit_ || playing_ || stepsRequested_ > 0 || reset_ || pose_ >= 0 || redraw_;
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
    lock.unlock();  // the step runs while the window draws and takes requests
    if (reset) scene_->reset();
    if (pose >= 0) scene_->setPose(pose);
    if (step) scene_->step();
    publish(debug);
    lock.lock();
  }
}

void LivePlayer::publish(const DebugRequest& debug) {
  drawer_.clear();
  drawer_.setDebugMode(debug.bulletMode);
  scene_->world().setDebugDrawer(&drawer_);
  scene_->world().setMuscleDebugFlags(debug.muscleFlags);
  scene_->world().debugDrawWorld();
  Snapshot next;
  next.frame = scene_->frame();
  next.debug = drawer_.geometry();
  next.stats = scene_->lastStep();
  next.steps = scene_->steps();
  next.shownPose = scene_->shownPose();
  next.nextPose = scene_->pose();
  {
    std::lock_guard lock(mutex_);
    next.version = snapshot_.version + 1;
    snapshot_ = std::move(next);
  }
  published_.notify_all();
}

}  // namespace fibremss::viewer
