// The limb scenes: the hip sweeps (pelvis, femur, four hip muscles) and thigh13 (13 thigh
// muscles around femur, pelvis, patella, tibia and fibula, with a walking-like motion).
// Millimetres; y up, x lateral (a right leg), z anterior; the hip joint centre at the origin.
#include <cmath>

#include "BuiltInParts.h"

namespace fibremss::builtin {
namespace {

constexpr double kDegrees = M_PI / 180;

/// A point at height y around the femoral shaft: `phi` degrees from anterior towards lateral,
/// `distance` from the shaft's centre-line.
btVector3 around(const Tube& femur, double y, double phi, double distance) {
  // The shaft descends monotonically below the trochanter: bisect for the height.
  double low = 0.0, high = 1.0;
  for (int i = 0; i < 40; ++i) {
    const double middle = 0.5 * (low + high);
    (femur.centre(middle).y() > y ? low : high) = middle;
  }
  const btVector3 centre = femur.centre(0.5 * (low + high));
  return btVector3(centre.x() + btScalar(distance * std::sin(phi * kDegrees)), btScalar(y),
                   centre.z() + btScalar(distance * std::cos(phi * kDegrees)));
}

struct Via {
  double y, phi, distance;
};

/// A muscle from an attachment on `origin` (near originTarget) through points around the femur
/// to an attachment on `insertion`; half-axes grow from 4 mm ends to (a, b) in the middle.
TubeDefinition limbMuscle(const Tube& origin, const btVector3& originTarget,
                          const std::vector<btVector3>& through, const Tube& insertion,
                          const btVector3& insertionTarget, double a, double b) {
  std::vector<btVector3> points{attachPoint(origin, originTarget)};
  points.insert(points.end(), through.begin(), through.end());
  points.push_back(attachPoint(insertion, insertionTarget));
  std::vector<std::array<double, 2>> radii;
  const size_t n = points.size();
  for (size_t i = 0; i < n; ++i) {
    if (i == 0 || i + 1 == n) {
      radii.push_back({4, 4});
      continue;
    }
    // Full size in the middle, 75 % next to the ends.
    const double taper = (i == 1 || i + 2 == n) && n > 3 ? 0.75 : 1.0;
    radii.push_back({a * taper, b * taper});
  }
  return muscleTube(std::move(points), std::move(radii));
}

std::vector<btVector3> viaPoints(const Tube& femur, const std::vector<Via>& vias) {
  std::vector<btVector3> points;
  for (const Via& via : vias) points.push_back(around(femur, via.y, via.phi, via.distance));
  return points;
}

btTransform rotationAbout(const btVector3& pivot, const btVector3& axis, double degrees) {
  const btTransform toOrigin(btQuaternion::getIdentity(), -pivot);
  const btTransform back(btQuaternion::getIdentity(), pivot);
  return back * btTransform(btQuaternion(axis.normalized(), btScalar(degrees * kDegrees))) *
         toOrigin;
}

}  // namespace

Json hipScene(const std::string& kind) {
  const Tube femur(femurTube());
  const Tube pelvis(pelvisTube());
  Json motion;
  std::string description;
  if (kind == "flexion") {
    motion = sweep(hipCentre(), {-1, 0, 0}, 0, 90, 10);
    description = "hip flexion 0 -> 90 deg about the femoral head";
  } else if (kind == "extension") {
    motion = sweep(hipCentre(), {1, 0, 0}, 0, 80, 10);
    description = "hip extension 0 -> 80 deg about the femoral head (step_deg 2, 4, 5 or 10)";
  } else if (kind == "adduction") {
    motion = sweep(hipCentre(), {0, 0, -1}, 0, 60, 2);
    description = "hip adduction 0 -> 60 deg in 2 deg steps about the femoral head";
  } else {
    // Internal rotation about the femur's mechanical axis (head centre to knee centre).
    motion = sweep(hipCentre(), btVector3(25, -400, 0).normalized(), 0, 60, 5);
    description = "hip internal rotation 0 -> 60 deg about the femur's mechanical axis";
  }
  Json scene = header("hip-" + kind, "pelvis, femur and four hip muscles; " + description);
  scene["bones"] = Json::array({bone("pelvis", tubeGenerator(pelvis.definition())),
                                bone("femur", tubeGenerator(femur.definition()), motion)});
  // Iliopsoas wraps over the front of the femoral head; gluteus medius over its top.
  const TubeDefinition iliopsoas =
      limbMuscle(pelvis, {-5, 75, 50}, {{0, 40, 47}, {8, 0, 40}, {16, -30, 26}}, femur,
                 {20, -50, -10}, 11, 10);
  const TubeDefinition gluteusMedius =
      limbMuscle(pelvis, {10, 110, -5}, {{28, 62, 0}, {45, 22, 0}}, femur, {50, -5, 0}, 14, 10);
  const TubeDefinition gluteusMaximus = limbMuscle(
      pelvis, {-40, 75, -65}, {{-5, 30, -45}, {25, -30, -40}}, femur, {45, -100, -25}, 15, 12);
  const TubeDefinition adductorLongus = limbMuscle(
      pelvis, {-50, -40, 45}, {{-25, -90, 28}, {-5, -160, 14}}, femur, {15, -220, -8}, 13, 10);
  scene["muscles"] =
      Json::array({tubeMuscle("iliopsoas", iliopsoas), tubeMuscle("gluteus-medius", gluteusMedius),
                   tubeMuscle("gluteus-maximus", gluteusMaximus),
                   tubeMuscle("adductor-longus", adductorLongus)});
  // Reference workloads: their poses stay as documented and measured (no sub-poses).
  scene["simulation"] = {{"max_step_deg", 0}};
  return scene;
}

namespace {

/// thigh13's five bones.
struct Thigh13Bones {
  Tube pelvis;   ///< the pelvis, fixed
  Tube femur;    ///< the femur, turning about the hip
  Tube patella;  ///< the patella, following half the knee angle
  Tube tibia;    ///< the tibia, with the shank
  Tube fibula;   ///< the fibula, with the shank
};

Thigh13Bones thigh13Bones() {
  TubeDefinition patellaShape =
      boneTube({{25, -378, 37}, {25, -398, 38}, {25, -418, 36}}, {0, 0, 0});
  patellaShape.radii = {{15, 6}, {18, 8}, {13, 6}};
  patellaShape.up = {0, 0, 1};
  return Thigh13Bones{
      Tube(pelvisTube()), Tube(femurTube()), Tube(patellaShape),
      Tube(
          boneTube({{25, -455, 0}, {24, -520, 0}, {22, -650, 0}, {20, -800, 0}}, {28, 20, 15, 20})),
      Tube(boneTube({{68, -470, -12}, {66, -560, -10}, {60, -780, -8}}, {10, 7, 8}))};
}

/// thigh13's bones with their motion: walking-like, hip flexion-extension ±20 deg with knee
/// flexion up to 60 deg, 13 poses from rest around one cycle back to rest; the patella follows
/// half the knee angle.
Json thigh13BoneList(const Thigh13Bones& bones) {
  const btVector3 knee(25, -415, 0);
  std::vector<btTransform> femurPoses, shankPoses, patellaPoses;
  for (int k = 0; k <= 12; ++k) {
    const double phase = 2 * M_PI * k / 12;
    const double hip = 20 * std::sin(phase), kneeAngle = 30 * (1 - std::cos(phase));
    const btTransform femurPose = rotationAbout(hipCentre(), {-1, 0, 0}, hip);
    femurPoses.push_back(femurPose);
    shankPoses.push_back(femurPose * rotationAbout(knee, {1, 0, 0}, kneeAngle));
    patellaPoses.push_back(femurPose * rotationAbout(knee, {1, 0, 0}, kneeAngle / 2));
  }
  return Json::array(
      {bone("pelvis", tubeGenerator(bones.pelvis.definition())),
       bone("femur", tubeGenerator(bones.femur.definition()), keyframes(femurPoses)),
       bone("patella", tubeGenerator(bones.patella.definition()), keyframes(patellaPoses)),
       bone("tibia", tubeGenerator(bones.tibia.definition()), keyframes(shankPoses)),
       bone("fibula", tubeGenerator(bones.fibula.definition()), keyframes(shankPoses))});
}

/// thigh13's 13 muscles around its bones.
Json thigh13Muscles(const Thigh13Bones& bones) {
  const Tube& pelvis = bones.pelvis;
  const Tube& femur = bones.femur;
  const Tube& patella = bones.patella;
  const Tube& tibia = bones.tibia;
  const Tube& fibula = bones.fibula;
  auto vias = [&femur](const std::vector<Via>& list) { return viaPoints(femur, list); };
  Json muscles = Json::array();
  auto add = [&muscles](const std::string& name, const TubeDefinition& tube) {
    muscles.push_back(tubeMuscle(name, tube));
  };
  // Quadriceps to the patella.
  add("rectus-femoris",
      limbMuscle(pelvis, {-5, 50, 45}, vias({{-60, 5, 50}, {-200, 0, 52}, {-320, 0, 48}}), patella,
                 {25, -370, 45}, 15, 12));
  add("vastus-intermedius",
      limbMuscle(femur, {40, -90, 20}, vias({{-130, 0, 30}, {-220, 0, 29}, {-310, 0, 30}}), patella,
                 {25, -372, 38}, 15, 9));
  add("vastus-lateralis",
      limbMuscle(femur, {62, -40, 5}, vias({{-100, 75, 40}, {-220, 70, 42}, {-330, 55, 38}}),
                 patella, {40, -385, 40}, 17, 11));
  add("vastus-medialis",
      limbMuscle(femur, {20, -110, 10}, vias({{-170, -70, 36}, {-270, -65, 38}, {-345, -45, 38}}),
                 patella, {10, -390, 40}, 15, 10));
  // Medial strap muscles to the tibia.
  add("sartorius",
      limbMuscle(pelvis, {15, 100, 40}, vias({{-60, 45, 62}, {-200, -15, 64}, {-340, -80, 50}}),
                 tibia, {-5, -485, 5}, 9, 6));
  add("gracilis", limbMuscle(pelvis, {-55, -45, 35},
                             vias({{-120, -105, 60}, {-260, -110, 58}, {-380, -105, 48}}), tibia,
                             {-5, -500, 0}, 9, 7));
  // Adductors from the pubis and ischium to the femur.
  add("adductor-longus",
      limbMuscle(pelvis, {-50, -40, 45}, vias({{-110, -55, 52}, {-170, -55, 40}}), femur,
                 {18, -230, -8}, 13, 10));
  add("adductor-brevis",
      limbMuscle(pelvis, {-45, -58, 42}, vias({{-100, -80, 50}, {-135, -75, 34}}), femur,
                 {25, -150, -10}, 11, 8));
  add("adductor-magnus", limbMuscle(pelvis, {-35, -70, -25},
                                    vias({{-120, -130, 44}, {-240, -120, 40}, {-330, -95, 32}}),
                                    femur, {8, -365, -5}, 17, 12));
  // Hamstrings from the ischium to tibia and fibula; biceps' short head from the femur.
  add("biceps-femoris-long",
      limbMuscle(pelvis, {-20, -72, -40}, vias({{-110, 165, 50}, {-240, 150, 50}, {-370, 125, 48}}),
                 fibula, {70, -462, -20}, 14, 11));
  add("biceps-femoris-short",
      limbMuscle(femur, {35, -230, -15}, vias({{-290, 125, 32}, {-360, 120, 38}}), fibula,
                 {75, -470, -10}, 10, 8));
  add("semitendinosus",
      limbMuscle(pelvis, {-15, -75, -45},
                 vias({{-110, -170, 58}, {-250, -170, 60}, {-380, -150, 56}, {-440, -125, 46}}),
                 tibia, {-2, -500, 14}, 10, 8));
  add("semimembranosus", limbMuscle(pelvis, {-30, -75, -30},
                                    vias({{-130, -145, 38}, {-260, -145, 40}, {-385, -130, 40}}),
                                    tibia, {10, -470, -22}, 14, 10));
  return muscles;
}

}  // namespace

Json thigh13Scene() {
  const Thigh13Bones bones = thigh13Bones();
  Json scene = header("thigh13",
                      "13 thigh muscles x 64 fibres around femur, pelvis, patella, tibia and "
                      "fibula; a walking-like hip and knee motion over 13 poses");
  scene["bones"] = thigh13BoneList(bones);
  scene["muscles"] = thigh13Muscles(bones);
  // The thesis' workload: 13 poses as measured there (no sub-poses).
  scene["simulation"] = {{"max_step_deg", 0}};
  // Its CalculiX reference tracks the bones' contact with small sliding: the approaching
  // attachments buckle the biceps femoris short head's belly in pose 3, and with finite sliding
  // ccx stops in the increment after the snap at any increment size (comparisons/README.md).
  scene["reference"] = {{"contact_sliding", "small"}};
  return scene;
}

}  // namespace fibremss::builtin
