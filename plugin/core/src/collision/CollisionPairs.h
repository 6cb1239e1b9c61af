#pragma once
// Narrow phase and response of the sphere collision (method.md §6), internal: exact sphere
// tests on the leaf pairs the trees report, pushes accumulated from the starting positions and
// applied after all pairs.
#include <LinearMath/btVector3.h>

#include <vector>

#include "state/MuscleState.h"

namespace fibremss {

/// Ends of the contacts found in one iteration, kept for debug drawing; fixed capacity.
struct ContactLog {
  std::vector<btVector3> ends;  ///< two points per contact, allocated up front
  size_t stored = 0;            ///< contacts stored (≤ ends.size() / 2)
  size_t found = 0;             ///< contacts found, stored or not
  size_t candidates = 0;        ///< sphere pairs tested exactly (listed or traversed)

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

/// The Verlet skin of a muscle tree as a share of the muscle's mean boundary radius (leaf bounds
/// grow by half of it): larger refits and relists less often, smaller lists fewer pairs to test.
/// Measured (callgrind, collide() of `fibremss run thigh13 --steps 3 --threads 1`): 0.25 lowest
/// of 0.125 / 0.25 / 0.35 / 0.5 / 1 at R=20 (267 / 259 / 262 / 267 / 418 M), and at R=40 below 0.5
/// (367 vs 374 M).
constexpr btScalar kTreeSkin = btScalar(0.25);
/// A candidate list holds kListSlack times the pairs its bodies have when added, plus half the
/// boundary particles of its muscle (the smaller muscle of two): muscles press together as bones
/// move (thigh13 at R=20 through its 13 poses: a pair with 9 at rest reached 102). None of
/// thigh13 (R=20, 40), hip-extension and pinch overflows with this room.
constexpr size_t kListSlack = 4;
/// The list of `lists` (TreeState::muscleLists or boneLists) for the body in `slot`, or null when
/// that body is unlisted.
inline CandidateList* candidateList(std::vector<CandidateList>& lists, uint32_t slot) {
  return slot < lists.size() ? &lists[slot] : nullptr;
}

/// Builds a muscle's tree with its skin (TreeState::treeSkin = kTreeSkin · meanRadius) around
/// its positions and takes the snapshot; rebuildable when `rebuildEveryStep` (the thesis' mode,
/// MuscleSystemDef::rebuildEveryStep). Allocates.
void buildTree(const MuscleSettings& settings, const ParticleState& particles, TreeState& trees,
               bool rebuildEveryStep);
/// Refits a muscle's tree (same topology, a new snapshot and epoch) when some boundary particle
/// moved farther than the tree's reach from its snapshot — whatever moved it (integration,
/// bones, rollback, the guard, a user); returns whether it refitted. Until then every sphere
/// lies inside its leaf's bounds. The new leaves are grown by skin/2, or not at all (refit every
/// iteration) while the muscle moves faster than the skin would hold: refit in two iterations
/// running, or more than the skin in one (bones moving). While tight and carried by its bones
/// (followBones), it refits without updating the snapshot (a pass less) until the iteration in
/// which they arrive.
bool refitTree(const MuscleSettings& settings, const ParticleState& particles, TreeState& trees);
/// Re-inserts every leaf (the thesis' rebuild each step), with the skin; a new snapshot and epoch.
void rebuildTree(const MuscleSettings& settings, const ParticleState& particles, TreeState& trees);
/// A list for the leaf pairs of `a` and a later-added `b` (TreeState::muscleLists), sized from
/// their pairs at the current positions (kListSlack). Allocates.
CandidateList muscleList(const CollidingMuscle& a, const CollidingMuscle& b);
/// A list for the leaf pairs of a muscle and a sphere bone (TreeState::boneLists), sized like
/// muscleList; empty (never listed) for a bone with a distance field. Allocates.
CandidateList boneList(const MuscleSettings& settings, const TreeState& trees,
                       const BoneState& bone);

/// MuscleContact::i or j of a fixed particle: the contact does not move it.
constexpr uint32_t kUnpushed = UINT32_MAX;

/// A contact of particle i of a muscle `a` with particle j of a later-added `b`: i is pushed by
/// `push`, j by −push (half the overlap each, the whole one to the free particle when the other
/// is fixed; both fixed are never tested).
struct MuscleContact {
  uint32_t i;      ///< particle of `a`, or kUnpushed
  uint32_t j;      ///< particle of `b`, or kUnpushed
  btVector3 push;  ///< push on i; j's is −push [m]
};

/// The contacts of one muscle pair in one iteration, in the order they were found, in room the
/// caller gives (the pair's candidate list capacity: a listed pair always fits).
struct MuscleContacts {
  MuscleContact* records = nullptr;  ///< capacity entries
  size_t capacity = 0;               ///< room in records
  size_t count = 0;                  ///< contacts found (> capacity: records incomplete)
  bool listOverflowed = false;       ///< the pair's listing overflowed its capacity
};

/// Muscle–muscle contacts of two different muscles (`b` added after `a`) recorded into `out`,
/// pushing neither: tests the pairs `list` (a's list for b, candidateList; null: unlisted) holds
/// for both trees' epochs, else traverses the trees (`stack` owns the traversal stack) and lists
/// them. Writes only `list`, `out` and `log` (log.candidates counts the pairs tested exactly:
/// listed or traversed; both-fixed pairs skipped), so pairs sharing a muscle may run
/// concurrently.
void collideMuscles(const CollidingMuscle& a, const CollidingMuscle& b, CandidateList* list,
                    TreeTraversalStack& stack, ContactLog& log, MuscleContacts& out);
/// Adds the pushes collideMuscles recorded for `a` and `b` to `pushed`, the contact state of a
/// (`onFirst`) or b, in record order; when they overflowed, traverses the trees again (`stack`
/// owns the traversal stack) for the same contacts in the same order. Writes only `pushed`.
/// Returns whether the records or the pair's listing overflowed (a's candidateOverflows counts
/// it once per pair).
bool pushMuscleContacts(const CollidingMuscle& a, const CollidingMuscle& b, bool onFirst,
                        ContactState& pushed, TreeTraversalStack& stack,
                        const MuscleContacts& contacts);
/// Muscle–bone contacts, the whole overlap to the free particle: against the bone's spheres
/// (its tree placed at its current transform), or, when the bone has a distance field, every
/// boundary particle in the field's box is pushed out along the field's gradient to clear its
/// radius. With the muscle's side memory (penetration recovery), a particle whose direction out
/// of the bone flipped since the last iteration is pushed back out on its remembered side.
/// Against spheres, the pairs trees.boneLists[bone.slot] holds for the muscle's tree epoch and
/// the bone's placement are tested, else listed like collideMuscles (an overflow counted in
/// trees.candidateOverflows); the field is traversed. The pushes go into `contact`.
void collideMuscleBone(const MuscleSettings& settings, const ParticleState& particles,
                       TreeState& trees, ContactState& contact, const BoneState& bone,
                       TreeTraversalStack& stack, ContactLog& log);

/// Forgets the bone sides penetration recovery remembers (after a rollback: the remembered
/// sides belong to positions that no longer exist).
void forgetBoneSides(ContactState& contact);

/// The slop an integrator that holds contacts (TimeIntegrator::holdsContacts) leaves in every
/// contact, as a share of the particle's radius [1] (leaveContactSlop).
constexpr btScalar kContactSlop = btScalar(0.01);

/// `v` without its part into the unit direction `normal` (a push's, out of the contact): the
/// approach a contact stops, or the force it holds; what points along or out of it stays.
inline btVector3 withoutInto(const btVector3& v, const btVector3& normal) {
  const btScalar into = v.dot(normal);
  return into < 0 ? v - normal * into : v;
}

/// Moves every pushed particle by its accumulated push and removes its velocity into the push
/// (when `sliding`, MuscleSystemDef::slidingContacts; else all of it: previous = position,
/// velocities zeroed when the integrator `hasVelocities`); clears the pushes. A particle two bones
/// press from opposite sides (pinched: no room between them) is moved to equal overlaps and out
/// sideways where the bones leave a way out; contact.pinched counts such particles.
void applyPushes(const MuscleSettings& settings, ParticleState& particles, ContactState& contact,
                 bool hasVelocities, bool sliding);

/// After applyPushes, for an integrator that holds contacts: every particle the response just
/// pushed (recordPushes: pushRounds[i] == contactRound) moves back along its push by `slop` times
/// its radius (at most the push), x and x(t−dt) alike, so that it rests that much inside its
/// contact and the next iteration finds the contact again (persistent contacts).
void leaveContactSlop(const MuscleSettings& settings, const ContactState& contact,
                      const ResidualState& residual, ParticleState& particles, btScalar slop);

}  // namespace fibremss
