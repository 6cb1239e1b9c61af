#pragma once
// A scene's tool run at haptic rate (`fibremss run` of a scene with a `tool`): the scene's
// muscles and bones in a MuscleSystem, its tool a kinematic sphere posed by the script every
// tick through HapticTool, the force on it recorded per tick.
#include <LinearMath/btVector3.h>

#include <string>
#include <vector>

#include "fibremss/Scene.h"

namespace fibremss {

/// One tick of a tool run.
struct ToolTickRecord {
  double time = 0;              ///< simulated time at the tick's end [s]
  btVector3 position{0, 0, 0};  ///< the tool's centre [m]
  btVector3 force{0, 0, 0};     ///< the muscles' force on the tool (contactWrench) [N]
  size_t contacts = 0;          ///< particle spheres overlapping the tool at its pose
};

/// What a tool run measured.
struct ToolRunResult {
  std::vector<ToolTickRecord> ticks;  ///< one per tick of the script
  double wallSeconds = 0;             ///< wall time of the ticks, force queries included [s]
  double ticksPerSecond = 0;          ///< ticks / wallSeconds
  double cpuSeconds = 0;  ///< processor time of the ticks, every thread of the process [s]
  long iterations = 0;    ///< solver iterations over all ticks
  long wholeTicks = 0;    ///< ticks that stepped the whole muscles (the rest their region)
  double peakForce = 0;   ///< largest |force| over the run [N]
  /// Largest |force(t) − force(t−1)| between two ticks of the script's "slide" phase [N].
  double slideJump = 0;
  int firstContact = -1;  ///< the first tick (from 1, as ticks.csv) with a force (-1: none)
  int threads = 0;        ///< threads the muscles stepped with
  bool failed = false;    ///< a tick's step failed numerically (NaN/inf, burst springs)
};

/// Runs the scene's tool script (scene.tool.present) tick by tick from the muscles at rest.
/// `threads` overrides the scene's simulation.threads when ≥ 0.
ToolRunResult runTool(const LoadedScene& scene, const PreparedScene& prepared, int threads = -1);

/// The force trace as CSV: tick, time_s, phase, x/y/z of the tool [scene units], force x/y/z
/// and |force| [N], contacts.
std::string ticksCsv(const LoadedScene& scene, const ToolRunResult& result);

}  // namespace fibremss
