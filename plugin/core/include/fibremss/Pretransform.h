#pragma once
// The rigid pre-transform of one particle (method.md §4): the blend of its two bones'
// transforms (MuscleSettings::blendBoneA/B/Weight) or, as in the thesis, its nearest bone's.
// The solver applies it before each step; baselines built from the same settings (the
// btSoftBody and FEM builders) move their nodes with it.
#include <LinearMath/btTransform.h>

#include <span>

#include "fibremss/MuscleSettings.h"

namespace fibremss {

/// transforms[bone], or null for no bone / a bone beyond the span (the identity).
inline const btTransform* boneTransformOf(std::span<const btTransform> transforms, int32_t bone) {
  return bone >= 0 && static_cast<size_t>(bone) < transforms.size() ? &transforms[bone] : nullptr;
}

/// Particle i's rigid transform applied to `point`: p + (1−w)·(T_A·p − p) + w·(T_B·p − p) with
/// the settings' blend when `blended` and the settings have one, else T_nearest·p. Written as
/// displacements so that identity transforms leave the point bit for bit unchanged.
/// `transforms[b]` belongs to the settings' bone index b.
inline btVector3 pretransformPoint(const MuscleSettings& settings,
                                   std::span<const btTransform> transforms, uint32_t i,
                                   const btVector3& point, bool blended) {
  if (!blended || settings.blendWeight.empty()) {
    const btTransform* nearest = boneTransformOf(transforms, settings.nearestBone[i]);
    return nearest ? *nearest * point : point;
  }
  const btScalar w = settings.blendWeight[i];
  const btTransform* a = boneTransformOf(transforms, settings.blendBoneA[i]);
  const btTransform* b = boneTransformOf(transforms, settings.blendBoneB[i]);
  btVector3 moved = point;
  if (a && w < 1) moved += (*a * point - point) * (1 - w);
  if (b && w > 0) moved += (*b * point - point) * w;
  return moved;
}

/// The rotation part of the same blend applied to a direction (velocities).
inline btVector3 pretransformDirection(const MuscleSettings& settings,
                                       std::span<const btTransform> transforms, uint32_t i,
                                       const btVector3& direction, bool blended) {
  if (!blended || settings.blendWeight.empty()) {
    const btTransform* nearest = boneTransformOf(transforms, settings.nearestBone[i]);
    return nearest ? nearest->getBasis() * direction : direction;
  }
  const btScalar w = settings.blendWeight[i];
  const btTransform* a = boneTransformOf(transforms, settings.blendBoneA[i]);
  const btTransform* b = boneTransformOf(transforms, settings.blendBoneB[i]);
  btVector3 turned = direction;
  if (a && w < 1) turned += (a->getBasis() * direction - direction) * (1 - w);
  if (b && w > 0) turned += (b->getBasis() * direction - direction) * w;
  return turned;
}

}  // namespace fibremss
