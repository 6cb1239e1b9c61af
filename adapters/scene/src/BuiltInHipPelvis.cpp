// The hip-pelvis scene: a pelvis-like bone with a brim, a femur with a head and a
// lesser trochanter, and three muscles that bring out what the nearest-bone attachment rule gets
// wrong: an iliacus whose belly passes just in front of the femoral head, a psoas that slides
// over the brim to the lesser trochanter, a gluteal muscle over the back of the joint. Each
// declares its origin and insertion (landmarks at its tube's ends, the bones they attach to), so
// only its ends are fixed and the belly slides over the bones. Millimetres; y up, x lateral,
// z anterior, the femoral head's centre at the origin.
#include "BuiltInParts.h"

namespace fibremss::builtin {
namespace {

/// Pelvis: one C-shaped tube from the anterior superior iliac spine over the iliac crest, the
/// posterior ilium and the body of the ilium (clear of the femoral head) to the brim (iliopubic
/// eminence) and the pubis. The iliac wing's inner face (iliac fossa) looks medially.
TubeDefinition hipPelvisTube() {
  return boneTube({{-8, 100, 42},
                   {-12, 128, 5},
                   {-30, 112, -40},
                   {-42, 70, -30},
                   {-12, 30, -10},
                   {-6, 26, 18},
                   {-36, 24, 32},
                   {-62, -2, 38}},
                  {10, 12, 14, 14, 9, 8, 9, 10});
}

/// Femur: head (centred on the hip joint), neck, greater trochanter, the lesser trochanter
/// (the centre-line swings posteromedially there, a bump on the medial side), shaft, condyles.
TubeDefinition hipPelvisFemurTube() {
  return boneTube({{0, 0, 0},
                   {9, -4.5, 0},
                   {24, -12, 0},
                   {42, -28, 0},
                   {34, -60, -6},
                   {40, -90, 0},
                   {33, -200, 0},
                   {27, -340, 0},
                   {25, -400, 0}},
                  {22, 20, 14, 18, 18, 14, 13, 15, 24});
}

/// A tube muscle from an attachment on `origin` (near originTarget) through `through` to one on
/// `insertion`, with half-axes `radii` per point (ends included), declaring its ends as its origin
/// and insertion: landmarks at the tube's end points, `radius` around them.
Json declaredMuscle(const std::string& name, const Tube& origin, const std::string& originBone,
                    const btVector3& originTarget, const std::vector<btVector3>& through,
                    const Tube& insertion, const std::string& insertionBone,
                    const btVector3& insertionTarget, std::vector<std::array<double, 2>> radii) {
  std::vector<btVector3> points{attachPoint(origin, originTarget)};
  points.insert(points.end(), through.begin(), through.end());
  points.push_back(attachPoint(insertion, insertionTarget));
  const btVector3 first = points.front(), last = points.back();
  Json muscle = tubeMuscle(name, muscleTube(std::move(points), std::move(radii)));
  constexpr double kAreaRadius = 8;
  muscle["origin"] = {{"landmarks", Json::array({vec(first)})},
                      {"radius", kAreaRadius},
                      {"bones", Json::array({originBone})}};
  muscle["insertion"] = {{"landmarks", Json::array({vec(last)})},
                         {"radius", kAreaRadius},
                         {"bones", Json::array({insertionBone})}};
  return muscle;
}

}  // namespace

Json hipPelvisScene() {
  const Tube pelvis(hipPelvisTube());
  const Tube femur(hipPelvisFemurTube());
  Json scene = header("hip-pelvis",
                      "pelvis with a brim, femur with head and lesser trochanter; iliacus over "
                      "the femoral head, psoas over the brim, a gluteal muscle over the back, "
                      "declared attachments; hip flexion 0 -> 90 deg in 10 deg steps");
  scene["bones"] = Json::array({bone("pelvis", tubeGenerator(pelvis.definition())),
                                bone("femur", tubeGenerator(femur.definition()),
                                     sweep(hipCentre(), {-1, 0, 0}, 0, 90, 10))});
  // Iliacus: the iliac fossa (inner face of the wing), down medial to the anterior spine and
  // in front of the femoral head (its surface about 0.3 mm from it) to the lesser trochanter.
  Json iliacus =
      declaredMuscle("iliacus", pelvis, "pelvis", {-40, 115, 25},
                     {{-22, 80, 45}, {2, 34, 36}, {3, 10, 33}, {16, -28, 24}}, femur, "femur",
                     {10, -64, -2}, {{4, 4}, {12, 9}, {12, 11}, {12, 12}, {9, 9}, {4, 4}});
  // Psoas: from the inner face of the posterior ilium, down inside the pelvic ring, over the
  // brim (about 1.4 mm above it), then medially round the femur to the back of the lesser
  // trochanter.
  Json psoas =
      declaredMuscle("psoas", pelvis, "pelvis", {-60, 120, -25},
                     {{-55, 85, 0}, {-50, 45, 30}, {-36, 20, 52}, {-12, -35, 25}}, femur, "femur",
                     {20, -62, -30}, {{4, 4}, {10, 10}, {10, 10}, {10, 10}, {8, 8}, {4, 4}});
  // Gluteal: from the posterior ilium over the back of the joint to the greater trochanter.
  Json gluteal =
      declaredMuscle("gluteal", pelvis, "pelvis", {-15, 105, -70}, {{20, 40, -32}, {45, -5, -22}},
                     femur, "femur", {60, -22, -12}, {{4, 4}, {14, 10}, {10, 8}, {4, 4}});
  scene["muscles"] = Json::array({std::move(iliacus), std::move(psoas), std::move(gluteal)});
  for (Json& muscle : scene["muscles"]) {
    muscle["fibre_count"] = 64;
    muscle["resolution"] = 18;
    muscle.erase("tendon_fraction");  // anatomy: the default tendons
  }
  // The reference frees the bellies (declared areas): with finite sliding iliacus's return step
  // diverges as its belly leaves the femoral head (comparisons/README.md).
  scene["reference"] = {{"contact_sliding", "small"}};
  return scene;
}

}  // namespace fibremss::builtin
