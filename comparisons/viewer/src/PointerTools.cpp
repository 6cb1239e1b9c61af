#include "PointerTools.h"

#include <cmath>
#include <limits>

namespace fibremss::viewer {
namespace {

/// How far the blade's edge reaches either way along the view direction from the view plane [m]:
/// through every muscle of a scene.
constexpr btScalar kBladeReach = 1;

/// A UV sphere of `radius` [m] about the origin.
ViewMesh sphereMesh(btScalar radius) {
  constexpr int kSlices = 16, kStacks = 10;
  ViewMesh mesh;
  mesh.name = "probe";
  for (int stack = 0; stack <= kStacks; ++stack) {
    const btScalar polar = SIMD_PI * btScalar(stack) / kStacks;
    for (int slice = 0; slice < kSlices; ++slice) {
      const btScalar azimuth = SIMD_2_PI * btScalar(slice) / kSlices;
      mesh.vertices.emplace_back(radius * std::sin(polar) * std::cos(azimuth),
                                 radius * std::cos(polar),
                                 radius * std::sin(polar) * std::sin(azimuth));
    }
  }
  auto triangles = std::make_shared<Triangles>();
  for (uint32_t stack = 0; stack < kStacks; ++stack)
    for (uint32_t slice = 0; slice < kSlices; ++slice) {
      const uint32_t a = stack * kSlices + slice, b = stack * kSlices + (slice + 1) % kSlices;
      triangles->push_back({a, b, a + kSlices});
      triangles->push_back({b, b + kSlices, a + kSlices});
    }
  mesh.triangles = std::move(triangles);
  return mesh;
}

}  // namespace

const char* toolName(ToolMode mode) {
  switch (mode) {
    case ToolMode::Grab:
      return "grab";
    case ToolMode::Probe:
      return "probe";
    case ToolMode::Blade:
      return "blade";
    case ToolMode::Camera:
      break;
  }
  return "camera";
}

ToolMode nextTool(ToolMode mode) {
  switch (mode) {
    case ToolMode::Camera:
      return ToolMode::Grab;
    case ToolMode::Grab:
      return ToolMode::Probe;
    case ToolMode::Probe:
      return ToolMode::Blade;
    case ToolMode::Blade:
      break;
  }
  return ToolMode::Camera;
}

PointerTools::PointerTools(MuscleWorld& world, btScalar probeRadius)
    : world_(world), probeShape_(probeRadius), probeMesh_(sphereMesh(probeRadius)) {
  probe_ = std::make_unique<btRigidBody>(
      btRigidBody::btRigidBodyConstructionInfo(0, nullptr, &probeShape_));
  probe_->setCollisionFlags(probe_->getCollisionFlags() | btCollisionObject::CF_KINEMATIC_OBJECT);
  probe_->setActivationState(DISABLE_DEACTIVATION);
}

PointerTools::~PointerTools() {
  removeProbe();
}

void PointerTools::setMuscles(std::vector<MuscleHandle> muscles) {
  grabbed_ = MuscleHandle();
  pull_.setZero();
  muscles_ = std::move(muscles);
}

void PointerTools::apply(ToolMode mode, const PointerRay& ray) {
  if (mode != mode_) {
    release();
    if (mode != ToolMode::Probe) removeProbe();
    mode_ = mode;
    held_ = false;
  }
  if (mode == ToolMode::Camera) return;
  if (ray.held && !held_) press(ray);
  if (ray.held) drag(onPlane(ray));
  if (!ray.held && held_) release();
  held_ = ray.held;
}

ToolReading PointerTools::reading() const {
  ToolReading reading;
  reading.mode = mode_;
  reading.engaged = grabbed_.valid() || probeInWorld_;
  if (grabbed_.valid()) reading.force = pull_;
  for (MuscleHandle muscle : muscles_)
    reading.cutSprings += world_.muscleSystem().tear(muscle).cutSprings;
  if (!probeInWorld_) return reading;
  const ContactWrench wrench = world_.contactWrench(*probe_);
  reading.force = wrench.force;
  reading.contacts = wrench.contacts;
  return reading;
}

void PointerTools::press(const PointerRay& ray) {
  planeNormal_ = ray.direction;
  planePoint_ = ray.planePoint;
  if (mode_ == ToolMode::Probe) {
    if (!probeInWorld_) world_.addRigidBody(probe_.get());
    probeInWorld_ = true;
    return;
  }
  if (mode_ == ToolMode::Blade) {
    // A new blade where the pointer pressed: the last one stays where it was let go (a blade
    // that does not move cuts nothing), so the pointer's jump between presses cuts nothing.
    btTransform pose = btTransform::getIdentity();
    pose.setOrigin(onPlane(ray));
    blade_ = world_.muscleSystem().addBlade(-kBladeReach * planeNormal_, kBladeReach * planeNormal_,
                                            pose);
    return;
  }
  // Grab: the free particle nearest the ray, within twice its radius of it.
  btScalar nearest = std::numeric_limits<btScalar>::infinity();
  const MuscleSystem& system = world_.muscleSystem();
  for (MuscleHandle muscle : muscles_) {
    const MuscleSettings& settings = system.settings(muscle);
    const std::span<const btVector3> x = system.positions(muscle);
    for (uint32_t i = 0; i < x.size(); ++i) {
      const btVector3 offset = x[i] - ray.origin;
      const btScalar distance = (offset - ray.direction * offset.dot(ray.direction)).length();
      if (settings.isFixed(i) || distance > 2 * settings.radii[i] || distance >= nearest) continue;
      nearest = distance;
      grabbed_ = muscle;
      grabbedParticle_ = i;
      planePoint_ = x[i];
    }
  }
  if (!grabbed_.valid()) return;
  grabStiffness_ = 0;
  for (const Spring& spring : system.settings(grabbed_).springs)
    if (spring.a == grabbedParticle_ || spring.b == grabbedParticle_)
      grabStiffness_ += spring.stiffness;
}

void PointerTools::drag(const btVector3& target) {
  if (mode_ == ToolMode::Probe) {
    btTransform pose = btTransform::getIdentity();
    pose.setOrigin(target);
    probe_->setWorldTransform(pose);
    probe_->setInterpolationWorldTransform(pose);
    probeMesh_.transform = pose;
    return;
  }
  if (mode_ == ToolMode::Blade) {
    btTransform pose = btTransform::getIdentity();
    pose.setOrigin(target);
    if (blade_.valid()) world_.muscleSystem().setBladeTransform(blade_, pose);
    return;
  }
  if (!grabbed_.valid()) return;
  MuscleSystem& system = world_.muscleSystem();
  pull_ = (target - system.positions(grabbed_)[grabbedParticle_]) * grabStiffness_;
  system.setExternalForce(grabbed_, grabbedParticle_, pull_);
}

void PointerTools::release() {
  if (grabbed_.valid()) world_.muscleSystem().clearExternalForces(grabbed_);
  grabbed_ = MuscleHandle();
  pull_.setZero();
}

void PointerTools::removeProbe() {
  if (probeInWorld_) world_.removeRigidBody(probe_.get());
  probeInWorld_ = false;
}

btVector3 PointerTools::onPlane(const PointerRay& ray) const {
  const btScalar along = ray.direction.dot(planeNormal_);
  if (std::abs(along) < btScalar(1e-6)) return planePoint_;
  return ray.origin + ray.direction * ((planePoint_ - ray.origin).dot(planeNormal_) / along);
}

}  // namespace fibremss::viewer
