#pragma once
// The btSoftBody baseline built from a prepared scene: the same particles as nodes (same
// masses), the same springs as links, fixed particles pinned and moved with their bones,
// kinematic bone bodies with their true triangle meshes, soft–soft collision by clusters.
#include <BulletSoftBody/btSoftBody.h>
#include <LinearMath/btTransform.h>

#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "fibremss/BaselineScene.h"
#include "fibremss/MuscleSettings.h"
#include "fibremss/Preparation.h"

class btSoftRigidDynamicsWorld;

namespace fibremss {

/// How the baseline is built and stepped.
///
/// Stiffness mapping: a FibreMSS spring k = κ/L0 between two particles of mass m removes, in
/// one explicit step of dt, the fraction f = min(1, 2·k·dt²/m) of its length error (reduced
/// mass m/2). btSoftBody's position solver applies m_kLST = s of the error per iteration, so
/// after n = positionIterations iterations (1−s)ⁿ of it is left: s = 1 − (1 − f)^(1/n).
/// Links are grouped into `stiffnessLevels` materials (s rounded to the level's centre).
/// At thigh13's substeps every link saturates (f = 200–10 000: m_kLST = 1 for all), so Bullet
/// weighs a 0.08 mm link like a 3 mm one; links are solved from the softest to the stiffest
/// spring so that the stiffest end each Gauss–Seidel sweep satisfied (SoftBodyBuilder.cpp).
/// Damping: btSoftBody's kDP removes that fraction of node velocity per step. FibreMSS's c·dt/m
/// came to 6–26 on thigh13 before clamping to 1: it zeroed every node's velocity each step.
/// Free nodes follow their bones each substep by FibreMSS's blended pre-transform; without it
/// the links alone dragged them through the bones' motion (thigh13 resolution 20, pose 0→1:
/// 16 links beyond 3×, one at 18×).
/// Collision margin of a muscle: the mean radius of its spheres, at most half its rest gap to
/// the nearest other muscle, so that muscles touching at rest are not pushed apart.
struct SoftBodyDefinition {
  int substepsPerPose = 0;           ///< world steps per pose (bones and pins interpolated);
                                     ///< 0: substepsFor(scene)
  btScalar poseDuration = 0.07f;     ///< simulated time of one pose [s]
  int positionIterations = 0;        ///< m_cfg.piterations (links, per world step);
                                     ///< 0: iterationsFor(scene)
  int clusterIterations = 2;         ///< m_cfg.citerations (cluster contacts, per world step)
  btScalar velocityDamping = 0.1f;   ///< m_cfg.kDP: share of node velocity removed per step
  bool freeNodesFollowBones = true;  ///< move free nodes by their bones' motion each substep
  /// How free nodes blend their two bones' motions (the scene's simulation.pretransform_blend)
  PretransformBlend pretransformBlend = PretransformBlend::Linear;
  int clustersPerMuscle = 48;     ///< free-node clusters for CL_SS (k-means by position); 48
                                  ///< vs 24: thigh13 R=20 rest links 1.12× vs 1.55×, same cost
  bool softSoftCollision = true;  ///< CL_SS between muscles (no self-collision)
  bool boneCollision = true;      ///< SDF_RS against the bones' triangle meshes
  int stiffnessLevels = 16;       ///< distinct link materials per muscle
  btScalar sdfVoxelSize =
      0.003f;  ///< btSparseSdf voxel edge [m] (Bullet's 0.25 is for metres-sized toys)
  /// Bullet units per metre inside the baseline's world. Bullet extrudes every bone triangle
  /// into a slab ±0.06 units thick for soft–mesh collision (btSoftBodyConcaveCollisionAlgorithm,
  /// hard-coded): in metres that is ±60 mm and pushes every node near a bone; in centimetres
  /// (100) it is ±0.6 mm. Inputs and outputs stay in metres.
  btScalar lengthScale = 100;
};

/// The baseline's default world steps per pose: the most particles on one fibre of the scene
/// (its resolution) / 4, rounded up, so that a substep moves the bones by the same share of
/// the particle spacing at every resolution.
/// Chosen as the cheapest measured counts with which thigh13 (13 poses, collisions on) runs
/// every pose with each link within [1/3, 3]× its rest length and its surface at most 1 mm
/// inside a bone, at resolutions 20 and 40: 5 substeps × 8 iterations at 20 (links within
/// 0.50–1.53×, 0.66 mm; 3 substeps or fewer fold a link below 0.11×, 4 iterations leave
/// 1.49 mm), 10 × 16 at 40 (0.60–1.55×; 5 substeps fold a link to 0.03–0.09×, 8 iterations
/// to 0.04×; 20 × 8, also within, costs more). comparisons/README.md has the grid.
int substepsFor(const PreparedScene& scene);

/// The baseline's default link iterations per substep: the most particles on one fibre × 2/5,
/// rounded up. A Gauss–Seidel sweep carries a pinned end's correction about one link along a
/// fibre, so the sweeps a substep needs grow with the particles on it (see substepsFor).
int iterationsFor(const PreparedScene& scene);

/// Deformed surface vertices of a muscle from its particle positions (method.md §7): every
/// skin particle j carries the vertex's rest offset rotated with the particle's nearest bone,
/// vertex = Σ w_j (x_j + R_j (v0 − X_j)). A rigid motion of everything is reproduced exactly.
void skinSurface(const MuscleSettings& muscle, std::span<const btVector3> positions,
                 std::span<const btTransform> boneTransforms, std::vector<btVector3>& out);

/// Initial particle positions: rest positions moved by the nearest (fixed: own) bone.
std::vector<btVector3> posedParticles(const MuscleSettings& muscle,
                                      std::span<const btTransform> boneTransforms);

/// The baseline world: one btSoftBody per muscle, one kinematic btRigidBody per bone, in a
/// btSoftRigidDynamicsWorld (btSoftBodyRigidBodyCollisionConfiguration, no gravity).
class SoftBodyScene : public BaselineScene {
 public:
  /// Bodies start at the poses `boneTransforms` (one per bone; rest pose when empty).
  SoftBodyScene(const PreparedScene& scene, std::span<const btTransform> boneTransforms,
                const SoftBodyDefinition& definition = {});
  ~SoftBodyScene() override;
  SoftBodyScene(const SoftBodyScene&) = delete;
  SoftBodyScene& operator=(const SoftBodyScene&) = delete;

  /// One pose: bones move from their current transforms to `targets` over the substeps,
  /// pinned nodes follow them, the world steps definition().substepsPerPose times (`stop` is
  /// not checked: a pose always completes).
  bool stepPose(std::span<const btTransform> targets,
                const std::function<bool()>& stop = {}) override;

  size_t muscleCount() const override;
  size_t nodeCount() const override;          ///< nodes of all muscles
  size_t elementCount() const override;       ///< links of all muscles
  size_t boundaryNodeCount() const override;  ///< the muscles' boundary particles
  /// Node positions of one muscle (particle order, metres), as of the last step.
  std::span<const btVector3> nodePositions(size_t muscle) const override;
  /// The muscle's deformed surface (skinSurface of the node positions).
  void surface(size_t muscle, std::vector<btVector3>& out) const override;
  /// The muscle's springs (its links' node pairs and rest lengths).
  std::vector<NodePair> nodePairs(size_t muscle) const override;
  /// Σ|l − L0| / Σ L0 over the springs of all muscles.
  double springDeviation() const override;
  long iterationsPerPose() const override;  ///< substeps × link iterations
  long substepsPerPose() const override;    ///< world steps per pose
  /// "btSoftBody position solver (…)" with the substeps, iterations and clusters used.
  std::string settings() const override;
  std::span<const btTransform> boneTransforms() const;
  btSoftBody& body(size_t muscle);    ///< in Bullet units (definition().lengthScale per metre)
  btSoftRigidDynamicsWorld& world();  ///< in Bullet units
  /// As given, with substepsPerPose and positionIterations 0 resolved for the scene.
  const SoftBodyDefinition& definition() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace fibremss
