// The analytic built-in scenes (the analytic tier of the comparisons): a straight cylindrical
// muscle between two plates, stretched or twisted by them, whose exact answers `run` and `compare`
// print; and one with a waist that the plates stretch until it tears (no exact answer).
#include <cmath>

#include "BuiltInParts.h"

namespace fibremss::builtin {
namespace {

constexpr double kRadius = 10;     // cylinder radius [mm]
constexpr double kFreeHalf = 50;   // half the free length between the attachments [mm]
constexpr double kAttachment = 2;  // attachment distance [mm]
constexpr double kPlateFace = kFreeHalf + kAttachment;  // plates' facing sides at y = ±52
constexpr double kPlateThickness = 10;
constexpr double kNotch = kRadius / 2;  // the tear scene's radius at its middle [mm]
constexpr double kNotchHalf = 4;        // the tear scene's notch: its half length along y [mm]
constexpr double kTearShift = 1;        // the tear scene's move of each plate per pose [mm]
constexpr int kTearPoses = 40;          // the tear scene's poses after the rest pose
constexpr double kTearStretch = 1.5;    // the tear scene's break_stretch [1]

Json plate(double side) {
  return Json{{"type", "box"},
              {"centre", vec({0, btScalar(side * (kPlateFace + kPlateThickness / 2)), 0})},
              {"size", vec({60, btScalar(kPlateThickness), 60})},
              {"divisions", Json::array({12, 2, 12})}};
}

/// The cylinder scene without motions: plates at y = ±52 mm, a cylinder of radius 10 mm whose
/// flat ends sit 1.5 mm inside them, attached within 2 mm (free length 100 mm, y in ±50); with a
/// `notch` of that radius at its middle, the radius 10 mm from kNotchHalf on either side.
Json cylinderScene(const std::string& name, const std::string& description,
                   double notch = kRadius) {
  Json scene = header(name, description);
  const auto end = btScalar(kPlateFace + 1.5), side = btScalar(kNotchHalf);
  TubeDefinition tube =
      notch < kRadius
          ? muscleTube({{0, -end, 0}, {0, -side, 0}, {0, 0, 0}, {0, side, 0}, {0, end, 0}},
                       {{kRadius, kRadius},
                        {kRadius, kRadius},
                        {notch, notch},
                        {kRadius, kRadius},
                        {kRadius, kRadius}})
          : muscleTube({{0, -end, 0}, {0, 0, 0}, {0, end, 0}},
                       {{kRadius, kRadius}, {kRadius, kRadius}, {kRadius, kRadius}});
  Json muscle = tubeMuscle("cylinder", tube);
  muscle["attachment_distance"] = kAttachment;
  scene["muscles"] = Json::array({muscle});
  // The exact answers are static: the default solver comes near each pose's equilibrium in the
  // iterations each scene sets (below) with the ends turned or pulled over the first tenth, not
  // onto it (cylinder-twist's residual at 26 iterations: 0.004 mm; docs/performance.md); a time
  // integrator needs `stop=converged`, `epsilon=1e-4`, `iterations=4000`,
  // `motion_fraction=0.025`.
  scene["simulation"] = {{"motion_fraction", 0.1}};
  return scene;
}

Json analytic(const std::string& type, double stretch, double twistDeg) {
  return Json{{"type", type},
              {"axis_start", vec({0, btScalar(-kFreeHalf), 0})},
              {"axis_end", vec({0, btScalar(kFreeHalf), 0})},
              {"stretch", stretch},
              {"twist_deg", twistDeg}};
}

}  // namespace

Json cylinderStretchScene() {
  // Both plates move apart along the axis, 2.5 mm each per pose: the free length 100 → 110 mm.
  Json scene = cylinderScene("cylinder-stretch",
                             "a straight cylindrical muscle stretched 10 % by its attachments");
  std::vector<btTransform> up, down;
  for (int i = 0; i < 3; ++i) {
    const btScalar shift = btScalar(0.05 * kFreeHalf * i);
    up.emplace_back(btQuaternion::getIdentity(), btVector3(0, shift, 0));
    down.emplace_back(btQuaternion::getIdentity(), btVector3(0, -shift, 0));
  }
  scene["bones"] = Json::array({bone("plate-lower", plate(-1), keyframes(down)),
                                bone("plate-upper", plate(1), keyframes(up))});
  scene["analytic"] = analytic("cylinder-stretch", 1.1, 0);
  // 20 iterations per pose: its ν and volume have settled by then (effective ν 0.482 and +0.365 %
  // at 20, 0.482 and +0.364 % at 30 and at 400: the model's own ν, docs/decisions.md, "Volume
  // terms"); at 8, 10 and 11 ν is 0.465, 0.472 and 0.478.
  scene["simulation"]["iterations"] = 20;
  return scene;
}

Json cylinderTwistScene() {
  // The upper plate turns about the axis 45° per pose, the lower one holds: 180° in four poses.
  Json scene =
      cylinderScene("cylinder-twist", "a straight cylindrical muscle, one end twisted 180 deg");
  std::vector<btTransform> turns;
  for (int i = 0; i <= 4; ++i)
    turns.emplace_back(btQuaternion(btVector3(0, 1, 0), btScalar(M_PI / 4 * i)),
                       btVector3(0, 0, 0));
  scene["bones"] = Json::array(
      {bone("plate-lower", plate(-1)), bone("plate-upper", plate(1), keyframes(turns))});
  scene["analytic"] = analytic("cylinder-twist", 1, 180);
  // The poses as given (45° each), not split into 5° sub-poses: the static answer does not
  // depend on the path, and the CalculiX reference solves 5 poses instead of 37 (FibreMSS's
  // last pose is the same within 0.1°: mid section 90.26° against 90.35° with 5° poses).
  scene["simulation"]["max_step_deg"] = 45;
  // 26 iterations per pose (at least 23: one per 2° of a 45° turn): 0.285 mm RMS to CalculiX and
  // the worst section 0.984° off the linear profile, against 0.281 mm and 0.359° at 30 and 0.313
  // mm and 1.78° at 23.
  scene["simulation"]["iterations"] = 26;
  return scene;
}

Json tearScene() {
  // A short notch of half the radius (a quarter of the section) takes the stretch: its springs
  // pass break_stretch there first while the rest of the cylinder stays below it, so it tears
  // across the notch into two pieces, one on each plate. The plates move apart 5 mm each per pose.
  Json scene = cylinderScene("tear",
                             "a cylindrical muscle with a waist stretched by its attachments until "
                             "it tears",
                             kNotch);
  std::vector<btTransform> up, down;
  for (int i = 0; i <= kTearPoses; ++i) {
    const btScalar shift = btScalar(kTearShift * i);
    up.emplace_back(btQuaternion::getIdentity(), btVector3(0, shift, 0));
    down.emplace_back(btQuaternion::getIdentity(), btVector3(0, -shift, 0));
  }
  scene["bones"] = Json::array({bone("plate-lower", plate(-1), keyframes(down)),
                                bone("plate-upper", plate(1), keyframes(up))});
  scene["model"]["break_stretch"] = kTearStretch;
  return scene;
}

}  // namespace fibremss::builtin
