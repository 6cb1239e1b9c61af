#pragma once
// MuscleSystem's private state (internal): body slots, scratch buffers, stats, and the step
// pipeline of method.md §5 (MuscleSystemStep.cpp).
#include <algorithm>
#include <memory>
#include <vector>

#include "CollisionPairs.h"
#include "MuscleState.h"
#include "fibremss/MuscleSystem.h"

namespace fibremss {

/// Slots with generations (Box2D style ids): a removed slot is reused with a new generation.
template <typename State>
struct Slots {
  std::vector<std::unique_ptr<State>> states;  ///< null: free slot
  std::vector<uint32_t> generations;           ///< generation of each slot
  std::vector<uint32_t> order;                 ///< occupied slots in insertion order

  template <typename Handle>
  Handle add(std::unique_ptr<State> state) {
    uint32_t slot = 0;
    while (slot < states.size() && states[slot]) ++slot;
    if (slot == states.size()) {
      states.emplace_back();
      generations.push_back(0);
    }
    states[slot] = std::move(state);
    order.push_back(slot);
    return Handle{slot, generations[slot]};
  }
  template <typename Handle>
  State* find(Handle handle) const {
    if (handle.index >= states.size() || generations[handle.index] != handle.generation)
      return nullptr;
    return states[handle.index].get();
  }
  template <typename Handle>
  void remove(Handle handle) {
    if (!find(handle)) return;
    states[handle.index].reset();
    ++generations[handle.index];
    order.erase(std::find(order.begin(), order.end(), handle.index));
  }
};

/// The private state of a MuscleSystem; the step pipeline lives in MuscleSystemStep.cpp.
struct MuscleSystem::Impl {
  SimulationParameters parameters;  ///< how to step
  StepStats stats;                  ///< what the last step did
  Slots<MuscleState> muscles;       ///< muscle states by slot
  Slots<BoneState> bones;           ///< bone states by slot
  MuscleBoneStack stack;            ///< traversal stack of muscle–bone queries
  ContactLog contacts;              ///< contacts of the last iteration, for drawing
  uint32_t musclesAdded = 0;        ///< counts additions, seeds each muscle's noise
  btScalar previousDt = 0;          ///< dt of the last iteration (0: none yet)

  MuscleState& muscle(MuscleHandle handle) const {
    MuscleState* state = muscles.find(handle);
    if (!state) throw std::out_of_range("MuscleSystem: unknown or removed muscle handle");
    return *state;
  }
  BoneState& bone(BoneHandle handle) const {
    BoneState* state = bones.find(handle);
    if (!state) throw std::out_of_range("MuscleSystem: unknown or removed bone handle");
    return *state;
  }

  void resolveBones(MuscleState& state) const;
  void placeAtBones(MuscleState& state) const;
  void pretransform(MuscleState& state, bool rotateVelocities) const;
  void followFixed(MuscleState& state) const;
  void moveBones(btScalar share, bool arrive);
  btScalar timeStep() const;
  void collide();
  void step();
};

}  // namespace fibremss
