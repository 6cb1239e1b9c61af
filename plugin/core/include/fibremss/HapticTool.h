#pragma once
// A tool in the hand at haptic rate: a kinematic Bullet body (a probe a device or a script poses
// every tick) whose interaction with the muscles runs at the device's rate, 1 kHz by default,
// while the rest of a scene (the bones' motion, drawing) may step slower. Each tick moves the
// tool to its new pose, advances the muscles by the tick's duration with the tool sweeping from
// its last pose to the new one (MuscleSystem::step(duration), a time integrator such as Verlet),
// and reads the tool's force with MuscleSystem::contactWrench at the new pose: the tick's mean
// reaction (the momentum the touching particles lost to the tool over the tick) plus the Hooke
// term of what still overlaps. With HapticRegion::wholeEvery > 1 most ticks step only the
// muscles' particles near the tool (MuscleSystem::stepLocal, Verlet), the whole muscles every
// wholeEvery-th tick. With a time integrator the far field then advances wholeEvery times
// slower than the tool (docs/contact.md, "Local ticks"); with the projective solver a whole tick
// settles the whole muscles towards their static equilibrium with the tool at its new pose (the
// system's iterations per step), a far field that keeps up with a slow tool, and a local tick
// follows it, whose force the tick returns (docs/contact.md, "A quasi-static far field").
#include <BulletDynamics/Dynamics/btRigidBody.h>
#include <LinearMath/btTransform.h>

#include "fibremss/MuscleSystem.h"
#include "fibremss/RigidContact.h"

namespace fibremss {

/// Which particles a HapticTool's ticks move.
struct HapticRegion {
  /// Every wholeEvery-th tick (the first, then every wholeEvery) steps the whole muscles
  /// (MuscleSystem::step(duration); with the projective solver followed by a local step); the
  /// ticks between step only the region around the tool (MuscleSystem::stepLocal). 1: every
  /// tick whole [ticks].
  int wholeEvery = 1;
  /// The region holds the free particles within the tool's bounding sphere grown by this [m].
  btScalar margin = btScalar(0.01);
  /// The region is gathered again before a local tick once the tool's centre is farther than this
  /// from where it was gathered [m]; less than margin by more than the particles' radii, so that
  /// what the tool touches stays inside.
  btScalar drift = btScalar(0.002);
};

class HapticTool {
 public:
  /// `tool`: a kinematic btRigidBody (mass 0, CF_KINEMATIC_OBJECT) whose shape touches the
  /// muscles (ShapeContact's convex shapes); `tickTime`: the simulated time of a tick [s]. Makes
  /// the tool the system's only contact body (allocates; a tick does not). Both must outlive
  /// the tool; `region`: which particles the ticks move. InputError for a body that is not
  /// kinematic, a tick time not finite > 0, wholeEvery < 1, or a drift not in [0, margin).
  HapticTool(MuscleSystem& system, btRigidBody& tool, btScalar tickTime = btScalar(1e-3),
             const HapticRegion& region = {});

  /// One tick: the tool moves to `pose` over the tick (its velocity the pose change / tickTime),
  /// the muscles (the whole, or the region around the tool) advance by tickTime with it, and the
  /// force and torque they exert on the tool at `pose` are returned. No allocation (but the first
  /// local tick's gathering). InputError for a pose with NaN or inf.
  ContactWrench tick(const btTransform& pose);

  btScalar tickTime() const { return tickTime_; }  ///< simulated time per tick [s]
  long ticks() const { return ticks_; }            ///< ticks taken
  long wholeTicks() const { return wholeTicks_; }  ///< ticks that stepped the whole muscles
  /// Solver iterations of the ticks taken: the whole steps' and the local steps' (a whole tick of
  /// the quasi-static solver runs both).
  long iterations() const { return iterations_; }
  const btRigidBody& tool() const { return tool_; }

 private:
  MuscleSystem& system_;  ///< the muscles the tool touches
  btRigidBody& tool_;     ///< the kinematic tool body
  btScalar tickTime_;     ///< simulated time per tick [s]
  HapticRegion region_;   ///< which particles the ticks move
  /// The system's solver is the quasi-static one (projective): its whole ticks settle the far
  /// field and each is followed by a local tick.
  bool quasiStatic_;
  long ticks_ = 0;                   ///< ticks taken
  long wholeTicks_ = 0;              ///< ticks that stepped the whole muscles
  long iterations_ = 0;              ///< solver iterations of the ticks taken
  btVector3 regionCentre_{0, 0, 0};  ///< the tool's centre where the region was gathered [m]
  bool gathered_ = false;            ///< a region was gathered
  /// Steps the muscles by a tick: whole, or the region around the tool at `pose`.
  void advance(const btTransform& pose);
};

}  // namespace fibremss
