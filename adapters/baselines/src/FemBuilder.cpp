#include "fibremss/FemBuilder.h"

#include <BulletSoftBody/btDeformableBodySolver.h>
#include <BulletSoftBody/btDeformableMultiBodyConstraintSolver.h>
#include <BulletSoftBody/btDeformableMultiBodyDynamicsWorld.h>
#include <BulletSoftBody/btDeformableNeoHookeanForce.h>
#include <BulletSoftBody/btSoftBodyHelpers.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <span>
#include <stdexcept>
#include <utility>

#include "SoftBodyBones.h"
#include "fibremss/Geometry.h"

namespace fibremss {
namespace {

/// Unit normal of a mesh triangle (its corners counter-clockwise seen from outside).
btVector3 faceNormal(const TriangleMesh& mesh, uint32_t triangle) {
  const auto& t = mesh.triangles[triangle];
  btVector3 normal =
      (mesh.vertices[t[1]] - mesh.vertices[t[0]]).cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]);
  return normal.safeNormalize();
}

}  // namespace

struct FemScene::Impl {
  FemDefinition definition;
  SoftWorldParts parts;
  std::unique_ptr<btDeformableBodySolver> deformableSolver =
      std::make_unique<btDeformableBodySolver>();
  std::unique_ptr<btDeformableMultiBodyConstraintSolver> solver =
      std::make_unique<btDeformableMultiBodyConstraintSolver>();
  std::unique_ptr<btDeformableMultiBodyDynamicsWorld> world;
  std::vector<btTransform> boneTransforms;  ///< current bone poses [m]
  std::vector<btTransform> deltas;          ///< bone motion of one substep (scratch)

  /// A bone for the node contact: its exact surface and bounds in its rest frame [m].
  struct Bone {
    MeshDistance surface;    ///< closest points, inside test
    btVector3 lower, upper;  ///< rest bounds grown by the contact reach
    /// p (rest frame) lies within the grown bounds.
    bool near(const btVector3& p) const {
      return p.x() >= lower.x() && p.y() >= lower.y() && p.z() >= lower.z() && p.x() <= upper.x() &&
             p.y() <= upper.y() && p.z() <= upper.z();
    }
  };
  std::vector<Bone> bones;
  btScalar contactMargin = 0;  ///< nodes are kept this far outside the bones [m]
  btScalar contactReach = 0;   ///< how far from a bone's surface nodes are looked at [m]

  struct Muscle {
    std::shared_ptr<const MuscleSettings> settings;  ///< its particles' bones and blends
    TetMesh mesh;                                    ///< rest tetrahedra
    std::vector<uint32_t> nearestParticle;  ///< per node: the particle whose bones it follows
    TetEmbedding surface;                   ///< the muscle's surface vertices in them
    std::vector<uint8_t> startedInside;     ///< node × bone: inside that bone at the start (such
                                            ///< nodes keep their contact-free overlap with it)
    std::vector<uint32_t> pinned;           ///< pinned node indices
    std::vector<int32_t> pinnedBone;        ///< their bones
    std::vector<btVector3> positions;       ///< node positions after the last step
    btSoftBody* body = nullptr;             ///< owned; removed from the world first
    double networkStiffness = 0;            ///< Σ κ·L0 of its springs [N·m]
  };
  std::vector<Muscle> muscles;
  /// One elasticity for all muscles: Bullet merges forces of one type into the first added.
  std::unique_ptr<btDeformableNeoHookeanForce> force;
  double youngsModulus = 0;   ///< E used [Pa]
  double addedMassShare = 0;  ///< mass added by scaleMasses / free nodes' mass before it
  size_t fewestPins = std::numeric_limits<size_t>::max();  ///< per bone of a muscle (pinAtLeast)
  int lastSettleSubsteps = 0;                              ///< of the last pose
  int unsettledPoses = 0;  ///< poses that did not settle within settleSubsteps

  /// Every free node's velocity scaled by `kept` (settling's drag).
  void dragNodes(btScalar kept) {
    for (Muscle& muscle : muscles)
      for (int n = 0; n < muscle.body->m_nodes.size(); ++n) muscle.body->m_nodes[n].m_v *= kept;
  }

  /// The fastest free node's speed [m/s].
  btScalar fastestNode() const {
    btScalar fastest = 0;
    for (const Muscle& muscle : muscles)
      for (int n = 0; n < muscle.body->m_nodes.size(); ++n)
        if (muscle.body->m_nodes[n].m_im > 0)
          fastest = std::max(fastest, muscle.body->m_nodes[n].m_v.length());
    return fastest / definition.lengthScale;
  }

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

  /// Selective mass scaling (FemDefinition::stableOmegaDt): a free node oscillates at
  /// ω² ≈ K/m with K = (λ+2μ)·Σ V·|∇N|² over its tetrahedra (N its barycentric coordinate);
  /// nodes with ω·dt beyond the limit get the mass that brings them to it.
  void scaleMasses(btScalar dt) {
    if (!(definition.stableOmegaDt > 0)) return;
    const double nu = definition.poissonRatio;
    const double modulus = youngsModulus * (1 - nu) / ((1 + nu) * (1 - 2 * nu));  // λ + 2μ
    const double limit = static_cast<double>(definition.stableOmegaDt) / dt;
    double total = 0, added = 0;
    for (Muscle& muscle : muscles) {
      const TetMesh& mesh = muscle.mesh;
      std::vector<double> stiffness(mesh.nodes.size(), 0);
      for (const auto& t : mesh.tetrahedra) {
        const btVector3* x[4] = {&mesh.nodes[t[0]], &mesh.nodes[t[1]], &mesh.nodes[t[2]],
                                 &mesh.nodes[t[3]]};
        const double volume = tetrahedronVolume(*x[0], *x[1], *x[2], *x[3]);
        for (int i = 0; i < 4; ++i) {
          // |∇N_i| = area of the opposite face / (3V)
          const btVector3& a = *x[(i + 1) % 4];
          const double area = 0.5 * (*x[(i + 2) % 4] - a).cross(*x[(i + 3) % 4] - a).length();
          const double gradient = area / (3 * volume);
          stiffness[t[i]] += modulus * volume * gradient * gradient;
        }
      }
      for (int n = 0; n < muscle.body->m_nodes.size(); ++n) {
        const btScalar inverse = muscle.body->m_nodes[n].m_im;
        if (inverse == 0) continue;  // pinned
        const double mass = 1 / static_cast<double>(inverse);
        const double needed = stiffness[static_cast<size_t>(n)] / (limit * limit);
        total += mass;
        if (needed > mass) {
          muscle.body->setMass(n, static_cast<btScalar>(needed));
          added += needed - mass;
        }
      }
    }
    addedMassShare = total > 0 ? added / total : 0;
  }

  ~Impl() {
    for (Muscle& m : muscles) {
      world->removeSoftBodyForce(m.body);
      world->removeSoftBody(m.body);
      delete m.body;
    }
  }

  void addBone(const BoneSettings& settings) {
    btVector3 lower(BT_LARGE_FLOAT, BT_LARGE_FLOAT, BT_LARGE_FLOAT);
    btVector3 upper = -lower;
    for (const btVector3& v : settings.mesh.vertices) {
      lower.setMin(v);
      upper.setMax(v);
    }
    const btVector3 reach(contactReach, contactReach, contactReach);
    bones.push_back({MeshDistance(settings.mesh), lower - reach, upper + reach});
  }

  /// Marks the nodes that start inside a bone (the scene's rest geometry overlaps there):
  /// pushing them out by up to a voxel at once inverts their tetrahedra.
  void markStartedInside() {
    const btScalar scale = definition.lengthScale;
    for (Muscle& muscle : muscles) {
      const size_t nodes = static_cast<size_t>(muscle.body->m_nodes.size());
      muscle.startedInside.assign(nodes * bones.size(), 0);
      for (size_t n = 0; n < nodes; ++n) {
        for (size_t b = 0; b < bones.size(); ++b) {
          const btVector3 p =
              boneTransforms[b].invXform(muscle.body->m_nodes[static_cast<int>(n)].m_x / scale);
          muscle.startedInside[n * bones.size() + b] =
              bones[b].near(p) && bones[b].surface.signedDistance(p) < 0;
        }
      }
    }
  }

  /// Keeps every free node at least contactMargin outside every bone it did not start in: a
  /// node within contactReach of a bone's surface and closer than the margin (or inside) is
  /// moved to the
  /// margin along the surface normal and its velocity into the bone (relative to the bone's
  /// motion over the substep `dt`, from `previous` transforms) is removed.
  void projectNodes(std::span<const btTransform> previous, btScalar dt) {
    const btScalar scale = definition.lengthScale;
    for (Muscle& muscle : muscles) {
      for (int n = 0; n < muscle.body->m_nodes.size(); ++n) {
        btSoftBody::Node& node = muscle.body->m_nodes[n];
        if (node.m_im == 0) continue;  // pinned
        for (size_t b = 0; b < bones.size(); ++b) {
          if (muscle.startedInside[static_cast<size_t>(n) * bones.size() + b]) continue;
          const Bone& bone = bones[b];
          const btVector3 p = boneTransforms[b].invXform(node.m_x / scale);
          if (!bone.near(p)) continue;
          const MeshDistance::Closest c = bone.surface.closest(p, contactReach);
          if (c.triangle == UINT32_MAX || (!c.inside && c.distance >= contactMargin)) continue;
          const btVector3 outward = c.distance > btScalar(1e-9)
                                        ? (c.inside ? c.point - p : p - c.point) / c.distance
                                        : faceNormal(bone.surface.mesh(), c.triangle);
          const btVector3 target = c.point + outward * contactMargin;
          node.m_x = boneTransforms[b] * target * scale;
          const btVector3 normal = boneTransforms[b].getBasis() * outward;
          const btVector3 boneVelocity =
              (boneTransforms[b] * target - previous[b] * target) * (scale / dt);
          const btScalar into = (node.m_v - boneVelocity).dot(normal);
          if (into < 0) node.m_v -= normal * into;
        }
      }
    }
  }

  /// Every bone fixing particles of the muscle gets at least minPinsPerBone pinned nodes: the
  /// unpinned nodes nearest to its fixed particles.
  void pinAtLeast(const MuscleSettings& s, const TetMesh& mesh, std::vector<int32_t>& pinBone) {
    std::map<int32_t, std::vector<uint32_t>> fixedOf;  // bone → its fixed particles
    for (uint32_t p : s.fixedParticles) fixedOf[s.fixedBone[p]].push_back(p);
    for (const auto& [bone, particles] : fixedOf) {
      const auto pins = std::count(pinBone.begin(), pinBone.end(), bone);
      std::vector<std::pair<btScalar, uint32_t>> candidates;  // distance², node
      for (uint32_t n = 0; n < mesh.nodes.size(); ++n) {
        if (pinBone[n] >= 0) continue;
        btScalar nearest = std::numeric_limits<btScalar>::infinity();
        for (uint32_t p : particles)
          nearest = std::min(nearest, mesh.nodes[n].distance2(s.restPositions[p]));
        candidates.emplace_back(nearest, n);
      }
      const size_t wanted =
          static_cast<size_t>(std::max<long>(definition.minPinsPerBone - pins, 0));
      const size_t take = std::min(wanted, candidates.size());
      std::partial_sort(candidates.begin(), candidates.begin() + static_cast<long>(take),
                        candidates.end());
      for (size_t k = 0; k < take; ++k) pinBone[candidates[k].second] = bone;
      fewestPins = std::min(fewestPins, static_cast<size_t>(pins) + take);
    }
  }

  /// Each node follows its nearest particle: pinned (`pinBone`) to that particle's bone when
  /// the particle is fixed and within the attachment distance, else posed (`poseBone`) with its
  /// nearest bone; every fixed particle holds at least its nearest node.
  void assignNodeBones(const MuscleSettings& s, Muscle& muscle, std::vector<int32_t>& poseBone,
                       std::vector<int32_t>& pinBone) const {
    const TetMesh& mesh = muscle.mesh;
    const size_t nodes = mesh.nodes.size();
    const btScalar reach =
        definition.attachmentDistance > 0 ? definition.attachmentDistance : mesh.cellSize;
    poseBone.assign(nodes, -1);
    pinBone.assign(nodes, -1);
    muscle.nearestParticle.assign(nodes, 0);
    for (size_t n = 0; n < nodes; ++n) {
      btScalar nearest = std::numeric_limits<btScalar>::infinity();
      btScalar nearestFixed = std::numeric_limits<btScalar>::infinity();
      for (size_t p = 0; p < s.particleCount(); ++p) {
        const btScalar d = mesh.nodes[n].distance2(s.restPositions[p]);
        if (d < nearest) {
          nearest = d;
          muscle.nearestParticle[n] = static_cast<uint32_t>(p);
          poseBone[n] = s.fixedBone[p] >= 0 ? s.fixedBone[p] : s.nearestBone[p];
        }
        if (s.isFixed(static_cast<uint32_t>(p)) && d < nearestFixed) {
          nearestFixed = d;
          if (d <= reach * reach) pinBone[n] = s.fixedBone[p];
        }
      }
    }
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
  }

  /// Lumped masses: a quarter of every adjacent tetrahedron's mass [kg]; a pinned node's is 0
  /// and it is listed in muscle.pinned with its bone.
  std::vector<btScalar> lumpedMasses(Muscle& muscle, const std::vector<int32_t>& pinBone) const {
    const TetMesh& mesh = muscle.mesh;
    std::vector<btScalar> masses(mesh.nodes.size(), 0);
    for (const auto& t : mesh.tetrahedra) {
      const double m = definition.density *
                       tetrahedronVolume(mesh.nodes[t[0]], mesh.nodes[t[1]], mesh.nodes[t[2]],
                                         mesh.nodes[t[3]]) /
                       4;
      for (uint32_t v : t) masses[v] += static_cast<btScalar>(m);
    }
    for (size_t n = 0; n < mesh.nodes.size(); ++n) {
      if (pinBone[n] >= 0) {
        masses[n] = 0;
        muscle.pinned.push_back(static_cast<uint32_t>(n));
        muscle.pinnedBone.push_back(pinBone[n]);
      }
    }
    return masses;
  }

  /// Links along the tetrahedra's edges: the deformable solver builds its node tree from link
  /// adjacency (without links it never finishes); they carry no force here.
  static void appendEdgeLinks(const TetMesh& mesh, btSoftBody& body) {
    std::vector<std::pair<uint32_t, uint32_t>> edges;
    for (const auto& t : mesh.tetrahedra) {
      for (int a = 0; a < 4; ++a) {
        for (int b = a + 1; b < 4; ++b) edges.emplace_back(std::minmax(t[a], t[b]));
      }
    }
    std::sort(edges.begin(), edges.end());
    edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
    for (const auto& [a, b] : edges) body.appendLink(static_cast<int>(a), static_cast<int>(b));
  }

  /// The muscle's soft body from its tetrahedral mesh (scaled) and node masses, at rest, with
  /// its collision settings; not yet in the world.
  btSoftBody* makeBody(const TetMesh& mesh, const std::vector<btScalar>& masses) const {
    const btScalar scale = definition.lengthScale;
    std::vector<btVector3> scaled;
    for (const btVector3& x : mesh.nodes) scaled.push_back(x * scale);
    auto* created = new btSoftBody(&world->getWorldInfo(), static_cast<int>(mesh.nodes.size()),
                                   scaled.data(), masses.data());
    btSoftBody& body = *created;
    for (const auto& t : mesh.tetrahedra) {
      body.appendTetra(static_cast<int>(t[0]), static_cast<int>(t[1]), static_cast<int>(t[2]),
                       static_cast<int>(t[3]));
    }
    appendEdgeLinks(mesh, body);
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
    body.m_cfg.collisions = 0;  // bone contact is projectNodes
    if (definition.muscleContact) body.m_cfg.collisions |= btSoftBody::fCollision::VF_DD;
    body.m_cfg.kDF = 0;  // frictionless, as FibreMSS's response
    body.m_sleepingThreshold = 0;
    // Bullet collides deformable faces pairwise unless told not to: minutes per pose on thigh13.
    body.m_softSoftCollision = definition.muscleContact;
    body.m_useSelfCollision = false;
    return created;
  }

  void addMuscle(std::shared_ptr<const MuscleSettings> settings) {
    const MuscleSettings& s = *settings;
    Muscle muscle;
    muscle.settings = std::move(settings);
    muscle.mesh = tetrahedralize(s.restSurface, definition.mesher);
    muscle.surface = embed(muscle.mesh, s.restSurface.vertices);
    const TetMesh& mesh = muscle.mesh;
    std::vector<int32_t> poseBone, pinBone;
    assignNodeBones(s, muscle, poseBone, pinBone);
    pinAtLeast(s, mesh, pinBone);
    const std::vector<btScalar> masses = lumpedMasses(muscle, pinBone);
    muscle.body = makeBody(mesh, masses);
    // Start posed: every node moved by its nearest particle's bone.
    const btScalar scale = definition.lengthScale;
    for (size_t n = 0; n < mesh.nodes.size(); ++n) {
      if (poseBone[n] >= 0) {
        btSoftBody::Node& node = muscle.body->m_nodes[static_cast<int>(n)];
        node.m_x = boneTransforms[poseBone[n]] * mesh.nodes[n] * scale;
        node.m_q = node.m_x;
      }
    }
    world->addSoftBody(muscle.body);
    for (const Spring& spring : s.springs) {
      muscle.networkStiffness +=
          static_cast<double>(spring.stiffness) * spring.restLength * spring.restLength;
    }
    muscle.positions.resize(mesh.nodes.size());
    readPositions(muscle);
    muscles.push_back(std::move(muscle));
  }

  void readPositions(Muscle& muscle) const {
    for (size_t n = 0; n < muscle.positions.size(); ++n) {
      muscle.positions[n] = muscle.body->m_nodes[static_cast<int>(n)].m_x / definition.lengthScale;
    }
  }

  /// Free nodes moved by the bones' motion of this substep (`deltas`), each blended as its
  /// nearest particle.
  void moveFreeNodes(const Muscle& muscle) const {
    for (int n = 0; n < muscle.body->m_nodes.size(); ++n) {
      btSoftBody::Node& node = muscle.body->m_nodes[n];
      if (node.m_im > 0) {
        moveNodeWithBones(*muscle.settings, deltas, definition.pretransformBlend,
                          muscle.nearestParticle[static_cast<size_t>(n)], definition.lengthScale,
                          node);
      }
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
  m.solver->setDeformableSolver(m.deformableSolver.get());
  m.world = std::make_unique<btDeformableMultiBodyDynamicsWorld>(
      m.parts.dispatcher.get(), m.parts.broadphase.get(), m.solver.get(),
      m.parts.configuration.get(), m.deformableSolver.get());
  m.world->setGravity(btVector3(0, 0, 0));
  m.world->getWorldInfo().m_gravity.setZero();

  m.boneTransforms.assign(scene.bones.size(), btTransform::getIdentity());
  if (!boneTransforms.empty())
    m.boneTransforms.assign(boneTransforms.begin(), boneTransforms.end());
  for (const auto& muscle : scene.muscles) m.addMuscle(muscle);
  m.addElasticity();
  m.scaleMasses(definition.poseDuration / static_cast<btScalar>(definition.substepsPerPose));
  // Contact reach from the finest muscle grid: one voxel (a node moves less in a substep).
  btScalar cell = BT_LARGE_FLOAT;
  for (const Impl::Muscle& muscle : m.muscles) cell = std::min(cell, muscle.mesh.cellSize);
  m.contactMargin = std::max(definition.contactMargin, btScalar(0));
  m.contactReach = std::max(cell, 2 * m.contactMargin);
  if (definition.boneContact) {
    for (const auto& bone : scene.bones) m.addBone(*bone);
  }
  m.markStartedInside();
}

FemScene::~FemScene() = default;

bool FemScene::stepPose(std::span<const btTransform> targets, const std::function<bool()>& stop) {
  Impl& m = *impl_;
  if (targets.size() != m.boneTransforms.size()) {
    throw std::invalid_argument("FemScene::stepPose: bone transforms do not match the bones");
  }
  const int substeps = m.definition.substepsPerPose;
  const btScalar dt = m.definition.poseDuration / static_cast<btScalar>(substeps);
  const std::vector<btTransform> from = m.boneTransforms;
  std::vector<btTransform> previous = from;
  for (int k = 1; k <= substeps; ++k) {
    if (stop && stop()) return false;
    previous = m.boneTransforms;
    advanceBones(from, targets, static_cast<btScalar>(k) / static_cast<btScalar>(substeps),
                 m.boneTransforms, m.deltas);
    for (const Impl::Muscle& muscle : m.muscles) {
      if (m.definition.freeNodesFollowBones) m.moveFreeNodes(muscle);
      m.movePins(muscle);
    }
    m.world->stepSimulation(dt, 0);
    m.projectNodes(previous, dt);
  }
  // Settling: the bones stay at the targets until no node moves faster than the tolerance.
  m.lastSettleSubsteps = 0;
  while (m.fastestNode() > m.definition.settleSpeed) {
    if (m.lastSettleSubsteps == m.definition.settleSubsteps) {
      ++m.lastSettleSubsteps;  // did not settle
      break;
    }
    if (stop && stop()) return false;
    m.world->stepSimulation(dt, 0);
    m.projectNodes(m.boneTransforms, dt);
    m.dragNodes(m.definition.settleDrag);
    ++m.lastSettleSubsteps;
  }
  m.unsettledPoses += m.lastSettleSubsteps > m.definition.settleSubsteps;
  for (Impl::Muscle& muscle : m.muscles) m.readPositions(muscle);
  return true;
}

size_t FemScene::fewestPinsPerBone() const {
  return impl_->fewestPins;
}

int FemScene::unsettledPoses() const {
  return impl_->unsettledPoses;
}

size_t FemScene::muscleCount() const {
  return impl_->muscles.size();
}

size_t FemScene::nodeCount() const {
  size_t n = 0;
  for (const auto& muscle : impl_->muscles) n += muscle.positions.size();
  return n;
}

size_t FemScene::elementCount() const {
  size_t n = 0;
  for (const auto& muscle : impl_->muscles) n += muscle.mesh.tetrahedra.size();
  return n;
}

size_t FemScene::boundaryNodeCount() const {
  return 0;
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

std::vector<NodePair> FemScene::nodePairs(size_t muscle) const {
  const TetMesh& mesh = impl_->muscles.at(muscle).mesh;
  std::vector<NodePair> pairs;
  for (const auto& t : mesh.tetrahedra)
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b)
        pairs.push_back({t[a], t[b], mesh.nodes[t[a]].distance(mesh.nodes[t[b]])});
  return pairs;
}

double FemScene::springDeviation() const {
  return std::nan("");
}

long FemScene::iterationsPerPose() const {
  return impl_->definition.substepsPerPose;
}

long FemScene::substepsPerPose() const {
  return impl_->definition.substepsPerPose;
}

std::string FemScene::settings() const {
  const FemDefinition& used = impl_->definition;
  char text[320];
  std::snprintf(text, sizeof text,
                "Neo-Hookean FEM, btDeformableBodySolver (explicit elasticity, implicit damping, "
                "%d substeps per pose, then settling until no node is faster than %.3g mm/s (at "
                "most %d substeps), mass scaling +%.0f %%, at least %d pins per bone (fewest: "
                "%zu))",
                used.substepsPerPose, 1e3 * double(used.settleSpeed), used.settleSubsteps,
                100 * addedMassShare(), used.minPinsPerBone, fewestPinsPerBone());
  const int unsettled = impl_->unsettledPoses;
  return unsettled > 0 ? text + ("; " + std::to_string(unsettled) + " pose(s) did not settle")
                       : text;
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

double FemScene::addedMassShare() const {
  return impl_->addedMassShare;
}

}  // namespace fibremss
