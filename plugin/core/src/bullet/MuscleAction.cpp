#include "fibremss/MuscleAction.h"

#include <BulletCollision/CollisionDispatch/btCollisionWorld.h>

#include "RigidCoupling.h"

namespace fibremss {

MuscleAction::MuscleAction(const MuscleSystemDef& def)
    : muscles_(def), rigid_(std::make_unique<RigidCoupling>()) {}

MuscleAction::~MuscleAction() = default;

void MuscleAction::updateAction(btCollisionWorld* world, btScalar timeStep) {
  rigid_->step(*world, muscles_, coupling_, timeStep);
}

void MuscleAction::setCoupling(const WorldCoupling& coupling) {
  checkCoupling(coupling, "MuscleAction::setCoupling");
  coupling_ = coupling;
}

void MuscleAction::forgetBody(const btCollisionObject* body) {
  rigid_->forget(body, muscles_);
}

void MuscleAction::debugDraw(btIDebugDraw* drawer) {
  if (drawer && debugFlags_ != 0) muscles_.debugDraw(drawer, debugFlags_);
}

}  // namespace fibremss
