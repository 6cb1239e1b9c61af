#include "fibremss/MuscleWorld.h"

#include <BulletDynamics/Dynamics/btRigidBody.h>

#include <algorithm>
#include <stdexcept>

#include "RigidCoupling.h"
#include "fibremss/Error.h"
#include "solver/MuscleSystemAccess.h"

namespace fibremss {

MuscleWorld::MuscleWorld(btDispatcher* dispatcher, btBroadphaseInterface* broadphase,
                         btConstraintSolver* solver, btCollisionConfiguration* configuration,
                         const MuscleSystemDef& def, btSoftBodySolver* softSolver)
    : btSoftRigidDynamicsWorld(dispatcher, broadphase, solver, configuration, softSolver),
      muscles_(def),
      rigid_(std::make_unique<RigidCoupling>()) {}

MuscleWorld::~MuscleWorld() = default;

BoneHandle MuscleWorld::addBone(std::shared_ptr<const BoneSettings> settings,
                                btCollisionObject* body) {
  if (!body) throw InputError("MuscleWorld::addBone", "", "a bone needs a collision object");
  const bool addHere = body->getBroadphaseHandle() == nullptr;
  BoneHandle handle = muscles_.addBone(std::move(settings), body);
  if (addHere) {
    if (btRigidBody* rigid = btRigidBody::upcast(body))
      addRigidBody(rigid);
    else
      addCollisionObject(body);
  }
  bones_.push_back({handle, body, addHere});
  return handle;
}

bool MuscleWorld::removeBone(BoneHandle bone) {
  auto it = std::find_if(bones_.begin(), bones_.end(), [&](const Bone& b) {
    return b.handle.index == bone.index && b.handle.generation == bone.generation;
  });
  if (it == bones_.end()) return false;
  const Bone removed = *it;
  bones_.erase(it);
  muscles_.removeBone(bone);
  if (removed.addedHere) removeCollisionObject(removed.body);
  return true;
}

void MuscleWorld::forgetBoneBody(const btCollisionObject* body) {
  auto it =
      std::find_if(bones_.begin(), bones_.end(), [&](const Bone& b) { return b.body == body; });
  if (it == bones_.end()) return;
  // Released even with muscles attached (Bullet's removal cannot fail): they treat it as gone.
  MuscleSystemAccess::impl(muscles_).bones.remove(it->handle);
  bones_.erase(it);
}

void MuscleWorld::setCoupling(const WorldCoupling& coupling) {
  checkCoupling(coupling, "MuscleWorld::setCoupling");
  coupling_ = coupling;
}

void MuscleWorld::removeCollisionObject(btCollisionObject* object) {
  forgetBoneBody(object);
  rigid_->forget(object, muscles_);
  btSoftRigidDynamicsWorld::removeCollisionObject(object);
}

void MuscleWorld::removeRigidBody(btRigidBody* body) {
  forgetBoneBody(body);
  rigid_->forget(body, muscles_);
  btSoftRigidDynamicsWorld::removeRigidBody(body);
}

MuscleHandle MuscleWorld::addMuscle(std::shared_ptr<const MuscleSettings> settings,
                                    std::span<const BoneHandle> bones) {
  return muscles_.addMuscle(std::move(settings), bones);
}

bool MuscleWorld::removeMuscle(MuscleHandle muscle) {
  if (!muscles_.contains(muscle)) return false;
  muscles_.removeMuscle(muscle);
  return true;
}

void MuscleWorld::internalSingleStepSimulation(btScalar timeStep) {
  btSoftRigidDynamicsWorld::internalSingleStepSimulation(timeStep);
  rigid_->step(*this, muscles_, coupling_, timeStep);
  ++muscleSteps_;
}

void MuscleWorld::debugDrawWorld() {
  btSoftRigidDynamicsWorld::debugDrawWorld();
  constexpr int kDrawModes =
      btIDebugDraw::DBG_DrawWireframe | btIDebugDraw::DBG_DrawAabb | btIDebugDraw::DBG_DrawNormals;
  btIDebugDraw* drawer = getDebugDrawer();
  if (drawer && (drawer->getDebugMode() & kDrawModes) && muscleDebugFlags_ != 0)
    muscles_.debugDraw(drawer, muscleDebugFlags_);
}

}  // namespace fibremss
