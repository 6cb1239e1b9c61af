#pragma once
// Where the viewer's pictures come from: a scene stepped live (LivePlayer) or a
// run's frames (FramePlayer). The window fetches the source's newest Snapshot
// every frame, draws the source's controls and timings in its panel and passes
// the playback keys on.
#include <vector>

#include "DebugDrawer.h"
#include "PointerTools.h"
#include "ViewFrame.h"

namespace fibremss::viewer {

/// What the window shows at one moment.
struct Snapshot {
  ViewFrame frame;            ///< surfaces and bones
  DebugGeometry debug;        ///< lines and points: what the world's debugDrawWorld
                              ///< drew, or the particles and fibres of a frame
  int steps = 0;              ///< steps taken (live) or the frame's index from 0 (frames)
  std::vector<float> stepMs;  ///< wall time of the recent steps, oldest first [ms] (live)
  long version = -1;          ///< increases with every new snapshot
};

/// What the panel's playback part showed, counted from 0 as everywhere in the viewer.
struct Playback {
  int counter = 0;        ///< the frame (a run) or pose (live) its text names
  int slider = 0;         ///< its slider: the frame to show (a run) or the next pose (live)
  int step = -1;          ///< the step its text names (-1: a run's frame not in its summary)
  float toolForce = 0;    ///< |force| of the pointer's tool its text names [N]
  size_t cutSprings = 0;  ///< springs the blade cut, as its text names
};

/// What to draw besides the surfaces (through the world's btIDebugDraw when
/// live).
struct DebugRequest {
  int muscleFlags = 0;  ///< DebugDrawFlag bits (MuscleWorld::setMuscleDebugFlags)
  int bulletMode = 0;   ///< btIDebugDraw::DebugDrawModes bits for Bullet's own drawing
  bool operator==(const DebugRequest&) const = default;
};

class Source {
 public:
  virtual ~Source() = default;

  /// Copies the newest snapshot into `into` when it is newer; returns whether
  /// it was.
  virtual bool fetch(Snapshot& into) = 0;
  /// Draws the panel's playback part: where it is, play/pause, step, reset,
  /// scrub; returns what its counter and slider showed.
  virtual Playback controls(const Snapshot& shown) = 0;
  /// Draws the per-part timings.
  virtual void timings(const Snapshot& shown) = 0;

  virtual void togglePlaying() = 0;  ///< play or pause
  virtual bool playing() const = 0;  ///< whether it plays (a run's frames stop at the last)
  virtual void step() = 0;           ///< one step (frame) forward
  virtual void reset() = 0;          ///< back to the start
  /// What to draw besides the surfaces (muscleFlags: particles, fibres, ...).
  virtual void setDebug(const DebugRequest& debug) = 0;
  /// Goes `steps` steps (frames) forward and returns once that is what fetch()
  /// gives.
  virtual void advance(int steps) = 0;
  /// The pointer as a tool in `mode` (a scene stepped live steps with it; a run's frames have
  /// nothing to touch).
  virtual void setPointer(ToolMode /*mode*/, const PointerRay& /*ray*/) {}
};

}  // namespace fibremss::viewer
