#include "fibremss/HapticTool.h"

#include <LinearMath/btTransformUtil.h>

#include <cmath>
#include <string>

#include "fibremss/Error.h"

namespace fibremss {

HapticTool::HapticTool(MuscleSystem& system, btRigidBody& tool, btScalar tickTime)
    : system_(system), tool_(tool), tickTime_(tickTime) {
  if (!tool.isKinematicObject())
    throw InputError(
        "HapticTool", "tool",
        "expected a kinematic body (mass 0, CF_KINEMATIC_OBJECT): the device poses it");
  if (!(tickTime > 0) || !std::isfinite(tickTime))
    throw InputError("HapticTool", "tickTime",
                     "expected a finite time > 0 s, got " + std::to_string(tickTime));
  const btCollisionObject* bodies[] = {&tool};
  system_.setContactBodies(bodies);
}

ContactWrench HapticTool::tick(const btTransform& pose) {
  const btTransform from = tool_.getWorldTransform();
  btVector3 linear, angular;
  btTransformUtil::calculateVelocity(from, pose, tickTime_, linear, angular);
  if (!std::isfinite(linear.length2()) || !std::isfinite(angular.length2()))
    throw InputError("HapticTool::tick", "pose",
                     "expected a finite transform (the tool's pose has NaN or inf)");
  tool_.setWorldTransform(pose);
  tool_.setInterpolationWorldTransform(pose);
  tool_.setLinearVelocity(linear);
  tool_.setAngularVelocity(angular);
  system_.step(tickTime_);
  ++ticks_;
  return system_.contactWrench(tool_, pose);
}

}  // namespace fibremss
