#pragma once
// The private state of a MuscleSystem for tools inside the project (the kernel benchmarks in
// comparisons/bench time one kernel at a time on the states a real system prepared).
#include "MuscleSystemImpl.h"

namespace fibremss {

struct MuscleSystemAccess {
  using Impl = MuscleSystem::Impl;  ///< the private state's type, nameable through this friend
  /// The system's private state.
  static Impl& impl(MuscleSystem& system) { return *system.impl_; }
  static const Impl& impl(const MuscleSystem& system) { return *system.impl_; }
};

}  // namespace fibremss
