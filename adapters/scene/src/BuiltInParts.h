#pragma once
// Internal to the built-in scenes: JSON building blocks (lengths in millimetres) and helpers
// that place muscle ends on bone surfaces so that they become attachments.
#include <LinearMath/btTransform.h>

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "fibremss/Procedural.h"

namespace fibremss::builtin {

using Json = nlohmann::ordered_json;

/// [x, y, z], rounded to 1 µm so that exported files stay readable.
Json vec(const btVector3& v);

/// {"name", "description", "units": "mm"} (the rest is filled in by the loader's defaults).
Json header(const std::string& name, const std::string& description);

/// {"type": "tube", ...} for a tube definition given in millimetres.
Json tubeGenerator(const TubeDefinition& tube);

/// A bone made by a generator, optionally with a motion.
Json bone(const std::string& name, Json generator, Json motion = nullptr);

/// A tube muscle with tube fibres.
Json tubeMuscle(const std::string& name, const TubeDefinition& tube);

/// A motion rotating about `pivot` around `axis` from start to end in `step` degrees.
Json sweep(const btVector3& pivot, const btVector3& axis, double start, double end, double step);

/// A keyframed motion from rigid transforms (translations in millimetres).
Json keyframes(const std::vector<btTransform>& poses);

/// The point of `bone`'s surface nearest to the ray from its centre-line towards `target`,
/// moved `depth` into the bone: where a muscle end touching that bone should sit.
btVector3 attachPoint(const Tube& bone, const btVector3& target, double depth = 1.5);

/// A bone tube with round caps and circular sections through `points` with `radii`.
TubeDefinition boneTube(std::vector<btVector3> points, std::vector<double> radii);

/// A muscle tube (flat caps) through `points`, half-axes per point, normal axis starting near `up`.
TubeDefinition muscleTube(std::vector<btVector3> points, std::vector<std::array<double, 2>> radii,
                          const btVector3& up = btVector3(0, 0, 0));

/// The femur, pelvis and shank shapes shared by thigh13 and the hip scenes.
TubeDefinition femurTube();
TubeDefinition pelvisTube();
/// Femoral head centre: the hip joint's pivot.
inline btVector3 hipCentre() {
  return btVector3(0, 0, 0);
}

Json fusiformScene();
Json thigh13Scene();
Json hipScene(const std::string& kind);  ///< "flexion", "extension", "adduction", "rotation"
Json hipPelvisScene();
Json tensionSpikeScene();
Json pinchScene();
Json sphereDenoiseScene();
Json spherePlanesScene();
Json cylinderStretchScene();
Json cylinderTwistScene();
Json tearScene();
Json probeScene();  ///< fusiform on a bed, a probe pressing and sliding (a tool)
Json cutScene();

}  // namespace fibremss::builtin
