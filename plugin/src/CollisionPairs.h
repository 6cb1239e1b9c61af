#pragma once
// Narrow phase and response of the sphere collision (method.md §6), internal: exact sphere
// tests on the leaf pairs the trees report, pushes accumulated from the starting positions and
// applied after all pairs.
#include <LinearMath/btVector3.h>

#include <vector>

#include "MuscleState.h"

namespace fibremss {

/// Ends of the contacts found in one iteration, kept for debug drawing; fixed capacity.
struct ContactLog {
  std::vector<btVector3> ends;  ///< two points per contact, allocated up front
  size_t stored = 0;            ///< contacts stored (≤ ends.size() / 2)
  size_t found = 0;             ///< contacts found, stored or not
  size_t candidates = 0;        ///< leaf pairs the broad phase reported

  void clear() { stored = found = candidates = 0; }
  void add(const btVector3& a, const btVector3& b) {
    ++found;
    if (2 * stored + 1 < ends.size()) {
      ends[2 * stored] = a;
      ends[2 * stored + 1] = b;
      ++stored;
    }
  }
};

/// Bone distance fields reach this many cells beyond the bone's bounds; beyond, the field's
/// value is an upper bound (BoneDistanceField::sample), so contacts need particle radii below.
constexpr btScalar kDistanceFieldMargin = 16;
/// Seed 001 eq 1: a bone direction that turned by more than arccos(−0.75) ≈ 139° since the
/// last iteration means the particle passed through the bone.
constexpr btScalar kFlippedSide = btScalar(-0.75);

/// Overlap of spheres (a, ra) and (b, rb): false when apart; else the unit direction from b to
/// a (+x when the centres coincide) and the overlap depth ra + rb − |a − b| > 0.
inline bool sphereOverlap(const btVector3& a, btScalar ra, const btVector3& b, btScalar rb,
                          btVector3& direction, btScalar& depth) {
  const btVector3 d = a - b;
  const btScalar reach = ra + rb;
  const btScalar distance2 = d.length2();
  if (distance2 >= reach * reach) return false;
  const btScalar distance = btSqrt(distance2);
  direction = distance > SIMD_EPSILON * reach ? d / distance : btVector3(1, 0, 0);
  depth = reach - distance;
  return true;
}

/// Refits a muscle's tree to its boundary spheres (same topology, tight bounds).
void refitTree(MuscleState& muscle);
/// Re-inserts every leaf (the thesis' rebuild each step).
void rebuildTree(MuscleState& muscle);

/// Muscle–muscle pairs of two different muscles: half the overlap each, the whole one to the
/// free particle when the other is fixed, nothing when both are fixed.
void collideMuscles(MuscleState& a, MuscleState& b, ContactLog& log);
/// Muscle–bone contacts, the whole overlap to the free particle: against the bone's spheres
/// (its tree placed at its current transform), or, when the bone has a distance field, every
/// boundary particle in the field's box is pushed out along the field's gradient to clear its
/// radius. With the muscle's side memory (penetration recovery), a particle whose direction out
/// of the bone flipped since the last iteration is pushed back out on its remembered side.
void collideMuscleBone(MuscleState& muscle, const BoneState& bone, MuscleBoneStack& stack,
                       ContactLog& log);

/// Forgets the bone sides penetration recovery remembers (after a rollback: the remembered
/// sides belong to positions that no longer exist).
void forgetBoneSides(MuscleState& muscle);

/// Moves every pushed particle by its accumulated push and removes its velocity into the push
/// (SimulationParameters::slidingContacts; else all of it: previous = position, velocities
/// zeroed when the integrator `hasVelocities`); clears the pushes. A particle two bones press from
/// opposite sides (pinched: no room between them) is moved to equal overlaps and out sideways where
/// the bones leave a way out; muscle.pinched counts such particles.
void applyPushes(MuscleState& muscle, bool hasVelocities);

}  // namespace fibremss
