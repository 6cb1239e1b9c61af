// Rigid-motion checks over the whole scene JSON: bones move rigidly, so a transform that
// scales or shears is refused with the field named instead of being silently made rigid.
#include "SceneValidation.h"

#include <cmath>
#include <sstream>

#include "fibremss/Error.h"

namespace fibremss::scene {
namespace {

/// Keys that would make a transform non-rigid; none is a scene field.
constexpr const char* kNonRigidKeys[] = {"scale", "shear", "matrix"};

/// A quaternion may deviate this much from unit length (rounding in files written by hand).
constexpr double kUnitTolerance = 1e-3;

void validateTransform(const Json& transform, const std::string& path, const std::string& source) {
  for (const char* key : kNonRigidKeys)
    if (transform.contains(key))
      throw InputError(source, path + "." + key,
                       "bones move rigidly: a transform has a translation and a rotation only "
                       "(scale meshes with \"units\", not with a transform)");
  const auto q = transform.find("quaternion");
  if (q == transform.end() || !q->is_array() || q->size() != 4) return;
  double norm2 = 0;
  for (const Json& component : *q) {
    if (!component.is_number()) return;  // the field reader names wrong types
    norm2 += component.get<double>() * component.get<double>();
  }
  const double norm = std::sqrt(norm2);
  if (std::abs(norm - 1) > kUnitTolerance) {
    std::ostringstream what;
    what << "expected a unit quaternion [x, y, z, w] (a rotation), got length " << norm
         << ": a scaled transform is not rigid";
    throw InputError(source, path + ".quaternion", what.str());
  }
}

void validateBone(const Json& bone, const std::string& path, const std::string& source) {
  if (!bone.is_object()) return;
  if (const auto transform = bone.find("transform");
      transform != bone.end() && transform->is_object())
    validateTransform(*transform, path + ".transform", source);
  const auto motion = bone.find("motion");
  if (motion == bone.end() || !motion->is_object()) return;
  const auto keyframes = motion->find("keyframes");
  if (keyframes == motion->end() || !keyframes->is_array()) return;
  for (size_t k = 0; k < keyframes->size(); ++k)
    if ((*keyframes)[k].is_object())
      validateTransform((*keyframes)[k], path + ".motion.keyframes[" + std::to_string(k) + "]",
                        source);
}

}  // namespace

void validateSceneJson(const Json& raw, const std::string& source) {
  if (!raw.is_object()) return;  // the field reader says what was expected
  const auto bones = raw.find("bones");
  if (bones == raw.end() || !bones->is_array()) return;
  for (size_t b = 0; b < bones->size(); ++b)
    validateBone((*bones)[b], "bones[" + std::to_string(b) + "]", source);
}

}  // namespace fibremss::scene
