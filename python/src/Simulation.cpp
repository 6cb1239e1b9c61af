#include "Simulation.h"

#include <pybind11/pybind11.h>

#include <string>
#include <utility>

#include "fibremss/SceneSystem.h"

namespace fibremss::python {
namespace {

/// The scene with `threads` in place of its own when given.
LoadedScene withThreads(LoadedScene scene, std::optional<int> threads) {
  if (threads) scene.simulation.threads = *threads;
  return scene;
}

}  // namespace

Simulation::Simulation(LoadedScene scene, std::optional<int> threads)
    : scene_(withThreads(std::move(scene), threads)),
      prepared_(prepareScene(scene_)),
      system_(scene_.simulation) {
  SceneHandles handles = addScene(system_, prepared_);
  bones_ = std::move(handles.bones);
  muscles_ = std::move(handles.muscles);
  for (const auto& bone : prepared_.bones) boneMeshes_.emplace_back(bone->mesh);
}

void Simulation::setPose(int pose) {
  if (pose < 0 || pose >= scene_.poseCount)
    throw pybind11::index_error("pose " + std::to_string(pose) + " of a scene with " +
                                std::to_string(scene_.poseCount) + " poses");
  for (size_t b = 0; b < bones_.size(); ++b)
    system_.setBoneTransform(bones_[b], scene_.bonePose(b, pose));
  pose_ = pose;
}

const StepStats& Simulation::step(std::optional<double> duration) {
  if (duration)
    system_.step(static_cast<btScalar>(*duration));
  else
    system_.step();
  time_ += system_.lastStep().simulatedTime;
  ++steps_;
  return system_.lastStep();
}

std::vector<SeriesRow> Simulation::measure() {
  std::vector<const MeshDistance*> meshes;
  std::vector<btTransform> transforms;
  for (size_t b = 0; b < bones_.size(); ++b) {
    meshes.push_back(&boneMeshes_[b]);
    transforms.push_back(system_.boneTransform(bones_[b]));
  }
  system_.forceResidual();
  std::vector<SeriesRow> rows;
  for (MuscleHandle muscle : muscles_) {
    SeriesRow& row = rows.emplace_back();
    row.step = steps_ - 1;
    row.pose = pose_;
    row.poseLabel =
        size_t(pose_) < scene_.poseLabels.size() ? scene_.poseLabels[size_t(pose_)] : double(pose_);
    row.timeS = time_;
    row.muscle = system_.settings(muscle).name;
    row.solverContacts = system_.lastStep().contacts;
    row.measures = measureMuscle(system_.settings(muscle), system_.positions(muscle),
                                 system_.surface(muscle), meshes, transforms);
    if (!row.measures.finite) continue;
    const ForceResidual residual = system_.lastForceResidual(muscle);
    row.measures.residualRmsMm = 1000 * residual.rmsDisplacement;
    row.measures.residualMaxMm = 1000 * residual.maxDisplacement;
  }
  return rows;
}

}  // namespace fibremss::python
