#pragma once
// The pointer as a tool in a scene stepped live (ToolMode): it grabs the free muscle particle
// nearest its ray and pulls it towards the pointer along the view plane (a spring of the
// particle's stiffness, an external force), or drives a probe, a kinematic sphere the muscles
// collide with (two-way contact), along the view plane; the probe's force is the world's
// contactWrench; or drives a blade, an edge along the view direction through the pointer, along
// the view plane: it cuts the muscles' springs it sweeps across. Each mode is one branch of
// apply().
#include <BulletCollision/CollisionShapes/btSphereShape.h>
#include <BulletDynamics/Dynamics/btRigidBody.h>

#include <memory>
#include <vector>

#include "ViewFrame.h"
#include "fibremss/MuscleWorld.h"
#include "fibremss/viewer/Viewer.h"

namespace fibremss::viewer {

/// The pointer as the window hands it to the scene [m].
struct PointerRay {
  btVector3 origin{0, 0, 0};      ///< the eye
  btVector3 direction{0, 0, -1};  ///< through the pointer, unit length
  btVector3 planePoint{0, 0, 0};  ///< on the view plane a probe starts in (the camera's target)
  bool held = false;              ///< the left button is down
  bool operator==(const PointerRay&) const = default;
};

/// What the tool does now, for the panel.
struct ToolReading {
  ToolMode mode = ToolMode::Camera;  ///< the pointer's mode
  bool engaged = false;              ///< a particle is held, or the probe is in the scene
  btVector3 force{0, 0, 0};          ///< the muscles' force on the probe, or the grab's pull [N]
  size_t contacts = 0;               ///< particle spheres overlapping the probe
  size_t cutSprings = 0;             ///< springs blades have cut in the muscles so far
};

/// "camera", "grab", "probe" or "blade".
const char* toolName(ToolMode mode);
/// The mode after `mode` (camera, grab, probe, blade, camera, ...: the T key).
ToolMode nextTool(ToolMode mode);

class PointerTools {
 public:
  /// Tools for the muscles of `world`; the probe is a sphere of `probeRadius` [m].
  PointerTools(MuscleWorld& world, btScalar probeRadius);
  ~PointerTools();  ///< takes the probe out of the world
  PointerTools(const PointerTools&) = delete;
  PointerTools& operator=(const PointerTools&) = delete;

  /// The muscles a grab picks from (the world's, again after a reset); lets go of a particle.
  void setMuscles(std::vector<MuscleHandle> muscles);
  /// Applies the pointer in `mode` before a step: presses, drags and releases.
  void apply(ToolMode mode, const PointerRay& ray);
  /// The tool's mode, force and contacts as of the last step.
  ToolReading reading() const;
  /// The probe's mesh where it is, or null when it is not in the scene.
  const ViewMesh* probeMesh() const { return probeInWorld_ ? &probeMesh_ : nullptr; }

 private:
  void press(const PointerRay& ray);               ///< the button went down
  void drag(const btVector3& target);              ///< the pointer moved with it down
  void release();                                  ///< lets go of a grabbed particle
  void removeProbe();                              ///< takes the probe out of the world
  btVector3 onPlane(const PointerRay& ray) const;  ///< the ray's point on the drag plane [m]

  MuscleWorld& world_;
  std::vector<MuscleHandle> muscles_;   ///< the muscles a grab picks from
  btSphereShape probeShape_;            ///< the probe's sphere
  std::unique_ptr<btRigidBody> probe_;  ///< kinematic; in the world once placed
  ViewMesh probeMesh_;                  ///< its mesh, placed by its transform
  bool probeInWorld_ = false;           ///< the probe is in the world
  ToolMode mode_ = ToolMode::Camera;    ///< the mode of the last apply
  bool held_ = false;                   ///< the button was down at the last apply
  btVector3 planePoint_{0, 0, 0};       ///< the drag plane: through this point [m] ...
  btVector3 planeNormal_{0, 0, 1};      ///< ... along the view direction
  MuscleHandle grabbed_;                ///< the grabbed particle's muscle (invalid: none)
  uint32_t grabbedParticle_ = 0;        ///< its index
  btScalar grabStiffness_ = 0;          ///< the pull per metre: Σ k of its springs [N/m]
  btVector3 pull_{0, 0, 0};             ///< the grab's pull on the particle [N]
  BladeHandle blade_;                   ///< the blade of the last press (invalid: none yet)
};

}  // namespace fibremss::viewer
