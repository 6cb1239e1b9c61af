#pragma once
// The numerical guard of a MuscleSystem step (internal; MuscleSystemDef::onFailure): the
// last good state of a muscle (saved at the start of every step, restored after a failed one)
// and the per-muscle check that attributes a failed step to the muscles that failed.
#include <cstddef>
#include <memory>
#include <span>

#include "state/MuscleState.h"

namespace fibremss {

/// What a muscle's state looks like; checked only after a step that reported a failure.
struct MuscleHealth {
  bool nan = false;            ///< a position, previous position or velocity is NaN or inf
  size_t explodedSprings = 0;  ///< springs counted as exploded (see checkMuscle)
  /// Of those, the springs whose ends two different bones pushed in the step (ContactState::
  /// stepBones) and grew in it by no more than those bones moved apart at its ends: their length
  /// is the bones' motion, not the solver's.
  size_t spannedSprings = 0;
  /// The particles' bounding box is more than kTornSpread times as large (diagonal) as at rest:
  /// diverging, not merely torn.
  bool spread = false;
  bool failed() const { return nan || explodedSprings > 0; }
};

/// Times its rest extent (bounding-box diagonal) a muscle may grow before it counts as diverging:
/// a torn muscle stays between its bones, a diverging one grows without bound.
constexpr double kTornSpread = 2;

/// NaN/inf scan of the particles, their extent and the spring lengths of `muscle`. A spring
/// counts as exploded when it is longer than 3× its rest length and longer than its rest length
/// by more than the muscle's mean rest length: the 3× rule alone trips on springs of a few µm
/// (converging fibre ends, jittered neighbours) whose stretch is harmless.
/// A muscle torn into pieces (Tearing.h) is spread when one of its pieces is. `contact` names the
/// bones that pushed each particle in the step, `start` holds the positions at its start and
/// `bones` (by slot) their transforms there and now (spannedSprings).
MuscleHealth checkMuscle(const MuscleSettings& settings, const ParticleState& muscle,
                         const ContactState& contact, const GuardSnapshot& start,
                         std::span<const std::unique_ptr<BoneState>> bones, TearState& tear);

/// Copies positions, previous and velocities of `muscle` into its good-state buffers `good`.
void saveGoodState(const ParticleState& muscle, GuardSnapshot& good);
/// Restores positions, previous and velocities saved by saveGoodState and forgets the sides of
/// the bones the contact stage saw the particles on (they may have been lost in the step).
void restoreGoodState(const GuardSnapshot& good, ParticleState& muscle, ContactState& contact);

}  // namespace fibremss
