#include "fibremss/FemBuilder.h"

#include <BulletCollision/BroadphaseCollision/btDbvtBroadphase.h>
#include <BulletSoftBody/btDeformableBodySolver.h>
#include <BulletSoftBody/btDeformableMultiBodyConstraintSolver.h>
#include <BulletSoftBody/btDeformableMultiBodyDynamicsWorld.h>
#include <BulletSoftBody/btDeformableNeoHookeanForce.h>
#include <BulletSoftBody/btSoftBodyHelpers.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <utility>

#include "SoftBodyBones.h"

namespace fibremss {

struct FemScene::Impl {
  FemDefinition definition;
  std::unique_ptr<btSoftBodyRigidBodyCollisionConfiguration> configuration;
  std::unique_ptr<btCollisionDispatcher> dispatcher;
  std::unique_ptr<btDbvtBroadphase> broadphase;
  std::unique_ptr<btDeformableBodySolver> deformableSolver;
  std::unique_ptr<btDeformableMultiBodyConstraintSolver> solver;
  std::unique_ptr<btDeformableMultiBodyDynamicsWorld> world;
  std::vector<KinematicBone> bones;
  std::vector<btTransform> boneTransforms;

  struct Muscle {
    TetMesh mesh;                      ///< rest tetrahedra
    TetEmbedding surface;              ///< the muscle's surface vertices in them
    std::vector<uint32_t> pinned;      ///< pinned node indices
    std::vector<int32_t> pinnedBone;   ///< their bones
    std::vector<btVector3> positions;  ///< node positions after the last step
    btSoftBody* body = nullptr;        ///< owned; removed from the world first
    double networkStiffness = 0;       ///< Σ κ·L0 of its springs [N·m]
  };
  std::vector<Muscle> muscles;
  /// One elasticity for all muscles: Bullet merges forces of one type into the first added.
  std::unique_ptr<btDeformableNeoHookeanForce> force;
  double youngsModulus = 0;  ///< E used [Pa]

  /// E from the definition or matched to all muscles' springs together, then the force.
  void addElasticity() {
    double stiffness = 0, volume = 0;
    for (const Muscle& muscle : muscles) {
      stiffness += muscle.networkStiffness;
      volume += totalVolume(muscle.mesh);
    }
    youngsModulus = definition.youngsModulus > 0 ? definition.youngsModulus
                    : volume > 0                 ? stiffness / (3 * volume)
                                                 : 0;
    // Lengths ×S with masses and time kept need stresses ÷S.
    const double e = youngsModulus / definition.lengthScale, nu = definition.poissonRatio;
    force = std::make_unique<btDeformableNeoHookeanForce>(
        static_cast<btScalar>(e / (2 * (1 + nu))),
        static_cast<btScalar>(e * nu / ((1 + nu) * (1 - 2 * nu))), definition.damping);
    for (Muscle& muscle : muscles) world->addForce(muscle.body, force.get());
  }

  ~Impl() {
    // Removing a body ends its pairs, and each ending pair scans every SDF bucket once per
    // cached triangle: empty the SDF down to one bucket first.
    world->getWorldInfo().m_sparsesdf.Reset();
    world->getWorldInfo().m_sparsesdf.Initialize(1, 1);
    for (Muscle& m : muscles) {
      world->removeSoftBodyForce(m.body);
      world->removeSoftBody(m.body);
      delete m.body;
    }
    for (KinematicBone& b : bones) world->removeRigidBody(b.body.get());
  }

  void addMuscle(const MuscleSettings& s) {
    Muscle muscle;
    muscle.mesh = tetrahedralize(s.restSurface, definition.mesher);
    muscle.surface = embed(muscle.mesh, s.restSurface.vertices);
    const TetMesh& mesh = muscle.mesh;
    const size_t nodes = mesh.nodes.size();

    // Each node follows its nearest particle: pinned to that particle's bone when the
    // particle is fixed and within the attachment distance, else posed with its nearest bone.
    const btScalar reach =
        definition.attachmentDistance > 0 ? definition.attachmentDistance : mesh.cellSize;
    std::vector<int32_t> poseBone(nodes, -1);
    std::vector<int32_t> pinBone(nodes, -1);
    for (size_t n = 0; n < nodes; ++n) {
      btScalar nearest = std::numeric_limits<btScalar>::infinity();
      btScalar nearestFixed = std::numeric_limits<btScalar>::infinity();
      for (size_t p = 0; p < s.particleCount(); ++p) {
        const btScalar d = mesh.nodes[n].distance2(s.restPositions[p]);
        if (d < nearest) {
          nearest = d;
          poseBone[n] = s.fixedBone[p] >= 0 ? s.fixedBone[p] : s.nearestBone[p];
        }
        if (s.isFixed(static_cast<uint32_t>(p)) && d < nearestFixed) {
          nearestFixed = d;
          if (d <= reach * reach) pinBone[n] = s.fixedBone[p];
        }
      }
    }
    // Every fixed particle holds at least its nearest node.
    for (uint32_t p : s.fixedParticles) {
      size_t best = 0;
      for (size_t n = 1; n < nodes; ++n) {
        if (mesh.nodes[n].distance2(s.restPositions[p]) <
            mesh.nodes[best].distance2(s.restPositions[p])) {
          best = n;
        }
      }
      if (pinBone[best] < 0) pinBone[best] = s.fixedBone[p];
    }

    // Lumped masses: a quarter of every adjacent tetrahedron's mass.
    std::vector<btScalar> masses(nodes, 0);
    for (const auto& t : mesh.tetrahedra) {
      const double m = definition.density *
                       tetrahedronVolume(mesh.nodes[t[0]], mesh.nodes[t[1]], mesh.nodes[t[2]],
                                         mesh.nodes[t[3]]) /
                       4;
      for (uint32_t v : t) masses[v] += static_cast<btScalar>(m);
    }
    for (size_t n = 0; n < nodes; ++n) {
      if (pinBone[n] >= 0) {
        masses[n] = 0;
        muscle.pinned.push_back(static_cast<uint32_t>(n));
        muscle.pinnedBone.push_back(pinBone[n]);
      }
    }

    const btScalar scale = definition.lengthScale;
    std::vector<btVector3> scaled;
    for (const btVector3& x : mesh.nodes) scaled.push_back(x * scale);
    muscle.body = new btSoftBody(&world->getWorldInfo(), static_cast<int>(nodes), scaled.data(),
                                 masses.data());
    btSoftBody& body = *muscle.body;
    for (const auto& t : mesh.tetrahedra) {
      body.appendTetra(static_cast<int>(t[0]), static_cast<int>(t[1]), static_cast<int>(t[2]),
                       static_cast<int>(t[3]));
    }
    // Links along the tetrahedra's edges: the deformable solver builds its node tree from
    // link adjacency (without links it never finishes); they carry no force here.
    std::vector<std::pair<uint32_t, uint32_t>> edges;
    for (const auto& t : mesh.tetrahedra) {
      for (int a = 0; a < 4; ++a) {
        for (int b = a + 1; b < 4; ++b) edges.emplace_back(std::minmax(t[a], t[b]));
      }
    }
    std::sort(edges.begin(), edges.end());
    edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
    for (const auto& [a, b] : edges) body.appendLink(static_cast<int>(a), static_cast<int>(b));
    body.initializeDmInverse();         // rest shape: the nodes as given
    btSoftBody::TetraScratch identity;  // F = I at rest (the default leaves it uninitialized)
    identity.m_F.setIdentity();
    identity.m_trace = 3;
    identity.m_J = 1;
    identity.m_cofF.setIdentity();
    identity.m_corotation.setIdentity();
    body.m_tetraScratches.resize(body.m_tetras.size(), identity);
    body.m_tetraScratchesTn.resize(body.m_tetras.size(), identity);
    btSoftBodyHelpers::generateBoundaryFaces(&body);
    body.getCollisionShape()->setMargin(mesh.cellSize * btScalar(0.25) * scale);
    body.m_cfg.collisions = 0;
    if (definition.boneContact) body.m_cfg.collisions |= btSoftBody::fCollision::SDF_RD;
    if (definition.muscleContact) body.m_cfg.collisions |= btSoftBody::fCollision::VF_DD;
    body.m_cfg.kKHR = 1;  // contact hardness with kinematic bodies
    body.m_cfg.kCHR = 1;  // contact hardness with rigid bodies
    body.m_cfg.kDF = 0;   // frictionless, as FibreMSS's response
    body.m_sleepingThreshold = 0;
    // Bullet collides deformable faces pairwise unless told not to: minutes per pose on thigh13.
    body.m_softSoftCollision = definition.muscleContact;
    body.m_useSelfCollision = false;

    // Start posed: every node moved by its nearest particle's bone.
    for (size_t n = 0; n < nodes; ++n) {
      if (poseBone[n] >= 0) {
        btSoftBody::Node& node = body.m_nodes[static_cast<int>(n)];
        node.m_x = boneTransforms[poseBone[n]] * mesh.nodes[n] * scale;
        node.m_q = node.m_x;
      }
    }
    world->addSoftBody(muscle.body);
    for (const Spring& spring : s.springs) {
      muscle.networkStiffness +=
          static_cast<double>(spring.stiffness) * spring.restLength * spring.restLength;
    }
    muscle.positions.resize(nodes);
    readPositions(muscle);
    muscles.push_back(std::move(muscle));
  }

  void readPositions(Muscle& muscle) const {
    for (size_t n = 0; n < muscle.positions.size(); ++n) {
      muscle.positions[n] = muscle.body->m_nodes[static_cast<int>(n)].m_x / definition.lengthScale;
    }
  }

  void movePins(const Muscle& muscle) {
    for (size_t k = 0; k < muscle.pinned.size(); ++k) {
      const uint32_t n = muscle.pinned[k];
      btSoftBody::Node& node = muscle.body->m_nodes[static_cast<int>(n)];
      node.m_x =
          boneTransforms[muscle.pinnedBone[k]] * muscle.mesh.nodes[n] * definition.lengthScale;
      node.m_q = node.m_x;
      node.m_v.setZero();
    }
  }
};

FemScene::FemScene(const PreparedScene& scene, std::span<const btTransform> boneTransforms,
                   const FemDefinition& definition)
    : impl_(std::make_unique<Impl>()) {
  if (!boneTransforms.empty() && boneTransforms.size() != scene.bones.size()) {
    throw std::invalid_argument("FemScene: bone transforms do not match the bones");
  }
  if (definition.substepsPerPose < 1 || definition.poseDuration <= 0) {
    throw std::invalid_argument("FemScene: substepsPerPose and poseDuration must be > 0");
  }
  if (!(definition.poissonRatio > -1 && definition.poissonRatio < 0.5f) ||
      !(definition.youngsModulus >= 0) || !(definition.lengthScale > 0)) {
    throw std::invalid_argument(
        "FemScene: needs E >= 0, -1 < Poisson ratio < 0.5 and a positive length scale");
  }
  Impl& m = *impl_;
  m.definition = definition;
  m.configuration = std::make_unique<btSoftBodyRigidBodyCollisionConfiguration>();
  m.dispatcher = std::make_unique<btCollisionDispatcher>(m.configuration.get());
  m.broadphase = std::make_unique<btDbvtBroadphase>();
  m.deformableSolver = std::make_unique<btDeformableBodySolver>();
  m.solver = std::make_unique<btDeformableMultiBodyConstraintSolver>();
  m.solver->setDeformableSolver(m.deformableSolver.get());
  m.world = std::make_unique<btDeformableMultiBodyDynamicsWorld>(
      m.dispatcher.get(), m.broadphase.get(), m.solver.get(), m.configuration.get(),
      m.deformableSolver.get());
  m.world->setGravity(btVector3(0, 0, 0));
  btSoftBodyWorldInfo& info = m.world->getWorldInfo();
  info.m_gravity.setZero();
  info.m_sparsesdf.Initialize(kSdfBuckets, kSdfMaxCells);
  info.m_sparsesdf.setDefaultVoxelsz(definition.sdfVoxelSize * definition.lengthScale);

  m.boneTransforms.assign(scene.bones.size(), btTransform::getIdentity());
  if (!boneTransforms.empty())
    m.boneTransforms.assign(boneTransforms.begin(), boneTransforms.end());
  m.bones.reserve(scene.bones.size());
  for (size_t b = 0; b < scene.bones.size(); ++b) {
    m.bones.emplace_back(*scene.bones[b],
                         scaledTransform(m.boneTransforms[b], definition.lengthScale),
                         definition.lengthScale);
    if (definition.boneContact) m.world->addRigidBody(m.bones.back().body.get());
  }
  for (const auto& muscle : scene.muscles) m.addMuscle(*muscle);
  m.addElasticity();
}

FemScene::~FemScene() = default;

bool FemScene::stepPose(std::span<const btTransform> targets, const std::function<bool()>& stop) {
  Impl& m = *impl_;
  if (targets.size() != m.bones.size()) {
    throw std::invalid_argument("FemScene::stepPose: bone transforms do not match the bones");
  }
  const int substeps = m.definition.substepsPerPose;
  const btScalar dt = m.definition.poseDuration / static_cast<btScalar>(substeps);
  const std::vector<btTransform> from = m.boneTransforms;
  for (int k = 1; k <= substeps; ++k) {
    if (stop && stop()) return false;
    const btScalar t = static_cast<btScalar>(k) / static_cast<btScalar>(substeps);
    for (size_t b = 0; b < m.bones.size(); ++b) {
      m.boneTransforms[b] = interpolateTransform(from[b], targets[b], t);
      m.bones[b].body->setWorldTransform(
          scaledTransform(m.boneTransforms[b], m.definition.lengthScale));
    }
    for (const Impl::Muscle& muscle : m.muscles) m.movePins(muscle);
    m.world->stepSimulation(dt, 0);
  }
  for (Impl::Muscle& muscle : m.muscles) m.readPositions(muscle);
  m.world->getWorldInfo().m_sparsesdf.GarbageCollect();
  return true;
}

size_t FemScene::muscleCount() const {
  return impl_->muscles.size();
}

size_t FemScene::nodeCount() const {
  size_t n = 0;
  for (const auto& muscle : impl_->muscles) n += muscle.positions.size();
  return n;
}

size_t FemScene::tetrahedronCount() const {
  size_t n = 0;
  for (const auto& muscle : impl_->muscles) n += muscle.mesh.tetrahedra.size();
  return n;
}

size_t FemScene::pinnedCount() const {
  size_t n = 0;
  for (const auto& muscle : impl_->muscles) n += muscle.pinned.size();
  return n;
}

const TetMesh& FemScene::tetMesh(size_t muscle) const {
  return impl_->muscles.at(muscle).mesh;
}

std::span<const btVector3> FemScene::nodePositions(size_t muscle) const {
  return impl_->muscles.at(muscle).positions;
}

void FemScene::surface(size_t muscle, std::vector<btVector3>& out) const {
  const auto& m = impl_->muscles.at(muscle);
  embeddedPositions(m.mesh, m.surface, m.positions, out);
}

btSoftBody& FemScene::body(size_t muscle) {
  return *impl_->muscles.at(muscle).body;
}

btDeformableMultiBodyDynamicsWorld& FemScene::world() {
  return *impl_->world;
}

const FemDefinition& FemScene::definition() const {
  return impl_->definition;
}

double FemScene::youngsModulus() const {
  return impl_->youngsModulus;
}

}  // namespace fibremss
