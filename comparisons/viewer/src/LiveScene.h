#pragma once
// A scene stepped live for the viewer: loaded and prepared as `fibremss run` does, its bones
// kinematic BoneBody objects in a MuscleWorld (so Bullet's debugDrawWorld draws the muscles),
// one world step per viewer step with the bones at the current pose of the motion.
#include <BulletCollision/BroadphaseCollision/btDbvtBroadphase.h>
#include <BulletDynamics/ConstraintSolver/btSequentialImpulseConstraintSolver.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>

#include <memory>
#include <string>
#include <vector>

#include "PointerTools.h"
#include "ViewFrame.h"
#include "fibremss/BoneBody.h"
#include "fibremss/MuscleWorld.h"
#include "fibremss/Scene.h"

namespace fibremss::viewer {

class LiveScene {
 public:
  /// Loads (built-in name or .json path, with key=value overrides) and prepares the scene;
  /// warnings go to stderr. Throws InputError for bad input.
  LiveScene(const std::string& scene, const std::vector<std::string>& overrides);
  ~LiveScene();
  LiveScene(const LiveScene&) = delete;
  LiveScene& operator=(const LiveScene&) = delete;

  /// One step with the bones at pose(), then the pose advances along the motion (held at
  /// the last pose, or swept back and forth when loop is set).
  void step();
  /// Back to the start: bones at the first pose, muscles at rest, no steps taken.
  void reset();
  /// Puts the bones' target at pose `pose` (clamped to the motion), for the next step.
  void setPose(int pose);
  /// The pointer as a tool (grab, probe) before the next step; the frame shows the probe.
  void applyPointer(ToolMode mode, const PointerRay& ray);
  /// The pointer tool's force and contacts as of the last step.
  ToolReading toolReading() const { return tools_->reading(); }

  const LoadedScene& scene() const { return scene_; }
  int pose() const { return pose_; }            ///< the pose the next step moves the bones to
  int shownPose() const { return shownPose_; }  ///< the pose the last step moved them to
  int steps() const { return steps_; }          ///< steps taken
  bool loop = false;  ///< past the last pose, sweep back (and forth again)

  MuscleWorld& world() { return *world_; }
  const StepStats& lastStep() const { return world_->muscleSystem().lastStep(); }
  /// The muscles' surfaces ("muscle_id", "fibre_stretch", "displacement") and the bones, as
  /// of the last step.
  const ViewFrame& frame() const { return frame_; }

 private:
  void updateFrame();

  LoadedScene scene_;
  PreparedScene prepared_;
  btSoftBodyRigidBodyCollisionConfiguration configuration_;
  std::unique_ptr<btCollisionDispatcher> dispatcher_;
  btDbvtBroadphase broadphase_;
  btSequentialImpulseConstraintSolver solver_;
  std::unique_ptr<MuscleWorld> world_;
  std::vector<std::unique_ptr<BoneBody>> boneBodies_;  ///< one per scene bone
  std::vector<BoneHandle> bones_;                      ///< the same, in the world
  std::vector<MuscleHandle> muscles_;                  ///< one per scene muscle
  std::unique_ptr<PointerTools> tools_;                ///< the pointer's grab and probe
  std::vector<std::vector<float>> particleStretch_;    ///< per muscle, per particle (scratch)
  std::vector<std::vector<float>> fibreSegments_;      ///< per muscle: segments per particle
  ViewFrame frame_;
  int pose_ = 0;       ///< the next step's pose
  int shownPose_ = 0;  ///< the last step's pose (0 before the first)
  int direction_ = 1;  ///< +1 forth, -1 back (loop)
  int steps_ = 0;      ///< steps taken
};

}  // namespace fibremss::viewer
