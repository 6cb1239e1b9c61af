#include "MuscleState.h"

#include <utility>

namespace fibremss {

void ParticleState::init(const MuscleSettings& settings, std::span<const BoneHandle> handles) {
  const size_t n = settings.particleCount();
  bones.assign(handles.begin(), handles.end());
  boneSlots.assign(handles.size(), -1);
  boneTransforms.assign(handles.size(), btTransform::getIdentity());
  boneDeltas.assign(handles.size(), btTransform::getIdentity());
  boneDualDeltas.assign(handles.size(), dualQuaternionOf(nullptr));
  positions.resize(n);
  previous.resize(n);
  velocities.assign(n, btVector3(0, 0, 0));
  forces.assign(n, btVector3(0, 0, 0));
  for (uint32_t i = 0; i < n; ++i)
    if (!settings.isFixed(i)) freeParticles.push_back(i);
}

void ContactState::init(size_t n, bool meshContact, bool recovery) {
  pushes.assign(n, btVector3(0, 0, 0));
  pushCounts.assign(n, 0);
  pushedLast.assign(n, 0);
  pinchBones.assign(n, -1);
  stepBones.assign(n, -1);
  firstBonePushes.assign(n, btVector3(0, 0, 0));
  otherBonePushes.assign(n, btVector3(0, 0, 0));
  if (meshContact) meshVisits.assign(n, 0);
  if (recovery) {
    sideBones.assign(n, -1);
    boneSides.assign(n, btVector3(0, 0, 0));
    sideStamps.assign(n, 0);
  }
}

void GuardSnapshot::init(size_t n) {
  goodPositions.resize(n);
  goodPrevious.resize(n);
  goodVelocities.resize(n);
}

void ResidualState::init(size_t n, std::vector<btScalar> stiffness) {
  lastPushes.assign(n, btVector3(0, 0, 0));
  pushRounds.assign(n, 0);
  lastBonePushes.assign(n, btVector3(0, 0, 0));
  residual.assign(n, btVector3(0, 0, 0));
  residualStiffness = std::move(stiffness);
}

}  // namespace fibremss
