#include "BuiltInParts.h"

#include <cmath>

#include "BuiltInScenes.h"
#include "fibremss/Scene.h"

namespace fibremss::builtin {
namespace {

double rounded(double value) {
  return std::round(value * 1000) / 1000;
}

}  // namespace

Json vec(const btVector3& v) {
  return Json::array({rounded(v.x()), rounded(v.y()), rounded(v.z())});
}

Json header(const std::string& name, const std::string& description) {
  return Json{{"name", name}, {"description", description}, {"units", "mm"}};
}

Json tubeGenerator(const TubeDefinition& tube) {
  Json points = Json::array(), radii = Json::array();
  for (const auto& p : tube.points) points.push_back(vec(p));
  for (const auto& [a, b] : tube.radii)
    radii.push_back(a == b ? Json(rounded(a)) : Json::array({rounded(a), rounded(b)}));
  Json generator{{"type", "tube"}, {"points", points}, {"radii", radii}};
  if (tube.up.length2() > 0) generator["up"] = vec(tube.up);
  generator["slices"] = tube.slices;
  generator["sections"] = tube.sections;
  generator["caps"] = tube.roundCaps ? "round" : "flat";
  return generator;
}

Json bone(const std::string& name, Json generator, Json motion) {
  Json result{{"name", name}, {"mesh", {{"generator", std::move(generator)}}}};
  if (!motion.is_null()) result["motion"] = std::move(motion);
  return result;
}

Json tubeMuscle(const std::string& name, const TubeDefinition& tube) {
  // One material, no tendons: btSoftBody, Bullet FEM and the CalculiX reference built from the
  // same scene model none, and a comparison must solve one problem. The ends sit 1.5 mm inside
  // their bones: 4 mm fixes the first particles (the measured workloads' distance).
  return Json{{"name", name},
              {"surface", {{"generator", tubeGenerator(tube)}}},
              {"fibres", {{"generator", {{"type", "tube"}}}}},
              {"tendon_fraction", 0},
              {"attachment_distance", 4}};
}

Json sweep(const btVector3& pivot, const btVector3& axis, double start, double end, double step) {
  return Json{{"type", "sweep"},    {"pivot", vec(pivot)}, {"axis", vec(axis)},
              {"start_deg", start}, {"end_deg", end},      {"step_deg", step}};
}

Json keyframes(const std::vector<btTransform>& poses) {
  Json frames = Json::array();
  for (const btTransform& pose : poses) {
    const btQuaternion q = pose.getRotation();
    auto r6 = [](double v) { return std::round(v * 1e6) / 1e6; };
    frames.push_back(
        Json{{"translation", vec(pose.getOrigin())},
             {"quaternion", Json::array({r6(q.x()), r6(q.y()), r6(q.z()), r6(q.w())})}});
  }
  return Json{{"type", "keyframes"}, {"keyframes", frames}};
}

btVector3 attachPoint(const Tube& bone, const btVector3& target, double depth) {
  // Nearest centre-line point to the target, then the section's surface towards the target.
  double bestT = 0, best = 1e30;
  for (int i = 0; i <= 400; ++i) {
    const double t = i / 400.0;
    const double d = (bone.centre(t) - target).length2();
    if (d < best) best = d, bestT = t;
  }
  const btVector3 offset = target - bone.centre(bestT);
  const double u = offset.dot(bone.side(bestT)), v = offset.dot(bone.normal(bestT));
  const double angle = std::atan2(v, u);
  const auto radii = bone.radii(bestT);
  const double ca = std::cos(angle), sa = std::sin(angle);
  const double r =
      1.0 / std::sqrt(ca * ca / (radii[0] * radii[0]) + sa * sa / (radii[1] * radii[1]));
  const double inner = std::max(0.0, r - depth) / r;
  return bone.at(bestT, inner * r / radii[0] * ca, inner * r / radii[1] * sa);
}

TubeDefinition boneTube(std::vector<btVector3> points, std::vector<double> radii) {
  TubeDefinition tube;
  tube.points = std::move(points);
  for (double r : radii) tube.radii.push_back({r, r});
  // Fine enough that the two-ring bone spheres hug the surface.
  tube.slices = 48;
  tube.sections = std::max(16, int(tube.points.size()) * 16);
  tube.roundCaps = true;
  return tube;
}

TubeDefinition muscleTube(std::vector<btVector3> points, std::vector<std::array<double, 2>> radii,
                          const btVector3& up) {
  TubeDefinition tube;
  tube.points = std::move(points);
  tube.radii = std::move(radii);
  tube.up = up;
  // Dense enough that every outer particle is the closest of some surface vertex up to
  // resolution 80 (the boundary counts then match the thesis' Table 5.2).
  tube.slices = 40;
  tube.sections = 128;
  return tube;
}

TubeDefinition femurTube() {
  // Head centred on the hip joint, neck, greater trochanter, shaft, condyles (mm, y up,
  // x lateral, z anterior).
  return boneTube({{0, 0, 0},
                   {9, -4.5, 0},
                   {24, -12, 0},
                   {42, -28, 0},
                   {40, -70, 0},
                   {33, -200, 0},
                   {27, -340, 0},
                   {25, -400, 0}},
                  {22, 20, 14, 18, 15, 13, 15, 24});
}

TubeDefinition pelvisTube() {
  // One C-shaped piece: posterior ilium, iliac crest, anterior ilium, medial acetabular wall
  // (clear of the femoral head), pubis, obturator ring, ischial tuberosity.
  return boneTube({{-35, 80, -45},
                   {-5, 105, -5},
                   {-15, 70, 35},
                   {-40, 15, 5},
                   {-45, -35, 30},
                   {-40, -60, 0},
                   {-25, -60, -35}},
                  {14, 16, 13, 13, 10, 10, 12});
}

}  // namespace fibremss::builtin

namespace fibremss {

std::vector<BuiltInScene> builtInScenes() {
  return {
      {"fusiform", "one spindle-shaped muscle between two bars; the lower bar pulls it longer"},
      {"thigh13",
       "13 thigh muscles x 64 fibres around femur, pelvis, patella, tibia, fibula; walking"},
      {"hip-flexion", "pelvis, femur and 4 hip muscles; hip flexion 0 -> 90 deg"},
      {"hip-extension", "pelvis, femur and 4 hip muscles; hip extension 0 -> 80 deg (step_deg 10)"},
      {"hip-adduction",
       "pelvis, femur and 4 hip muscles; hip adduction 0 -> 60 deg in 2 deg steps"},
      {"hip-rotation", "pelvis, femur and 4 hip muscles; internal rotation 0 -> 60 deg"},
      {"hip-pelvis",
       "pelvis with a brim, femur with head and lesser trochanter, iliacus, psoas, gluteal; "
       "declared attachments; flexion 0 -> 90 deg"},
      {"tension-spike", "a short muscle whose attachments jump 40 mm apart in one pose, then hold"},
      {"pinch", "a muscle between two bones that pass each other like shear blades"},
      {"sphere-denoise", "a sphere of 3840 particles perturbed by noise, no bones (integrators)"},
      {"sphere-planes", "a soft noisy sphere squeezed between two closing plates"},
      {"cylinder-stretch",
       "a straight cylindrical muscle stretched 10 % by its attachments (exact answer known)"},
      {"cylinder-twist",
       "a straight cylindrical muscle, one end twisted 180 deg (exact answer known)"},
      {"tear", "a cylindrical muscle with a waist stretched until it tears (break_stretch 1.5)"},
      {"probe", "a probe pressing and sliding on a muscle lying on a bone, at 1 kHz (a tool)"},
      {"cut", "fusiform under tension cut across by a blade sweeping through it"},
  };
}

std::string builtInSceneDefinition(const std::string& name) {
  using namespace builtin;
  Json scene;
  if (name == "fusiform")
    scene = fusiformScene();
  else if (name == "thigh13")
    scene = thigh13Scene();
  else if (name == "hip-flexion")
    scene = hipScene("flexion");
  else if (name == "hip-extension")
    scene = hipScene("extension");
  else if (name == "hip-adduction")
    scene = hipScene("adduction");
  else if (name == "hip-rotation")
    scene = hipScene("rotation");
  else if (name == "hip-pelvis")
    scene = hipPelvisScene();
  else if (name == "tension-spike")
    scene = tensionSpikeScene();
  else if (name == "pinch")
    scene = pinchScene();
  else if (name == "sphere-denoise")
    scene = sphereDenoiseScene();
  else if (name == "sphere-planes")
    scene = spherePlanesScene();
  else if (name == "cylinder-stretch")
    scene = cylinderStretchScene();
  else if (name == "cylinder-twist")
    scene = cylinderTwistScene();
  else if (name == "tear")
    scene = tearScene();
  else if (name == "probe")
    scene = probeScene();
  else if (name == "cut")
    scene = cutScene();
  else
    return "";
  return scene.dump();
}

}  // namespace fibremss
