#include "fibremss/SoftBodyBuilder.h"

#include <BulletDynamics/ConstraintSolver/btSequentialImpulseConstraintSolver.h>
#include <BulletSoftBody/btSoftRigidDynamicsWorld.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numeric>
#include <stdexcept>

#include "SoftBodyBones.h"
#include "fibremss/BoneBody.h"
#include "fibremss/Measures.h"

namespace fibremss {
namespace {

/// Lloyd iterations of the cluster k-means (a fixed count: the same clusters on every machine).
constexpr int kClusterPasses = 16;

/// True when a precedes b in (x, y, z) order: a node order that does not depend on indices.
bool positionBefore(const btSoftBody::Node* a, const btSoftBody::Node* b) {
  if (a->m_x.x() != b->m_x.x()) return a->m_x.x() < b->m_x.x();
  if (a->m_x.y() != b->m_x.y()) return a->m_x.y() < b->m_x.y();
  return a->m_x.z() < b->m_x.z();
}

/// Soft–soft collision clusters of the free nodes: k-means from farthest-point seeds over the
/// nodes sorted by position, so compact and independent of the node order. Bullet's own
/// generateClusters seeds its k-means by node index: once preparation numbered particles along
/// a Morton curve, its clusters pushed thigh13's muscles apart at rest (a link at 4.2×; with
/// these clusters and the rest-gap margin below, 1.12×). Pinned nodes stay
/// out: Bullet weighs a mass-0 node as BT_LARGE_FLOAT (1e18), in float the cluster's inverse
/// inertia is NaN and CL_SS spreads it. Clusters of fewer than four nodes (no inertia) are
/// dropped.
void freeNodeClusters(btSoftBody& body, int count) {
  std::vector<btSoftBody::Node*> nodes;
  for (int i = 0; i < body.m_nodes.size(); ++i) {
    if (body.m_nodes[i].m_im > 0) nodes.push_back(&body.m_nodes[i]);
  }
  std::sort(nodes.begin(), nodes.end(), positionBefore);
  const size_t k = std::min(nodes.size(), static_cast<size_t>(std::max(count, 0)));
  if (k == 0) return;
  std::vector<btVector3> centres{nodes.front()->m_x};
  std::vector<btScalar> nearest(nodes.size());
  for (size_t j = 0; j < nodes.size(); ++j) nearest[j] = nodes[j]->m_x.distance2(centres[0]);
  while (centres.size() < k) {
    const auto farthest = std::max_element(nearest.begin(), nearest.end()) - nearest.begin();
    centres.push_back(nodes[static_cast<size_t>(farthest)]->m_x);
    for (size_t j = 0; j < nodes.size(); ++j) {
      nearest[j] = std::min(nearest[j], nodes[j]->m_x.distance2(centres.back()));
    }
  }
  std::vector<size_t> owner(nodes.size());
  std::vector<btVector3> sums(k);
  std::vector<int> sizes(k);
  for (int pass = 0;; ++pass) {
    for (size_t j = 0; j < nodes.size(); ++j) {
      btScalar best = BT_LARGE_FLOAT;
      for (size_t c = 0; c < k; ++c) {
        const btScalar d = nodes[j]->m_x.distance2(centres[c]);
        if (d < best) {
          best = d;
          owner[j] = c;
        }
      }
    }
    if (pass == kClusterPasses) break;
    std::fill(sums.begin(), sums.end(), btVector3(0, 0, 0));
    std::fill(sizes.begin(), sizes.end(), 0);
    for (size_t j = 0; j < nodes.size(); ++j) {
      sums[owner[j]] += nodes[j]->m_x;
      ++sizes[owner[j]];
    }
    for (size_t c = 0; c < k; ++c) {
      if (sizes[c] > 0) centres[c] = sums[c] / static_cast<btScalar>(sizes[c]);
    }
  }
  for (size_t c = 0; c < k; ++c) {
    if (std::count(owner.begin(), owner.end(), c) < 4) continue;
    auto* cluster = new (btAlignedAlloc(sizeof(btSoftBody::Cluster), 16)) btSoftBody::Cluster();
    cluster->m_collide = true;
    cluster->m_clusterIndex = body.m_clusters.size();
    for (size_t j = 0; j < nodes.size(); ++j) {
      if (owner[j] == c) cluster->m_nodes.push_back(nodes[j]);
    }
    body.m_clusters.push_back(cluster);  // freed by the body (releaseClusters)
  }
  body.initializeClusters();
  body.updateClusters();
}

/// Spring indices from the softest to the stiffest (FibreMSS's k = κ/L0; ties by index).
/// Bullet solves links Gauss–Seidel in this order, and those solved last end each sweep
/// satisfied. At the baseline's substep every link of thigh13 saturates (2k·dt²/m = 200 to
/// 10 000, so m_kLST = 1 for all): Bullet weighs a 0.08 mm link like a 3 mm one that FibreMSS
/// makes 40× softer, and unless it comes last the short link takes the stretch. In fibre
/// order a 0.078 mm link of muscle 1 at resolution 40 grew by 0.04× per substep and passed 3×
/// at pose 3, with every collision off too and with 32 iterations or 40 substeps alike; solved
/// stiffest last, no link passed 1.5× over the 13 poses.
std::vector<uint32_t> linksSoftestFirst(const MuscleSettings& muscle) {
  std::vector<uint32_t> order(muscle.springs.size());
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(), [&](uint32_t x, uint32_t y) {
    return muscle.springs[x].stiffness < muscle.springs[y].stiffness;
  });
  return order;
}

/// Mean radius of the muscle's boundary particles (its collision spheres) [m].
double meanBoundaryRadius(const MuscleSettings& muscle) {
  double sum = 0;
  for (uint32_t i : muscle.boundaryParticles) sum += muscle.radii[i];
  return muscle.boundaryParticles.empty()
             ? 0
             : sum / static_cast<double>(muscle.boundaryParticles.size());
}

/// Per muscle, the smallest distance from one of its boundary particles to a boundary particle
/// of another muscle at the poses `boneTransforms` (`reach` when none is nearer), by a sweep
/// along x.
std::vector<double> restGaps(const PreparedScene& scene,
                             std::span<const btTransform> boneTransforms, double reach) {
  struct Point {
    btVector3 x;
    size_t muscle;
  };
  std::vector<Point> points;
  for (size_t m = 0; m < scene.muscles.size(); ++m) {
    const std::vector<btVector3> posed = posedParticles(*scene.muscles[m], boneTransforms);
    for (uint32_t i : scene.muscles[m]->boundaryParticles) points.push_back({posed[i], m});
  }
  std::sort(points.begin(), points.end(),
            [](const Point& a, const Point& b) { return a.x.x() < b.x.x(); });
  std::vector<double> gaps(scene.muscles.size(), reach);
  for (size_t a = 0; a < points.size(); ++a) {
    for (size_t b = a + 1; b < points.size() && points[b].x.x() - points[a].x.x() < reach; ++b) {
      if (points[a].muscle == points[b].muscle) continue;
      const double d = points[a].x.distance(points[b].x);
      gaps[points[a].muscle] = std::min(gaps[points[a].muscle], d);
      gaps[points[b].muscle] = std::min(gaps[points[b].muscle], d);
    }
  }
  return gaps;
}

/// The most particles on one fibre of the scene (its resolution).
uint32_t particlesPerFibre(const PreparedScene& scene) {
  uint32_t most = 0;
  for (const auto& muscle : scene.muscles)
    for (size_t f = 0; f < muscle->fibreCount(); ++f)
      most = std::max(most, muscle->fibreOffsets[f + 1] - muscle->fibreOffsets[f]);
  return most;
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

int substepsFor(const PreparedScene& scene) {
  return std::max(1, static_cast<int>((particlesPerFibre(scene) + 3) / 4));
}

int iterationsFor(const PreparedScene& scene) {
  return std::max(1, static_cast<int>((2 * particlesPerFibre(scene) + 4) / 5));
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

  /// `restGap`: from the muscle's boundary particles to the nearest other muscle's [m].
  void addMuscle(std::shared_ptr<const MuscleSettings> settings, double restGap) {
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
    for (uint32_t i : linksSoftestFirst(s)) {
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
    body.m_cfg.kDF = 0;   // frictionless, as FibreMSS's response and the CalculiX reference
    body.m_cfg.collisions = 0;
    if (definition.boneCollision) body.m_cfg.collisions |= btSoftBody::fCollision::SDF_RS;
    if (definition.softSoftCollision) {
      body.m_cfg.collisions |= btSoftBody::fCollision::CL_SS;
      freeNodeClusters(body, definition.clustersPerMuscle);
    }
    // Collision margin: the mean radius of the colliding particles (FibreMSS's spheres), at
    // most half the rest gap to the nearest other muscle: thigh13's muscles lie 0.6–2.5 mm
    // apart against 2–4 mm radii, and margins that overlap at rest push them apart at once.
    const double margin = std::min(meanBoundaryRadius(s), 0.5 * restGap);
    body.getCollisionShape()->setMargin(
        static_cast<btScalar>(std::max(margin, 1e-4) * definition.lengthScale));
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
        moveNodeWithBones(s, deltas, definition.pretransformBlend, i, scale,
                          muscle.body->m_nodes[static_cast<int>(i)]);
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
  if (definition.substepsPerPose < 0 || definition.positionIterations < 0 ||
      definition.poseDuration <= 0 || definition.lengthScale <= 0) {
    throw std::invalid_argument(
        "SoftBodyScene: substepsPerPose and positionIterations must be >= 0, poseDuration and "
        "lengthScale > 0");
  }
  Impl& m = *impl_;
  m.definition = definition;
  if (m.definition.substepsPerPose == 0) m.definition.substepsPerPose = substepsFor(scene);
  if (m.definition.positionIterations == 0) m.definition.positionIterations = iterationsFor(scene);
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
  // Gaps wider than twice the largest margin limit no margin.
  double reach = 0;
  for (const auto& muscle : scene.muscles) reach = std::max(reach, 2 * meanBoundaryRadius(*muscle));
  const std::vector<double> gaps = restGaps(scene, m.boneTransforms, reach);
  for (size_t i = 0; i < scene.muscles.size(); ++i) m.addMuscle(scene.muscles[i], gaps[i]);
}

SoftBodyScene::~SoftBodyScene() = default;

bool SoftBodyScene::stepPose(std::span<const btTransform> targets, const std::function<bool()>&) {
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
  return true;
}

size_t SoftBodyScene::muscleCount() const {
  return impl_->muscles.size();
}

size_t SoftBodyScene::nodeCount() const {
  size_t n = 0;
  for (const auto& muscle : impl_->muscles) n += muscle.positions.size();
  return n;
}

size_t SoftBodyScene::elementCount() const {
  return impl_->links;
}

size_t SoftBodyScene::boundaryNodeCount() const {
  size_t n = 0;
  for (const auto& muscle : impl_->muscles) n += muscle.settings->boundaryParticles.size();
  return n;
}

std::span<const btVector3> SoftBodyScene::nodePositions(size_t muscle) const {
  return impl_->muscles.at(muscle).positions;
}

void SoftBodyScene::surface(size_t muscle, std::vector<btVector3>& out) const {
  const auto& m = impl_->muscles.at(muscle);
  skinSurface(*m.settings, m.positions, impl_->boneTransforms, out);
}

std::vector<NodePair> SoftBodyScene::nodePairs(size_t muscle) const {
  std::vector<NodePair> pairs;
  for (const Spring& s : impl_->muscles.at(muscle).settings->springs)
    pairs.push_back({s.a, s.b, s.restLength});
  return pairs;
}

double SoftBodyScene::springDeviation() const {
  double deviation = 0, restLengths = 0;
  for (const auto& muscle : impl_->muscles) {
    double lengths = 0;
    for (const Spring& s : muscle.settings->springs) {
      lengths += s.restLength;
      restLengths += s.restLength;
    }
    if (lengths > 0)
      deviation += lengths * springDeviationRatio(muscle.settings->springs, muscle.positions);
  }
  return restLengths > 0 ? deviation / restLengths : std::nan("");
}

long SoftBodyScene::iterationsPerPose() const {
  return static_cast<long>(impl_->definition.substepsPerPose) *
         impl_->definition.positionIterations;
}

long SoftBodyScene::substepsPerPose() const {
  return impl_->definition.substepsPerPose;
}

std::string SoftBodyScene::settings() const {
  const SoftBodyDefinition& used = impl_->definition;
  char text[200];
  std::snprintf(text, sizeof text,
                "btSoftBody position solver (%d substeps × %d link iterations per pose, links "
                "softest first, %d clusters per muscle × %d iterations)",
                used.substepsPerPose, used.positionIterations, used.clustersPerMuscle,
                used.clusterIterations);
  return text;
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
