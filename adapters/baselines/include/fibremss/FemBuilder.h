#pragma once
// The finite-element reference built from a prepared scene: each muscle's surface
// tetrahedralized (TetMesher.h), a btSoftBody of those tetrahedra with Bullet's Neo-Hookean
// force in a btDeformableMultiBodyDynamicsWorld, nodes near the attachments pinned and moved
// with their bones, contact with the bones' true triangle meshes (own node projection between
// Bullet's substeps). It is the accuracy reference, not a speed competitor.
#include <BulletSoftBody/btSoftBody.h>
#include <LinearMath/btTransform.h>

#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "fibremss/BaselineScene.h"
#include "fibremss/Preparation.h"
#include "fibremss/TetMesher.h"

class btDeformableMultiBodyDynamicsWorld;

namespace fibremss {

/// Material and solver of the reference: Neo-Hookean, nearly incompressible (ν = 0.45).
/// Young's modulus 0 (default) matches the muscles' spring networks: springs k = κ/L0 filling
/// volume V are as stiff as E ≈ Σ κ·L0 / (3V) (exact for a cubic lattice pulled along an axis),
/// so the FEM and FibreMSS model the same material and their difference is the method's;
/// FibreMSS's default κ = 1 N gives a few hundred kPa, a contracted muscle. One E serves all
/// muscles (Bullet merges Neo-Hookean forces into the first one added).
/// Lamé μ = E/(2(1+ν)), λ = Eν/((1+ν)(1−2ν)).
struct FemDefinition {
  btScalar youngsModulus = 0;     ///< E [Pa]; 0: matched to the muscles' springs (above)
  btScalar poissonRatio = 0.45f;  ///< ν (0.5 is incompressible)
  btScalar damping = 0.001f;      ///< Neo-Hookean damping [s]: damping stress = damping × (μ, λ)
                                  ///< terms of the strain rate (0.1 s would be treacle)
  btScalar density = 1060;        ///< muscle density [kg/m³]; node mass = ρ·(adjacent volume)/4
  btScalar poseDuration = 0.07f;  ///< simulated time of one pose [s]
  /// Bullet's deformable world applies the elastic forces explicitly (only the damping is
  /// implicit), so a substep must keep ω·dt below ~2 for every node (ω² = the node's stiffness
  /// K ≈ (λ+2μ)·Σ V·|∇N|² over its tetrahedra, divided by its mass). On thigh13 (E ≈ 216 kPa,
  /// ν = 0.45) the stiffest nodes need dt ≈ 0.1 ms: at 120 voxels 50 substeps (1.4 ms) exploded
  /// in the first moving pose, 200 in pose 11. Selective mass scaling: a free node whose ω·dt
  /// passes stableOmegaDt gets the mass that brings it back (0: none); the poses are
  /// quasi-static, where mass changes only the transient. thigh13 survives all 13 poses with
  /// 80 voxels and 150 substeps (+133 % mass, FemScene::addedMassShare; ~35 s CPU) or 120 and
  /// 200 (+76 %, ~68 s CPU, past the compare budget).
  btScalar stableOmegaDt = 2;
  int substepsPerPose = 150;  ///< world steps per pose (dt = poseDuration / substeps: 0.47 ms
                              ///< per 70 ms pose)
  /// Voxels per muscle (6 tetrahedra each), chosen with substepsPerPose for the compare budget.
  TetMesherDefinition mesher{.targetCells = 80};
  /// Node contact with the bones' true triangle meshes: after every substep a node inside a
  /// bone (found within one voxel edge of its surface) or closer than contactMargin is put
  /// back at the margin and loses its velocity into the bone (frictionless). Nodes that start
  /// inside a bone (overlapping rest geometry) keep that overlap. Bullet's own SDF_RD
  /// node–face contact took minutes per pose against thigh13's bone meshes.
  bool boneContact = true;
  btScalar contactMargin = 0;  ///< [m] kept between nodes and bones (0: on the surface)
  bool muscleContact = false;  ///< VF_DD contact between muscles (boundary faces)
  /// Free nodes follow their bones each substep by FibreMSS's blended pre-transform (of their
  /// nearest particle), as in the btSoftBody baseline; without it the pinned nodes alone drag
  /// them and thigh13's first moving pose inverts tetrahedra within 7 substeps.
  bool freeNodesFollowBones = true;
  /// How free nodes blend their two bones' motions (the scene's simulation.pretransform_blend)
  PretransformBlend pretransformBlend = PretransformBlend::Linear;
  btScalar attachmentDistance = 0;  ///< nodes this close to a fixed particle are pinned to its
                                    ///< bone [m]; 0: one voxel edge
  /// At least this many nodes are pinned to each bone that fixes particles of a muscle: the
  /// nodes nearest to those particles (a coarse grid can leave an end with 2–4 pins, and it
  /// swings almost rigidly).
  int minPinsPerBone = 12;
  /// Per-pose settling (dynamic relaxation towards the pose's static equilibrium): after its
  /// substeps the bones stay and the world steps on, every free node's velocity scaled by
  /// settleDrag after each substep, until no node is faster than settleSpeed [m/s] (a
  /// thousandth of a mm per 0.5 ms substep: 2 mm/s), at most settleSubsteps more substeps (0:
  /// no settling). Without the drag Bullet's light damping lets a pose swing for seconds; with
  /// it a slow mode still creeps (fem_test: 0.35 mm in the next pose, 0.98 mm without).
  btScalar settleSpeed = 0.002f;
  int settleSubsteps = 300;
  btScalar settleDrag = 0.9f;  ///< velocity kept per settling substep (1: none)
  /// Bullet units per metre inside the reference's world (centimetres, as the btSoftBody
  /// baseline). Lengths are scaled by it, the Lamé parameters divided by it, masses and time
  /// kept, so the motion in metres is the same.
  btScalar lengthScale = 100;
};

/// The reference world: one deformable btSoftBody per muscle in a
/// btDeformableMultiBodyDynamicsWorld without gravity; the bones are their exact meshes
/// (MeshDistance) moved by their transforms, outside Bullet's world.
class FemScene : public BaselineScene {
 public:
  /// Bodies start at the poses `boneTransforms` (one per bone; rest pose when empty).
  FemScene(const PreparedScene& scene, std::span<const btTransform> boneTransforms,
           const FemDefinition& definition = {});
  ~FemScene() override;
  FemScene(const FemScene&) = delete;
  FemScene& operator=(const FemScene&) = delete;

  /// One pose: bones move to `targets` over the substeps, pinned nodes follow them.
  /// Returns false when `stop` (checked between substeps; may be empty) ended the pose early:
  /// one substep of Bullet's deformable contact can take seconds on large bones.
  bool stepPose(std::span<const btTransform> targets,
                const std::function<bool()>& stop = {}) override;

  size_t muscleCount() const override;
  size_t nodeCount() const override;          ///< nodes of all muscles
  size_t elementCount() const override;       ///< tetrahedra of all muscles
  size_t boundaryNodeCount() const override;  ///< 0: its nodes are its own mesh's
  size_t pinnedCount() const;                 ///< pinned nodes of all muscles
  /// Fewest nodes pinned to one bone of one muscle (over the bones fixing its particles).
  size_t fewestPinsPerBone() const;
  /// Poses stepped so far that did not settle within settleSubsteps.
  int unsettledPoses() const;
  /// Node positions of one muscle, as of the last step.
  std::span<const btVector3> nodePositions(size_t muscle) const override;
  /// The muscle's surface vertices, embedded in the tetrahedra (barycentric).
  void surface(size_t muscle, std::vector<btVector3>& out) const override;
  /// The muscle's tetrahedron edges and their rest lengths.
  std::vector<NodePair> nodePairs(size_t muscle) const override;
  double springDeviation() const override;  ///< NaN: not a spring model
  long iterationsPerPose() const override;  ///< world substeps per pose
  long substepsPerPose() const override;    ///< world substeps per pose
  /// "Neo-Hookean FEM, btDeformableBodySolver (…)" with its substeps, settling, added mass and
  /// pins, and the poses that did not settle.
  std::string settings() const override;
  const TetMesh& tetMesh(size_t muscle) const;  ///< rest mesh
  btSoftBody& body(size_t muscle);
  btDeformableMultiBodyDynamicsWorld& world();
  const FemDefinition& definition() const;
  double youngsModulus() const;   ///< E used for all muscles [Pa]
  double addedMassShare() const;  ///< mass added by scaling / free nodes' mass (0.1: +10 %)

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace fibremss
