#pragma once
// The rigid pre-transform of one particle (method.md §4): the blend of its two bones'
// transforms (MuscleSettings::blendBoneA/B/Weight; linear or by dual quaternions,
// PretransformBlend) or, as in the thesis, its nearest bone's. The solver applies it before
// each step; baselines built from the same settings (the btSoftBody and FEM builders) move their
// nodes with it.
#include <LinearMath/btTransform.h>

#include <span>

#include "fibremss/MuscleSettings.h"
#include "fibremss/Parameters.h"

namespace fibremss {

/// A rigid motion as a unit dual quaternion.
struct DualQuaternion {
  btQuaternion real;  ///< the rotation
  btQuaternion dual;  ///< ½·(0, t)·real, t the translation [m]
};

/// The dual quaternion of `t`; of the identity for null.
inline DualQuaternion dualQuaternionOf(const btTransform* t) {
  if (!t) return {btQuaternion::getIdentity(), btQuaternion(0, 0, 0, 0)};
  const btQuaternion real = t->getRotation();
  const btVector3& o = t->getOrigin();
  return {real, btQuaternion(o.x(), o.y(), o.z(), 0) * real * btScalar(0.5)};
}

/// A rigid motion as a rotation about the origin, then a translation.
struct RigidMotion {
  btQuaternion rotation;  ///< unit quaternion
  btVector3 translation;  ///< [m]
};

/// The motion of (1−w)·a + w·b normalised (b taken with the sign nearer a): dual-quaternion
/// blending, rigid for every w. Identities give the identity exactly (zero vector parts).
inline RigidMotion blendDualQuaternions(const DualQuaternion& a, const DualQuaternion& b,
                                        btScalar w) {
  const btScalar shareB = a.real.dot(b.real) < 0 ? -w : w;
  const btQuaternion real = a.real * (1 - w) + b.real * shareB;
  const btQuaternion dual = a.dual * (1 - w) + b.dual * shareB;
  const btScalar length = real.length();
  const btQuaternion unit(real.x() / length, real.y() / length, real.z() / length,
                          real.w() / length);
  const btQuaternion scaledDual(dual.x() / length, dual.y() / length, dual.z() / length,
                                dual.w() / length);
  const btQuaternion t = scaledDual * unit.inverse();  // the inverse of a unit one: conjugate
  return {unit, btVector3(t.x(), t.y(), t.z()) * btScalar(2)};
}

/// `d` turned by the unit quaternion q: d + 2·v×(v×d + s·d) (v, s: q's vector and scalar parts),
/// so that a rotation with a zero vector part leaves d bit for bit unchanged.
inline btVector3 rotateByQuaternion(const btQuaternion& q, const btVector3& d) {
  const btVector3 v(q.x(), q.y(), q.z());
  return d + v.cross(v.cross(d) + d * q.w()) * btScalar(2);
}

/// `p` moved by `motion`, as displacements (the identity leaves p bit for bit unchanged).
inline btVector3 moveRigidly(const RigidMotion& motion, const btVector3& p) {
  return rotateByQuaternion(motion.rotation, p) + motion.translation;
}

/// transforms[bone] (a btTransform or a DualQuaternion), or null for no bone / a bone beyond
/// them (the identity).
template <class Transforms>
inline auto boneTransformOf(const Transforms& transforms, int32_t bone)
    -> decltype(transforms.data()) {
  return bone >= 0 && static_cast<size_t>(bone) < transforms.size() ? &transforms[bone] : nullptr;
}

/// Whether particle i's pre-transform is a dual-quaternion blend of two motions: blended
/// settings with that rule and a weight strictly between 0 and 1 (at 0 and 1 both rules take
/// one bone's motion, by the linear form).
inline bool blendsDualQuaternions(const MuscleSettings& settings, uint32_t i,
                                  PretransformBlend blend) {
  return blend == PretransformBlend::DualQuaternion && settings.blendWeight[i] > 0 &&
         settings.blendWeight[i] < 1;
}

/// Particle i's dual-quaternion blend of its bones' motions `transforms` (null or beyond the
/// span: the identity).
inline RigidMotion dualQuaternionBlend(const MuscleSettings& settings,
                                       std::span<const btTransform> transforms, uint32_t i) {
  return blendDualQuaternions(dualQuaternionOf(boneTransformOf(transforms, settings.blendBoneA[i])),
                              dualQuaternionOf(boneTransformOf(transforms, settings.blendBoneB[i])),
                              settings.blendWeight[i]);
}

/// Particle i's rigid transform applied to `point`: with the settings' blend when `blended` and
/// the settings have one, p + (1−w)·(T_A·p − p) + w·(T_B·p − p) (PretransformBlend::Linear) or
/// the dual-quaternion blend of T_A and T_B, else T_nearest·p. Written as displacements so that
/// identity transforms leave the point bit for bit unchanged. `transforms[b]` belongs to the
/// settings' bone index b.
inline btVector3 pretransformPoint(const MuscleSettings& settings,
                                   std::span<const btTransform> transforms, uint32_t i,
                                   const btVector3& point, bool blended, PretransformBlend blend) {
  if (!blended || settings.blendWeight.empty()) {
    const btTransform* nearest = boneTransformOf(transforms, settings.nearestBone[i]);
    return nearest ? *nearest * point : point;
  }
  if (blendsDualQuaternions(settings, i, blend))
    return moveRigidly(dualQuaternionBlend(settings, transforms, i), point);
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
                                       const btVector3& direction, bool blended,
                                       PretransformBlend blend) {
  if (!blended || settings.blendWeight.empty()) {
    const btTransform* nearest = boneTransformOf(transforms, settings.nearestBone[i]);
    return nearest ? nearest->getBasis() * direction : direction;
  }
  if (blendsDualQuaternions(settings, i, blend))
    return rotateByQuaternion(dualQuaternionBlend(settings, transforms, i).rotation, direction);
  const btScalar w = settings.blendWeight[i];
  const btTransform* a = boneTransformOf(transforms, settings.blendBoneA[i]);
  const btTransform* b = boneTransformOf(transforms, settings.blendBoneB[i]);
  btVector3 turned = direction;
  if (a && w < 1) turned += (a->getBasis() * direction - direction) * (1 - w);
  if (b && w > 0) turned += (b->getBasis() * direction - direction) * w;
  return turned;
}

}  // namespace fibremss
