#include "fibremss/MuscleAction.h"

namespace fibremss {

void MuscleAction::updateAction(btCollisionWorld*, btScalar) {
  muscles_.step();
}

void MuscleAction::debugDraw(btIDebugDraw* drawer) {
  if (drawer && debugFlags_ != 0) muscles_.debugDraw(drawer, debugFlags_);
}

}  // namespace fibremss
