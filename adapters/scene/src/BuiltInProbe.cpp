// The built-in probe scene: a tool pressing into and sliding along a muscle that lies on a bone.
#include "BuiltInParts.h"

namespace fibremss::builtin {
namespace {

/// A waypoint of the probe's path: time [ms], centre [mm], the phase of the segment ending there.
Json waypoint(double timeMs, const btVector3& centre, const char* phase) {
  return Json{{"time_ms", timeMs}, {"position", vec(centre)}, {"phase", phase}};
}

}  // namespace

Json probeScene() {
  // fusiform as it is (its bars, its spindle at its default resolution), a bed 5 mm behind its
  // belly (beyond the 4 mm attachment distance: nothing fixed to it) and a 5 mm sphere that
  // comes down on the belly from the front (z), presses 8 mm into it in 300 ms, holds for
  // 100 ms and slides 40 mm along the fibres in 600 ms (67 mm/s), the muscle rolling over the bed.
  Json scene = fusiformScene();
  scene["name"] = "probe";
  scene["description"] = "a probe pressing and sliding on a muscle lying on a bone (1 kHz)";
  scene["bones"][1].erase("motion");  // the bars hold still: the tool moves
  Json bed{{"type", "box"},
           {"centre", vec({0, 0, -35})},
           {"size", vec({80, 260, 20})},
           {"divisions", Json::array({8, 26, 2})}};
  scene["bones"].push_back(bone("bed", bed));
  // Every 1 ms tick advances the region around the tool by 1 ms of simulated time in as many
  // Verlet iterations as its stable time step needs; every 2nd tick first settles the whole
  // muscle in 2 projective iterations, a far field that keeps up with the tool (docs/contact.md,
  // "A quasi-static far field"; every 4th: the region sinks with the far field between whole
  // ticks and lets go of the tool near the muscle's end). Plain projective steps: L-BFGS pairs
  // would span the tool's moves between whole ticks (in the double build they pass the rounding
  // test and the force jumps to 84 % of its peak). The skin alone: surface contact (lifting the
  // surface out of the bones) would take a quarter of the ticks' time, and the tool's force does
  // not read the surface.
  scene["simulation"]["integrator"] = "projective";
  scene["simulation"]["iterations"] = 2;
  scene["simulation"]["projective_history"] = 0;
  scene["collision"]["surface_contact"] = false;
  scene["tool"] = {
      {"radius", 5},
      {"tick_ms", 1},
      {"whole_every", 2},
      {"path",
       Json::array({waypoint(0, {0, 0, 35}, "approach"), waypoint(100, {0, 0, 25}, "approach"),
                    waypoint(400, {0, 0, 17}, "press"), waypoint(500, {0, 0, 17}, "hold"),
                    waypoint(1100, {0, 40, 17}, "slide")})}};
  return scene;
}

}  // namespace fibremss::builtin
