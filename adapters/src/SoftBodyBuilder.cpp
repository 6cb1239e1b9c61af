#include "fibremss/SoftBodyBuilder.h"

#include <BulletDynamics/ConstraintSolver/btSequentialImpulseConstraintSolver.h>
#include <BulletSoftBody/btSoftRigidDynamicsWorld.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "SoftBodyBones.h"
#include "fibremss/BoneBody.h"

namespace fibremss {
namespace {

/// Drops the pinned nodes from every cluster (and the clusters left with fewer than four
/// nodes, which have no inertia), then recomputes the clusters. Bullet weighs a mass-0 node as
/// BT_LARGE_FLOAT (1e18) in its cluster; in float the cluster's inertia then overflows and its
/// inverse is NaN, which CL_SS spreads to every node it touches (NaN in thigh13's first pose).
/// Pinned nodes are moved with their bones by us, so cluster impulses must not touch them.
void clustersOfFreeNodes(btSoftBody& body) {
  for (int c = body.m_clusters.size() - 1; c >= 0; --c) {
    btSoftBody::Cluster& cluster = *body.m_clusters[c];
    btAlignedObjectArray<btSoftBody::Node*> free;
    for (int j = 0; j < cluster.m_nodes.size(); ++j) {
      if (cluster.m_nodes[j]->m_im > 0) free.push_back(cluster.m_nodes[j]);
    }
    if (free.size() < 4) {
      body.releaseCluster(c);
      continue;
    }
    cluster.m_nodes = free;
    cluster.m_containsAnchor = false;
    if (cluster.m_leaf) body.m_cdbvt.remove(cluster.m_leaf);  // initializeClusters forgets it
    cluster.m_leaf = nullptr;
  }
  body.initializeClusters();
  body.updateClusters();
}

}  // namespace

void skinSurface(const MuscleSettings& muscle, std::span<const btVector3> positions,
                 std::span<const btTransform> boneTransforms, std::vector<btVector3>& out) {
  const auto& rest = muscle.restSurface.vertices;
  const size_t n = static_cast<size_t>(muscle.skinNeighbours);
  out.resize(rest.size());
  for (size_t v = 0; v < rest.size(); ++v) {
    btVector3 sum(0, 0, 0);
    for (size_t k = 0; k < n; ++k) {
      const uint32_t j = muscle.skinParticles[v * n + k];
      const int32_t bone = muscle.nearestBone[j];
      const btVector3 offset = rest[v] - muscle.restPositions[j];
      const btVector3 carried = bone >= 0 && static_cast<size_t>(bone) < boneTransforms.size()
                                    ? positions[j] + boneTransforms[bone].getBasis() * offset
                                    : positions[j] + offset;
      sum += carried * muscle.skinWeights[v * n + k];
    }
    out[v] = sum;
  }
}

std::vector<btVector3> posedParticles(const MuscleSettings& muscle,
                                      std::span<const btTransform> boneTransforms) {
  std::vector<btVector3> posed(muscle.restPositions);
  for (size_t i = 0; i < posed.size(); ++i) {
    const int32_t bone = muscle.fixedBone[i] >= 0 ? muscle.fixedBone[i] : muscle.nearestBone[i];
    if (bone >= 0 && static_cast<size_t>(bone) < boneTransforms.size()) {
      posed[i] = boneTransforms[bone] * posed[i];
    }
  }
  return posed;
}

struct SoftBodyScene::Impl {
  SoftBodyDefinition definition;
  SoftWorldParts parts;
  std::unique_ptr<btSequentialImpulseConstraintSolver> solver =
      std::make_unique<btSequentialImpulseConstraintSolver>();
  std::unique_ptr<btSoftRigidDynamicsWorld> world = std::make_unique<btSoftRigidDynamicsWorld>(
      parts.dispatcher.get(), parts.broadphase.get(), solver.get(), parts.configuration.get());

  /// Kinematic bones in Bullet units, their bounds padded by kBonePadding so that muscle–bone
  /// pairs never end: when one ends, btSoftBodyTriangleCallback::clearCache scans every
  /// sparse-SDF cell once per cached triangle (minutes per pose on thigh13). Triangles are
  /// still culled by the muscle's own bounds.
  std::vector<std::unique_ptr<BoneBody>> bones;
  std::vector<btTransform> boneTransforms;     ///< current bone poses [m]
  std::vector<btTransform> deltas;             ///< bone motion of one substep (scratch)
  static constexpr btScalar kBonePadding = 2;  ///< [m] beyond any muscle's reach

  struct Muscle {
    std::shared_ptr<const MuscleSettings> settings;
    btSoftBody* body = nullptr;  // owned; removed from the world before deletion
    std::vector<btVector3> positions;
  };
  std::vector<Muscle> muscles;
  size_t links = 0;

  ~Impl() {
    // Removing a body ends its pairs, and each ending pair scans every SDF bucket once per
    // cached triangle: empty the SDF down to one bucket first.
    world->getWorldInfo().m_sparsesdf.Reset();
    world->getWorldInfo().m_sparsesdf.Initialize(1, 1);
    for (Muscle& m : muscles) {
      world->removeSoftBody(m.body);
      delete m.body;
    }
    for (auto& bone : bones) world->removeRigidBody(bone->body());
  }

  void addBone(std::shared_ptr<const BoneSettings> settings, const btTransform& transform) {
    const btScalar scale = definition.lengthScale;
    bones.push_back(std::make_unique<BoneBody>(std::move(settings),
                                               scaledTransform(transform, scale),
                                               BoneBodyOptions{scale, kBonePadding * scale}));
    bones.back()->body()->getCollisionShape()->setMargin(0);
    if (definition.boneCollision) world->addRigidBody(bones.back()->body());
  }

  void addMuscle(std::shared_ptr<const MuscleSettings> settings) {
    const MuscleSettings& s = *settings;
    const btScalar dt = definition.poseDuration / static_cast<btScalar>(definition.substepsPerPose);
    Muscle muscle;
    muscle.settings = settings;
    muscle.positions = posedParticles(s, boneTransforms);
    std::vector<btVector3> scaled;
    for (const btVector3& x : muscle.positions) scaled.push_back(x * definition.lengthScale);
    std::vector<btScalar> masses(s.particleCount(), s.particleMass);
    for (uint32_t i : s.fixedParticles) masses[i] = 0;  // pinned: moved by us with the bone
    muscle.body = new btSoftBody(&world->getWorldInfo(), static_cast<int>(s.particleCount()),
                                 scaled.data(), masses.data());
    btSoftBody& body = *muscle.body;

    // Stiffness levels: s per link from k, dt, m and the iteration count (see the header);
    // each level's material gets the mean s of its links.
    const int levels = std::max(1, definition.stiffnessLevels);
    const int n = std::max(1, definition.positionIterations);
    const double mass = s.particleMass > 0 ? s.particleMass : 1;
    std::vector<int> linkLevel(s.springs.size());
    std::vector<double> levelSum(levels, 0);
    std::vector<int> levelCount(levels, 0);
    for (size_t i = 0; i < s.springs.size(); ++i) {
      const double f = std::min(1.0, 2.0 * s.springs[i].stiffness * dt * dt / mass);
      const double perIteration = 1.0 - std::pow(1.0 - f, 1.0 / n);
      linkLevel[i] = std::clamp(static_cast<int>(perIteration * levels), 0, levels - 1);
      levelSum[linkLevel[i]] += perIteration;
      ++levelCount[linkLevel[i]];
    }
    std::vector<btSoftBody::Material*> materials(levels, nullptr);
    for (int level = 0; level < levels; ++level) {
      if (levelCount[level] == 0) continue;
      materials[level] = body.appendMaterial();
      materials[level]->m_kLST = static_cast<btScalar>(levelSum[level] / levelCount[level]);
    }
    for (size_t i = 0; i < s.springs.size(); ++i) {
      body.appendLink(static_cast<int>(s.springs[i].a), static_cast<int>(s.springs[i].b),
                      materials[linkLevel[i]]);
    }
    links += s.springs.size();

    body.m_cfg.piterations = definition.positionIterations;
    body.m_cfg.citerations = definition.clusterIterations;
    body.m_cfg.kDP = std::clamp(definition.velocityDamping, btScalar(0), btScalar(1));
    body.m_cfg.kCHR = 1;  // rigid contact hardness
    body.m_cfg.kKHR = 1;  // kinematic contact hardness
    body.m_cfg.kSHR = 1;  // soft contact hardness
    body.m_cfg.collisions = 0;
    if (definition.boneCollision) body.m_cfg.collisions |= btSoftBody::fCollision::SDF_RS;
    if (definition.softSoftCollision) {
      body.m_cfg.collisions |= btSoftBody::fCollision::CL_SS;
      body.generateClusters(
          std::min<int>(definition.clustersPerMuscle, static_cast<int>(s.particleCount())));
      clustersOfFreeNodes(body);
    }
    // Collision margin: the mean radius of the colliding particles (FibreMSS's spheres).
    double radius = 0;
    for (uint32_t i : s.boundaryParticles) radius += s.radii[i];
    if (!s.boundaryParticles.empty()) radius /= static_cast<double>(s.boundaryParticles.size());
    body.getCollisionShape()->setMargin(
        static_cast<btScalar>(std::max(radius, 1e-4) * definition.lengthScale));
    world->addSoftBody(muscle.body);
    muscles.push_back(std::move(muscle));
  }

  /// Free nodes moved by the bones' motion of this substep, `deltas` (filled once per
  /// substep for every muscle).
  void moveFreeNodes(const Muscle& muscle) const {
    const MuscleSettings& s = *muscle.settings;
    const btScalar scale = definition.lengthScale;
    for (uint32_t i = 0; i < s.particleCount(); ++i) {
      if (!s.isFixed(i))
        moveNodeWithBones(s, deltas, i, scale, muscle.body->m_nodes[static_cast<int>(i)]);
    }
  }

  void movePins(const Muscle& muscle) const {
    const MuscleSettings& s = *muscle.settings;
    for (uint32_t i : s.fixedParticles) {
      btSoftBody::Node& node = muscle.body->m_nodes[static_cast<int>(i)];
      node.m_x = boneTransforms[s.fixedBone[i]] * s.restPositions[i] * definition.lengthScale;
      node.m_q = node.m_x;
      node.m_v.setZero();
    }
  }
};

SoftBodyScene::SoftBodyScene(const PreparedScene& scene,
                             std::span<const btTransform> boneTransforms,
                             const SoftBodyDefinition& definition)
    : impl_(std::make_unique<Impl>()) {
  if (!boneTransforms.empty() && boneTransforms.size() != scene.bones.size()) {
    throw std::invalid_argument("SoftBodyScene: bone transforms do not match the bones");
  }
  if (definition.substepsPerPose < 1 || definition.poseDuration <= 0 ||
      definition.lengthScale <= 0) {
    throw std::invalid_argument(
        "SoftBodyScene: substepsPerPose, poseDuration and lengthScale must be > 0");
  }
  Impl& m = *impl_;
  m.definition = definition;
  m.world->setGravity(btVector3(0, 0, 0));
  btSoftBodyWorldInfo& info = m.world->getWorldInfo();
  info.m_gravity.setZero();
  info.air_density = 0;
  info.m_sparsesdf.Initialize(kSdfBuckets, kSdfMaxCells);
  info.m_sparsesdf.setDefaultVoxelsz(definition.sdfVoxelSize * definition.lengthScale);
  info.m_sparsesdf.Reset();  // the voxel size takes effect only here

  m.boneTransforms.assign(scene.bones.size(), btTransform::getIdentity());
  if (!boneTransforms.empty())
    m.boneTransforms.assign(boneTransforms.begin(), boneTransforms.end());
  for (size_t b = 0; b < scene.bones.size(); ++b) m.addBone(scene.bones[b], m.boneTransforms[b]);
  for (const auto& muscle : scene.muscles) m.addMuscle(muscle);
}

SoftBodyScene::~SoftBodyScene() = default;

void SoftBodyScene::stepPose(std::span<const btTransform> targets) {
  Impl& m = *impl_;
  if (targets.size() != m.bones.size()) {
    throw std::invalid_argument("SoftBodyScene::stepPose: bone transforms do not match the bones");
  }
  const int substeps = m.definition.substepsPerPose;
  const btScalar dt = m.definition.poseDuration / static_cast<btScalar>(substeps);
  const std::vector<btTransform> from = m.boneTransforms;
  for (int k = 1; k <= substeps; ++k) {
    advanceBones(from, targets, static_cast<btScalar>(k) / static_cast<btScalar>(substeps),
                 m.boneTransforms, m.deltas);
    for (size_t b = 0; b < m.bones.size(); ++b) {
      m.bones[b]->setTransform(scaledTransform(m.boneTransforms[b], m.definition.lengthScale));
    }
    for (const Impl::Muscle& muscle : m.muscles) {
      if (m.definition.freeNodesFollowBones) m.moveFreeNodes(muscle);
      m.movePins(muscle);
    }
    m.world->stepSimulation(dt, 0);
  }
  for (Impl::Muscle& muscle : m.muscles) {
    for (size_t i = 0; i < muscle.positions.size(); ++i) {
      muscle.positions[i] =
          muscle.body->m_nodes[static_cast<int>(i)].m_x / m.definition.lengthScale;
    }
  }
  m.world->getWorldInfo().m_sparsesdf.GarbageCollect();
}

size_t SoftBodyScene::muscleCount() const {
  return impl_->muscles.size();
}

size_t SoftBodyScene::nodeCount() const {
  size_t n = 0;
  for (const auto& muscle : impl_->muscles) n += muscle.positions.size();
  return n;
}

size_t SoftBodyScene::linkCount() const {
  return impl_->links;
}

std::span<const btVector3> SoftBodyScene::positions(size_t muscle) const {
  return impl_->muscles.at(muscle).positions;
}

void SoftBodyScene::surface(size_t muscle, std::vector<btVector3>& out) const {
  const auto& m = impl_->muscles.at(muscle);
  skinSurface(*m.settings, m.positions, impl_->boneTransforms, out);
}

std::span<const btTransform> SoftBodyScene::boneTransforms() const {
  return impl_->boneTransforms;
}

btSoftBody& SoftBodyScene::body(size_t muscle) {
  return *impl_->muscles.at(muscle).body;
}

btSoftRigidDynamicsWorld& SoftBodyScene::world() {
  return *impl_->world;
}

const SoftBodyDefinition& SoftBodyScene::definition() const {
  return impl_->definition;
}

}  // namespace fibremss
