#include "LiveScene.h"

#include <algorithm>
#include <cstdio>

#include "fibremss/Messages.h"
#include "fibremss/SceneSystem.h"

namespace fibremss::viewer {
namespace {

/// Bullet's time step per viewer step [s] (rigid bodies only: the muscles take their own dt).
const btScalar kTimeStep = btScalar(1.0 / 60);
/// The pointer's probe: a sphere of this radius [m].
const btScalar kProbeRadius = btScalar(5e-3);

/// Per particle: the mean over the fibre segments it ends of current / rest length.
void fibreStretch(const MuscleSettings& muscle, std::span<const btVector3> x,
                  const std::vector<float>& segments, std::vector<float>& stretch) {
  std::fill(stretch.begin(), stretch.end(), 0.0f);
  for (size_t f = 0; f < muscle.fibreCount(); ++f)
    for (uint32_t k = muscle.fibreOffsets[f] + 1; k < muscle.fibreOffsets[f + 1]; ++k) {
      const uint32_t a = muscle.fibreParticles[k - 1], b = muscle.fibreParticles[k];
      const btScalar rest = muscle.restPositions[a].distance(muscle.restPositions[b]);
      if (rest <= 0) continue;
      const float ratio = static_cast<float>(x[a].distance(x[b]) / rest);
      stretch[a] += ratio / segments[a];
      stretch[b] += ratio / segments[b];
    }
  for (size_t p = 0; p < stretch.size(); ++p)
    if (segments[p] == 0) stretch[p] = 1;
}

/// Per particle: the number of fibre segments (of nonzero rest length) it ends.
std::vector<float> fibreSegmentCounts(const MuscleSettings& muscle) {
  std::vector<float> counts(muscle.particleCount(), 0.0f);
  for (size_t f = 0; f < muscle.fibreCount(); ++f)
    for (uint32_t k = muscle.fibreOffsets[f] + 1; k < muscle.fibreOffsets[f + 1]; ++k) {
      const uint32_t a = muscle.fibreParticles[k - 1], b = muscle.fibreParticles[k];
      if (muscle.restPositions[a].distance(muscle.restPositions[b]) <= 0) continue;
      counts[a] += 1;
      counts[b] += 1;
    }
  return counts;
}

/// A per-particle value carried to the surface vertices by the skinning weights.
void skinned(const MuscleSettings& muscle, const std::vector<float>& perParticle,
             std::vector<float>& perVertex) {
  const size_t n = static_cast<size_t>(muscle.skinNeighbours);
  for (size_t v = 0; v < perVertex.size(); ++v) {
    double sum = 0;
    for (size_t k = 0; k < n; ++k)
      sum += double(muscle.skinWeights[v * n + k]) * perParticle[muscle.skinParticles[v * n + k]];
    perVertex[v] = static_cast<float>(sum);
  }
}

}  // namespace

LiveScene::LiveScene(const std::string& scene, const std::vector<std::string>& overrides)
    : scene_(loadScene(scene, overrides)) {
  printWarnings(scene_.warnings);
  printNotes(scene_.notes);
  std::fprintf(stderr, "preparing %s ...\n", scene_.name.c_str());
  prepared_ = prepareScene(scene_);
  printWarnings(prepared_.report.warnings);
  printWarnings(attachmentWarnings(scene_, prepared_));

  dispatcher_ = std::make_unique<btCollisionDispatcher>(&configuration_);
  world_ = std::make_unique<MuscleWorld>(dispatcher_.get(), &broadphase_, &solver_, &configuration_,
                                         scene_.simulation);
  world_->setGravity(btVector3(0, 0, 0));
  WorldScene added = addScene(*world_, scene_, prepared_);
  boneBodies_ = std::move(added.bodies);
  bones_ = std::move(added.handles.bones);
  muscles_ = std::move(added.handles.muscles);
  tools_ = std::make_unique<PointerTools>(*world_, kProbeRadius);
  tools_->setMuscles(muscles_);
  for (size_t b = 0; b < prepared_.bones.size(); ++b) {
    ViewMesh mesh;
    mesh.name = prepared_.bones[b]->name;
    mesh.vertices = prepared_.bones[b]->mesh.vertices;
    mesh.triangles = std::make_shared<const Triangles>(prepared_.bones[b]->mesh.triangles);
    frame_.bones.push_back(std::move(mesh));
  }
  for (const auto& muscle : prepared_.muscles) {
    fibreSegments_.push_back(fibreSegmentCounts(*muscle));
    particleStretch_.emplace_back(muscle->particleCount());
    ViewMesh mesh;
    mesh.name = muscle->name;
    mesh.triangles = std::make_shared<const Triangles>(muscle->restSurface.triangles);
    const size_t vertices = muscle->restSurface.vertices.size();
    mesh.arrays = {{"muscle_id", std::vector<float>(vertices, float(frame_.muscles.size()))},
                   {"fibre_stretch", std::vector<float>(vertices, 1.0f)},
                   {"displacement", std::vector<float>(vertices, 0.0f)}};
    frame_.muscles.push_back(std::move(mesh));
  }
  frame_.lengthUnit = scene_.unitScale == 0.001 ? "mm" : "m";
  updateFrame();
}

LiveScene::~LiveScene() {
  for (MuscleHandle muscle : muscles_) world_->removeMuscle(muscle);
  for (BoneHandle bone : bones_) world_->removeBone(bone);
}

void LiveScene::reset() {
  for (MuscleHandle muscle : muscles_) world_->removeMuscle(muscle);
  muscles_.clear();
  for (size_t b = 0; b < boneBodies_.size(); ++b)
    boneBodies_[b]->setTransform(scene_.bonePose(b, 0));
  world_->stepSimulation(kTimeStep, 0);  // no muscles: only the bones go back to the first pose
  muscles_ = addMuscles(*world_, prepared_, bones_);
  tools_->setMuscles(muscles_);
  pose_ = shownPose_ = steps_ = 0;
  direction_ = 1;
  updateFrame();
}

void LiveScene::setPose(int pose) {
  pose_ = std::clamp(pose, 0, std::max(scene_.poseCount, 1) - 1);
}

void LiveScene::applyPointer(ToolMode mode, const PointerRay& ray) {
  tools_->apply(mode, ray);
  frame_.tools.clear();
  if (const ViewMesh* probe = tools_->probeMesh()) frame_.tools.push_back(*probe);
}

void LiveScene::step() {
  for (size_t b = 0; b < boneBodies_.size(); ++b)
    boneBodies_[b]->setTransform(scene_.bonePose(b, pose_));
  world_->stepSimulation(kTimeStep, 0);
  ++steps_;
  shownPose_ = pose_;
  updateFrame();
  const int last = std::max(scene_.poseCount, 1) - 1;
  if (last == 0) return;
  if (!loop) direction_ = 1;
  if (loop && (pose_ + direction_ < 0 || pose_ + direction_ > last)) direction_ = -direction_;
  setPose(pose_ + direction_);
}

void LiveScene::updateFrame() {
  const MuscleSystem& system = world_->muscleSystem();
  for (size_t b = 0; b < bones_.size(); ++b)
    frame_.bones[b].transform = boneBodies_[b]->transform();
  for (size_t m = 0; m < muscles_.size(); ++m) {
    const MuscleSettings& muscle = *prepared_.muscles[m];
    std::span<const btVector3> surface = system.surface(muscles_[m]);
    ViewMesh& mesh = frame_.muscles[m];
    mesh.vertices.assign(surface.begin(), surface.end());
    fibreStretch(muscle, system.positions(muscles_[m]), fibreSegments_[m], particleStretch_[m]);
    skinned(muscle, particleStretch_[m], mesh.arrays[1].second);
    std::vector<float>& displacement = mesh.arrays[2].second;
    for (size_t v = 0; v < surface.size(); ++v)
      displacement[v] = static_cast<float>(surface[v].distance(muscle.restSurface.vertices[v]) /
                                           scene_.unitScale);
  }
}

}  // namespace fibremss::viewer
