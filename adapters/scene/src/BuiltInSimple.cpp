// The small built-in scenes: fusiform, cut, tension-spike, pinch, sphere-denoise, sphere-planes.
#include <algorithm>

#include "BuiltInParts.h"

namespace fibremss::builtin {

constexpr int kCutPoses = 8;  ///< the cut scene's poses: rest, 4 of the sweep, 3 held

Json fusiformScene() {
  // Two horizontal bars 320 mm apart, a 293 mm spindle between them whose ends sit 1.5 mm
  // inside the bars; the lower bar moves down 30 mm in three poses (a stretch test).
  Json scene = header("fusiform", "one spindle-shaped muscle between two bars");
  const TubeDefinition upper = boneTube({{-60, 160, 0}, {60, 160, 0}}, {15, 15});
  const TubeDefinition lower = boneTube({{-60, -160, 0}, {60, -160, 0}}, {15, 15});
  std::vector<btTransform> poses;
  for (int i = 0; i < 3; ++i)
    poses.emplace_back(btQuaternion::getIdentity(), btVector3(0, btScalar(-15 * i), 0));
  scene["bones"] = Json::array(
      {bone("upper", tubeGenerator(upper)), bone("lower", tubeGenerator(lower), keyframes(poses))});
  const TubeDefinition muscle =
      muscleTube({{0, 146.5, 0}, {0, 75, 0}, {0, 0, 0}, {0, -75, 0}, {0, -146.5, 0}},
                 {{6, 6}, {14, 14}, {20, 20}, {14, 14}, {6, 6}});
  scene["muscles"] = Json::array({tubeMuscle("fusiform", muscle)});
  return scene;
}

Json cutScene() {
  // fusiform between its bars, the lower bar held 10 mm down (the spindle under tension); a
  // blade whose 80 mm edge lies along x sweeps across the spindle along z at y = 60 mm (radius
  // about 15 mm there), 20 mm per pose from z = -40 to +40 mm, then the bars hold two poses
  // while the cut halves draw back to their bars.
  Json scene = fusiformScene();
  scene["name"] = "cut";
  scene["description"] = "fusiform under tension cut across by a blade";
  std::vector<btTransform> bar, blade;
  for (int i = 0; i < kCutPoses; ++i) {
    bar.emplace_back(btQuaternion::getIdentity(), btVector3(0, -10, 0));
    const double z = std::min(-40.0 + 20.0 * std::max(i - 1, 0), 40.0);
    blade.emplace_back(btQuaternion::getIdentity(), btVector3(0, 0, btScalar(z)));
  }
  scene["bones"][1]["motion"] = keyframes(bar);
  scene["blades"] = Json::array({Json{{"name", "blade"},
                                      {"from", Json::array({-40, 60, 0})},
                                      {"to", Json::array({40, 60, 0})},
                                      {"motion", keyframes(blade)}}});
  return scene;
}

Json tensionSpikeScene() {
  // A stability hard case: a short spindle between two bars that jump 20 mm apart
  // each in one pose (the muscle from 103 to 143 mm, a sudden 1.4x stretch), then hold for six
  // poses so that a stable integrator's kinetic energy decays and an unstable one's grows.
  Json scene = header("tension-spike", "a short muscle whose attachments jump apart, then hold");
  const TubeDefinition upper = boneTube({{-30, 65, 0}, {30, 65, 0}}, {15, 15});
  const TubeDefinition lower = boneTube({{-30, -65, 0}, {30, -65, 0}}, {15, 15});
  std::vector<btTransform> up{btTransform::getIdentity()}, down{btTransform::getIdentity()};
  for (int i = 0; i < 7; ++i) {
    up.emplace_back(btQuaternion::getIdentity(), btVector3(0, 20, 0));
    down.emplace_back(btQuaternion::getIdentity(), btVector3(0, -20, 0));
  }
  scene["bones"] = Json::array({bone("upper", tubeGenerator(upper), keyframes(up)),
                                bone("lower", tubeGenerator(lower), keyframes(down))});
  // Ends 1.5 mm inside the bars (their facing sides at y = ±50).
  const TubeDefinition muscle =
      muscleTube({{0, 51.5, 0}, {0, 25, 0}, {0, 0, 0}, {0, -25, 0}, {0, -51.5, 0}},
                 {{4, 4}, {8, 8}, {10, 10}, {8, 8}, {4, 4}});
  scene["muscles"] = Json::array({tubeMuscle("spiked", muscle)});
  return scene;
}

Json pinchScene() {
  // Blade A (upper, z > 0) moves down and blade B (lower, z < 0) moves up; they pass each other
  // with a 2 mm gap at z = 0 where the muscle lies, attached at its left end under A and its
  // right end on top of B.
  Json scene = header("pinch", "a muscle between two bones passing each other like shear blades");
  const btVector3 sizeA(120, 20, 30);
  Json bladeA{{"type", "box"},
              {"centre", vec({-30, 22, 16})},
              {"size", vec(sizeA)},
              {"divisions", Json::array({24, 4, 6})}};
  Json bladeB{{"type", "box"},
              {"centre", vec({30, -22, -16})},
              {"size", vec(sizeA)},
              {"divisions", Json::array({24, 4, 6})}};
  std::vector<btTransform> down, up;
  for (int i = 0; i <= 6; ++i) {
    down.emplace_back(btQuaternion::getIdentity(), btVector3(0, btScalar(-7 * i), 0));
    up.emplace_back(btQuaternion::getIdentity(), btVector3(0, btScalar(7 * i), 0));
  }
  scene["bones"] = Json::array(
      {bone("blade-a", bladeA, keyframes(down)), bone("blade-b", bladeB, keyframes(up))});
  // Ends 1.5 mm inside the blades' facing sides (A's bottom at y = 12, B's top at y = -12).
  // Its body keeps 5 mm from both blades at rest, clear of the attachment distance.
  const TubeDefinition muscle =
      muscleTube({{-80, 13.5, 12}, {-55, 0, 5}, {0, 0, 0}, {55, 0, -5}, {80, -13.5, -12}},
                 {{4, 4}, {6, 6}, {7, 7}, {6, 6}, {4, 4}});
  scene["muscles"] = Json::array({tubeMuscle("pinched", muscle)});
  // Its CalculiX reference (and every gate's solve) tracks the blades' contact with small
  // sliding: the C3D10 gate stops in pose 1 with finite sliding and solves with small, and the
  // muscle slides along a blade by 0.72 mm at most within an increment (against 5 mm faces;
  // comparisons/README.md).
  scene["reference"] = {{"contact_sliding", "small"}};
  return scene;
}

namespace {

constexpr double kSphereRadius = 30;  // [mm]

Json sphereMuscle(int subdivisions) {
  // 64 chords × resolution 60 = 3840 particles (seed 002's sphere had 3840 vertices).
  return Json{{"name", "sphere"},
              {"surface",
               {{"generator",
                 {{"type", "ellipsoid"},
                  {"centre", vec({0, 0, 0})},
                  {"radii", vec({kSphereRadius, kSphereRadius, kSphereRadius})},
                  {"subdivisions", subdivisions}}}}},
              {"fibres", {{"generator", {{"type", "chords"}, {"axis", vec({0, 0, 1})}}}}},
              {"fibre_count", 64},
              {"resolution", 60},
              {"attachment_distance", 0},
              {"free_end", "both"}};  // held by the plates' contact alone, or by nothing
}

}  // namespace

Json sphereDenoiseScene() {
  Json scene =
      header("sphere-denoise", "a sphere of 3840 particles perturbed by 0.2 mm of noise, no bones");
  scene["muscles"] = Json::array({sphereMuscle(3)});
  // Noise a fifth of the ~1 mm sample spacing: 1.5 mm left jittered short springs beyond 3×
  // their rest length before the first iteration (flagged as exploded at step 0).
  scene["simulation"] = {
      {"stop", "converged"}, {"epsilon", 0.001}, {"iterations", 5000}, {"initial_noise", 0.2}};
  return scene;
}

Json spherePlanesScene() {
  // Two plates (thin boxes) touch the sphere at rest and close in on it, each by δ = 0.25 and
  // 0.5 mm (δ/R ≤ 1.7 %: Hertz's small-strain contact), so collision must squeeze it between
  // them; light noise as in sphere-denoise. (3 mm of noise, three sample spacings, made the
  // double-precision self-reference tear springs beyond 3×.) The surface is finer than
  // sphere-denoise's (10 242 vertices, ~1 mm edges) so that the contact patch, radius
  // √(Rδ) = 2.7–3.9 mm, spans several edges.
  Json scene = header("sphere-planes", "a soft noisy sphere squeezed between two closing plates");
  auto plate = [](double side) {
    return Json{{"type", "box"},
                {"centre", vec({0, btScalar(side * (kSphereRadius + 2)), 0})},
                {"size", vec({120, 4, 120})},
                {"divisions", Json::array({12, 1, 12})}};
  };
  std::vector<btTransform> down, up;
  for (const double approach : {0.0, 0.25, 0.5}) {
    down.emplace_back(btQuaternion::getIdentity(), btVector3(0, btScalar(-approach), 0));
    up.emplace_back(btQuaternion::getIdentity(), btVector3(0, btScalar(approach), 0));
  }
  scene["bones"] = Json::array({bone("plane-top", plate(1), keyframes(down)),
                                bone("plane-bottom", plate(-1), keyframes(up))});
  scene["muscles"] = Json::array({sphereMuscle(5)});
  scene["simulation"] = {
      {"stop", "converged"}, {"epsilon", 0.001}, {"iterations", 5000}, {"initial_noise", 0.2}};
  scene["analytic"] = {{"type", "sphere-planes"},
                       {"axis_start", vec({0, 0, 0})},
                       {"axis_end", vec({0, btScalar(kSphereRadius), 0})},
                       {"plate", "plane-top"}};
  return scene;
}

}  // namespace fibremss::builtin
