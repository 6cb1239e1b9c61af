#include "BenchScene.h"

#include <string>

#include "dynamics/TimeStep.h"
#include "fibremss/Preparation.h"
#include "fibremss/SceneSystem.h"
#include "integrators/Integrators.h"
#include "kernels/VolumeForces.h"

namespace fibremss::bench {

const char* partName(Part part) {
  switch (part) {
    case Part::SpringForces:
      return "spring-forces";
    case Part::VolumeForces:
      return "volume-forces";
    case Part::AdaptiveTimeStep:
      return "adaptive-dt";
    case Part::Integration:
      return "integration";
    case Part::TreeRefit:
      return "tree-refit";
    case Part::MuscleMusclePairs:
      return "muscle-muscle-pairs";
    case Part::MuscleBonePairs:
      return "muscle-bone-pairs";
    case Part::Response:
      return "response";
  }
  return "?";
}

BenchScene::BenchScene(int resolution, int threads, Integrator integrator)
    : scene_(loadScene("thigh13", {"resolution=" + std::to_string(resolution),
                                   "threads=" + std::to_string(threads),
                                   std::string("integrator=") + toString(integrator)})) {
  const PreparedScene prepared = prepareScene(scene_);
  system_ = std::make_unique<MuscleSystem>(scene_.simulation);
  bones_ = addScene(*system_, prepared).bones;
  for (const auto& muscle : prepared.muscles) particles_ += muscle->particleCount();
  impl_ = &MuscleSystemAccess::impl(*system_);
  stepPose();
  dt_ = system_->stepSettings().timeStep;
}

void BenchScene::stepPose() {
  pose_ = scene_.poseCount > 1 ? 1 - pose_ : 0;
  for (size_t b = 0; b < bones_.size(); ++b)
    system_->setBoneTransform(bones_[b], scene_.bonePose(b, pose_));
  system_->step();
}

void BenchScene::countIterations(int iterations) {
  StepSettings settings = system_->stepSettings();
  settings.stopRule = StopRule::Iterations;
  settings.iterations = iterations;
  system_->setStepSettings(settings);
}

void BenchScene::run(Part part) {
  MuscleSystemAccess::Impl& impl = *impl_;
  const MuscleSystemDef& def = impl.definition;
  const StepSettings& step = impl.stepSettings;
  const TimeIntegrator& integrator = integratorFor(def.integrator);
  switch (part) {
    case Part::SpringForces:
      for (uint32_t slot : impl.muscles.order) {
        MuscleState& state = *impl.muscles.states[slot];
        springForces(*state.settings, state);
      }
      break;
    case Part::VolumeForces:
      for (uint32_t slot : impl.muscles.order) {
        MuscleState& state = *impl.muscles.states[slot];
        addLocalVolumeForces(*state.settings, state.positions, state.forces);
      }
      break;
    case Part::AdaptiveTimeStep:
      dt_ = step.timeStep;
      for (uint32_t slot : impl.muscles.order) {
        const MuscleState& state = *impl.muscles.states[slot];
        if (step.adaptiveTimeStep)
          dt_ = std::min(dt_, adaptiveTimeStep(*state.settings, state, state.centredDamping(),
                                               impl.previousDt));
      }
      dt_ = std::max(dt_, step.minTimeStep);
      break;
    case Part::Integration:
      for (uint32_t slot : impl.muscles.order)
        integrator.advance(impl.muscles.states[slot]->integrated(false), def, dt_, impl.previousDt);
      impl.previousDt = dt_;
      break;
    case Part::TreeRefit:
      for (uint32_t slot : impl.muscles.order) {
        MuscleState& state = *impl.muscles.states[slot];
        refitTree(*state.settings, state, state);
      }
      break;
    case Part::MuscleMusclePairs:
      impl.collideMusclePairs();
      for (uint32_t slot : impl.muscles.order) {
        MuscleState& state = *impl.muscles.states[slot];
        impl.pushMusclePairs(state, state, slot, impl.scratch[0].stack);
      }
      for (ThreadScratch& thread : impl.scratch) thread.contacts.clear();
      break;
    case Part::MuscleBonePairs:
      for (uint32_t muscle : impl.muscles.order) {
        MuscleState& state = *impl.muscles.states[muscle];
        for (uint32_t bone : impl.bones.order)
          collideMuscleBone(*state.settings, state, state, state, *impl.bones.states[bone],
                            impl.scratch[0].stack, impl.contacts);
      }
      break;
    case Part::Response:
      for (uint32_t slot : impl.muscles.order) {
        MuscleState& state = *impl.muscles.states[slot];
        applyPushes(*state.settings, state, state, integrator.usesVelocities(),
                    def.slidingContacts);
      }
      break;
  }
}

}  // namespace fibremss::bench
