#include "fibremss/HapticTool.h"

#include <BulletCollision/CollisionShapes/btCollisionShape.h>
#include <LinearMath/btTransformUtil.h>

#include <cmath>
#include <string>

#include "fibremss/Error.h"

namespace fibremss {

HapticTool::HapticTool(MuscleSystem& system, btRigidBody& tool, btScalar tickTime,
                       const HapticRegion& region)
    : system_(system),
      tool_(tool),
      tickTime_(tickTime),
      region_(region),
      quasiStatic_(system.definition().integrator == Integrator::Projective) {
  if (!tool.isKinematicObject())
    throw InputError(
        "HapticTool", "tool",
        "expected a kinematic body (mass 0, CF_KINEMATIC_OBJECT): the device poses it");
  if (!(tickTime > 0) || !std::isfinite(tickTime))
    throw InputError("HapticTool", "tickTime",
                     "expected a finite time > 0 s, got " + std::to_string(tickTime));
  if (region.wholeEvery < 1)
    throw InputError("HapticTool", "region.wholeEvery",
                     "expected at least 1 tick, got " + std::to_string(region.wholeEvery));
  if (!(region.drift >= 0) || !(region.drift < region.margin) || !std::isfinite(region.margin))
    throw InputError("HapticTool", "region.drift",
                     "expected a drift in [0, margin) and a finite margin [m], got drift " +
                         std::to_string(region.drift) + ", margin " +
                         std::to_string(region.margin));
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
  advance(pose);
  ++ticks_;
  return system_.contactWrench(tool_, pose);
}

void HapticTool::advance(const btTransform& pose) {
  const bool whole = ticks_ % region_.wholeEvery == 0;
  if (whole) {
    system_.step(tickTime_);
    ++wholeTicks_;
    iterations_ += system_.lastStep().iterations;
  }
  // A whole tick of the quasi-static solver settles the far field; a local tick follows it.
  if (whole && !quasiStatic_) return;
  btVector3 centre;
  btScalar radius;
  tool_.getCollisionShape()->getBoundingSphere(centre, radius);
  centre = pose * centre;
  if (!gathered_ || centre.distance(regionCentre_) > region_.drift) {
    system_.setLocalRegion(centre, radius + region_.margin);
    regionCentre_ = centre;
    gathered_ = true;
  }
  system_.stepLocal(tickTime_);
  iterations_ += system_.lastStep().iterations;
}

}  // namespace fibremss
