#pragma once
// Plays the frames a run wrote (DIR/run.pvd and the .vtp files it lists, read with the io
// layer's VTK XML reader): one frame per timestep of the collection, muscle surfaces with their
// point-data arrays, bones, and on request the particles and fibres; play/pause, step, reset
// and a scrub slider over the frames. Frames are read when shown (a still bone once).
#include <chrono>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "Source.h"
#include "fibremss/VtkFiles.h"

namespace fibremss::viewer {

class FramePlayer : public Source {
 public:
  /// Reads DIR/run.pvd (and the units of DIR/scene.json, the timings of DIR/summary.json when
  /// there); InputError when the collection is missing, malformed or lists no frame.
  FramePlayer(const std::string& runDir, const DebugRequest& debug);

  bool fetch(Snapshot& into) override;
  Playback controls(const Snapshot& shown) override;
  void timings(const Snapshot& shown) override;
  void togglePlaying() override { playing_ = !playing_; }
  bool playing() const override { return playing_; }
  void step() override { show(index_ + 1); }
  void reset() override { show(0); }
  void setDebug(const DebugRequest& debug) override;
  void advance(int steps) override { show(index_ + steps); }

  bool loop = false;  ///< playing past the last frame starts again at the first

 private:
  /// The files of one timestep.
  struct Frame {
    double time = 0;                     ///< simulated time [s]
    std::vector<std::string> surfaces;   ///< muscle surfaces
    std::vector<std::string> particles;  ///< muscle particles and fibres
    std::vector<std::string> bones;      ///< bones where they are
  };

  void show(int index);  ///< makes frame `index` (clamped) the one to fetch
  void load();           ///< reads the current frame into snapshot_
  ViewMesh surface(const std::string& file, size_t muscle) const;
  const ViewMesh& bone(const std::string& file);
  void drawParticles(const PolyDataFile& particles, DebugGeometry& debug) const;

  std::string dir_;
  double scale_ = 1;  ///< metres per file unit (the scene's units)
  std::vector<Frame> frames_;
  nlohmann::json summary_;  ///< DIR/summary.json (null when absent)
  int index_ = 0;           ///< the frame to show
  bool playing_ = false;
  bool loaded_ = false;  ///< snapshot_ holds frames_[index_] drawn for debug_
  DebugRequest debug_;
  Snapshot snapshot_;
  double readMs_ = 0;                              ///< time it took to read the shown frame [ms]
  std::chrono::steady_clock::time_point shownAt_;  ///< when the shown frame was loaded
  std::map<std::string, ViewMesh> bones_;          ///< the shown frame's bone files, read
};

}  // namespace fibremss::viewer
