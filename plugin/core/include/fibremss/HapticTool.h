#pragma once
// A tool in the hand at haptic rate: a kinematic Bullet body (a probe a device or a script poses
// every tick) whose interaction with the muscles runs at the device's rate, 1 kHz by default,
// while the rest of a scene (the bones' motion, drawing) may step slower. Each tick moves the
// tool to its new pose, advances the muscles by the tick's duration with the tool sweeping from
// its last pose to the new one (MuscleSystem::step(duration), a time integrator such as Verlet),
// and reads the tool's force with MuscleSystem::contactWrench at the new pose: the tick's mean
// reaction (the momentum the touching particles lost to the tool over the tick) plus the Hooke
// term of what still overlaps. The muscles move every tick, so the force follows the tool as
// it presses and slides (docs/contact.md, "A tool at haptic rate").
#include <BulletDynamics/Dynamics/btRigidBody.h>
#include <LinearMath/btTransform.h>

#include "fibremss/MuscleSystem.h"
#include "fibremss/RigidContact.h"

namespace fibremss {

class HapticTool {
 public:
  /// `tool`: a kinematic btRigidBody (mass 0, CF_KINEMATIC_OBJECT) whose shape touches the
  /// muscles (ShapeContact's convex shapes); `tickTime`: the simulated time of a tick [s]. Makes
  /// the tool the system's only contact body (allocates; a tick does not). Both must outlive
  /// the tool. InputError for a body that is not kinematic or a tick time not finite > 0.
  HapticTool(MuscleSystem& system, btRigidBody& tool, btScalar tickTime = btScalar(1e-3));

  /// One tick: the tool moves to `pose` over the tick (its velocity the pose change / tickTime),
  /// the muscles advance by tickTime with it, and the force and torque they exert on the tool at
  /// `pose` are returned. No allocation. InputError for a pose with NaN or inf.
  ContactWrench tick(const btTransform& pose);

  btScalar tickTime() const { return tickTime_; }  ///< simulated time per tick [s]
  long ticks() const { return ticks_; }            ///< ticks taken
  const btRigidBody& tool() const { return tool_; }

 private:
  MuscleSystem& system_;  ///< the muscles the tool touches
  btRigidBody& tool_;     ///< the kinematic tool body
  btScalar tickTime_;     ///< simulated time per tick [s]
  long ticks_ = 0;        ///< ticks taken
};

}  // namespace fibremss
