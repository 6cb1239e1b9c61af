#pragma once
// Steps a LiveScene on a worker thread so that the window stays responsive (camera, panel)
// while a step takes longer than a frame. The window sends requests (play, step, reset, pose,
// what to debug-draw); after every step or redraw the worker publishes a Snapshot, which the
// window fetches when it is newer than the one it shows.
#include <condition_variable>
#include <memory>
#include <mutex>
#include <thread>

#include "DebugDrawer.h"
#include "LiveScene.h"

namespace fibremss::viewer {

/// What the window shows of the live scene at one moment.
struct Snapshot {
  ViewFrame frame;      ///< surfaces and bones
  DebugGeometry debug;  ///< what the world's debugDrawWorld drew
  StepStats stats;      ///< the last step's statistics and timings
  int steps = 0;        ///< steps taken
  int shownPose = 0;    ///< the pose of the last step
  int nextPose = 0;     ///< the pose the next step moves the bones to
  long version = -1;    ///< increases with every publication
};

/// What the worker draws through the world's btIDebugDraw.
struct DebugRequest {
  int muscleFlags = 0;  ///< DebugDrawFlag bits (MuscleWorld::setMuscleDebugFlags)
  int bulletMode = 0;   ///< btIDebugDraw::DebugDrawModes bits for Bullet's own drawing
  bool operator==(const DebugRequest&) const = default;
};

class LivePlayer {
 public:
  /// Takes the scene and starts the worker, which publishes the scene at rest.
  explicit LivePlayer(std::unique_ptr<LiveScene> scene, const DebugRequest& debug);
  /// Stops the worker after its current step.
  ~LivePlayer();
  LivePlayer(const LivePlayer&) = delete;
  LivePlayer& operator=(const LivePlayer&) = delete;

  const LoadedScene& scene() const { return scene_->scene(); }  ///< never changes

  void setPlaying(bool playing);  ///< step continuously (or stop after the current step)
  bool playing() const;
  void requestSteps(int steps);              ///< this many more steps
  void requestReset();                       ///< back to the start (LiveScene::reset)
  void requestPose(int pose);                ///< the next step's pose (LiveScene::setPose)
  void setLoop(bool loop);                   ///< LiveScene::loop
  void setDebug(const DebugRequest& debug);  ///< redraws when it changes

  /// Copies the newest snapshot into `into` when it is newer; returns whether it was.
  bool fetch(Snapshot& into);
  /// Waits until at least `steps` steps are done and published.
  void waitForSteps(int steps);

 private:
  void work();
  bool hasWork() const;  ///< under mutex_
  void publish(const DebugRequest& debug);

  std::unique_ptr<LiveScene> scene_;
  DebugDrawer drawer_;  ///< the world's drawer; the worker's only
  mutable std::mutex mutex_;
  std::condition_variable wake_;       ///< the worker: a request came
  std::condition_variable published_;  ///< waitForSteps: a snapshot was published
  // Requests, under mutex_.
  bool quit_ = false;
  bool playing_ = false;
  int stepsRequested_ = 0;
  bool reset_ = false;
  int pose_ = -1;  ///< requested pose (-1: none)
  bool loop_ = false;
  bool redraw_ = true;
  DebugRequest debug_;
  Snapshot snapshot_;   ///< the newest publication, under mutex_
  std::thread worker_;  ///< last: starts when everything above is ready
};

}  // namespace fibremss::viewer
