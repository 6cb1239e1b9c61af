#pragma once
// Steps a LiveScene on a worker thread so that the window stays responsive
// (camera, panel) while a step takes longer than a frame. The window sends
// requests (play, step, reset, pose, what to debug-draw); after every step or
// redraw the worker publishes a Snapshot, which the window fetches when it is
// newer than the one it shows.
#include <condition_variable>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "LiveScene.h"
#include "Source.h"

namespace fibremss::viewer {

class LivePlayer : public Source {
 public:
  /// Takes the scene and starts the worker, which publishes the scene at rest.
  LivePlayer(std::unique_ptr<LiveScene> scene, const DebugRequest& debug);
  /// Stops the worker after its current step.
  ~LivePlayer() override;
  LivePlayer(const LivePlayer&) = delete;
  LivePlayer& operator=(const LivePlayer&) = delete;

  bool fetch(Snapshot& into) override;
  Playback controls(const Snapshot& shown) override;
  void timings(const Snapshot& shown) override;
  void togglePlaying() override;
  bool playing() const override;
  void step() override { requestSteps(1); }
  void reset() override;
  void setDebug(const DebugRequest& debug) override;
  void advance(int steps) override;
  void setPointer(ToolMode mode, const PointerRay& ray) override;

 private:
  /// What the worker publishes beyond the Snapshot.
  struct Published {
    Snapshot snapshot;
    StepStats stats;    ///< the last step's statistics and timings
    int shownPose = 0;  ///< the pose of the last step
    int nextPose = 0;   ///< the pose the next step moves the bones to
    ToolReading tool;   ///< the pointer tool's force as of the last step
  };

  void requestSteps(int steps);
  void work();
  void stepScene();      ///< the worker: one step, its time into stepMs_
  bool hasWork() const;  ///< under mutex_
  void publish(const DebugRequest& debug);

  std::unique_ptr<LiveScene> scene_;  ///< the worker's; scene_->scene() never changes
  DebugDrawer drawer_;                ///< the world's drawer; the worker's only
  mutable std::mutex mutex_;
  std::condition_variable wake_;       ///< the worker: a request came
  std::condition_variable published_;  ///< advance(): a snapshot was published
  // Requests, under mutex_.
  bool quit_ = false;
  bool playing_ = false;
  int stepsRequested_ = 0;
  bool reset_ = false;
  int pose_ = -1;  ///< requested pose (-1: none)
  bool loop_ = false;
  bool redraw_ = true;
  DebugRequest debug_;
  ToolMode toolMode_ = ToolMode::Camera;  ///< the pointer's mode
  PointerRay pointer_;                    ///< the pointer
  bool pointerChanged_ = false;           ///< the mode or the pointer changed since applied
  Published newest_;                      ///< the newest publication, under mutex_
  std::vector<float> stepMs_;             ///< the worker's: wall time of the recent steps [ms]
  // The window's, outside the mutex.
  Published shown_;     ///< what the window shows
  std::thread worker_;  ///< last: starts when everything above is ready
};

}  // namespace fibremss::viewer
