#include "CollisionPairs.h"

#include <LinearMath/btAabbUtil2.h>

#include <algorithm>
#include <cmath>

#include "Integrators.h"

namespace fibremss {
namespace {

/// Steps of the walk back out of a bone along a remembered side before it gives up.
constexpr int kMaxBackOutSteps = 64;

/// Two bones' pushes on one particle oppose when their directions are more than 120° apart.
constexpr btScalar kOpposed = btScalar(-0.5);
/// A caught particle has a way out sideways when the bones' pushes across the gap add up to at
/// least this share of their lengths (an edge or a rounded end of a bone next to it).
constexpr btScalar kWayOut = btScalar(0.05);

/// `velocity` without its part into the unit push direction `normal`: no rebound, and what
/// moves along the contact keeps moving (frictionless sliding).
btVector3 withoutApproach(const btVector3& velocity, const btVector3& normal) {
  const btScalar into = velocity.dot(normal);
  return into < 0 ? velocity - normal * into : velocity;
}

void addPush(MuscleState& muscle, uint32_t i, const btVector3& push) {
  muscle.pushes[i] += push;
  ++muscle.pushCounts[i];
}

/// addPush of bone `slot`, also summed per bone for the pinch test of applyPushes.
void addBonePush(MuscleState& muscle, uint32_t i, uint32_t slot, const btVector3& push) {
  addPush(muscle, i, push);
  int32_t& first = muscle.pinchBones[i];
  if (first < 0) first = static_cast<int32_t>(slot);
  (first == static_cast<int32_t>(slot) ? muscle.firstBonePushes[i] : muscle.otherBonePushes[i]) +=
      push;
}

/// The response of a particle that bone pushes `a` (first bone) and `b` (the others) press
/// from opposite sides, both overlapping it (no room for its diameter): replaces `push` and
/// returns true; false, `push` unchanged, when they do not oppose. Along the gap's normal it
/// moves half the pushes' sum, which leaves equal overlaps on both sides (the whole sum would
/// swap them, back and forth every iteration); across, it moves out of the gap by their mean
/// depth along what the bones push across (towards a bone's edge or rounded end); muscle pushes
/// count only across the gap, where they cannot drive it into a bone.
bool pinchPush(const btVector3& a, const btVector3& b, btVector3& push) {
  const btScalar la = a.length(), lb = b.length();
  if (la <= 0 || lb <= 0 || a.dot(b) > kOpposed * la * lb) return false;
  const btVector3 normal = (a / la - b / lb).normalized();
  const btVector3 bones = a + b;
  const btScalar along = bones.dot(normal);
  const btVector3 across = bones - normal * along;
  const btVector3 muscles = push - bones;
  push = normal * (along / 2) + (muscles - normal * muscles.dot(normal));
  const btScalar acrossLength = across.length();
  if (acrossLength > kWayOut * (la + lb)) push += across * ((la + lb) / (2 * acrossLength));
  return true;
}

/// Walks from `local` (bone frame) along the remembered unit `side` until the field clears
/// `radius` with its direction on that side; returns the point reached.
btVector3 backOut(const BoneDistanceField& field, btVector3 local, const btVector3& side,
                  btScalar radius) {
  for (int k = 0; k < kMaxBackOutSteps; ++k) {
    const BoneDistanceField::Sample s = field.sample(local);
    if (s.distance >= radius && s.gradient.dot(side) > 0) break;
    local += side * std::max(std::abs(radius - s.distance), field.cell());
  }
  return local;
}

/// Push (bone frame) of penetration recovery for particle i at `local` with field sample `s`:
/// non-zero only when its side flipped; updates the particle's side memory.
btVector3 recoveryPush(MuscleState& muscle, uint32_t i, int32_t bone,
                       const BoneDistanceField& field, const btVector3& local,
                       const BoneDistanceField::Sample& s, btScalar radius) {
  int32_t& owner = muscle.sideBones[i];
  btVector3& side = muscle.boneSides[i];
  uint32_t& stamp = muscle.sideStamps[i];
  // Remembered only while the particle stays near the bone from one iteration to the next:
  // away from it (unseen, stale), a particle may go round the bone legitimately.
  const btScalar band = 2 * radius + 2 * field.cell();
  if (owner >= 0 && stamp + 1 < muscle.contactRound) owner = -1;
  if (owner == bone) {
    if (s.distance > band) {
      owner = -1;
      return btVector3(0, 0, 0);
    }
    stamp = muscle.contactRound;
    if (s.gradient.dot(side) < kFlippedSide) return backOut(field, local, side, radius) - local;
    if (!s.gradient.isZero()) side = s.gradient;
  } else if (owner < 0 && s.distance <= band && !s.gradient.isZero()) {
    owner = bone;
    side = s.gradient;
    stamp = muscle.contactRound;
  }
  return btVector3(0, 0, 0);
}

/// collideMuscleBone against the bone's distance field.
void collideWithField(MuscleState& muscle, const BoneState& bone, MuscleBoneStack& stack,
                      ContactLog& log) {
  const btDbvtNode* root = muscle.tree.root();
  if (!root) return;
  const MuscleSettings& settings = *muscle.settings;
  const BoneDistanceField& field = *bone.field;
  btVector3 lower, upper;
  btTransformAabb(field.lower(), field.upper(), 0, bone.current, lower, upper);
  const btDbvtVolume box = btDbvtVolume::FromMM(lower, upper);
  const btTransform toBone = bone.current.inverse();
  const btMatrix3x3& toWorld = bone.current.getBasis();
  const bool recovery = !muscle.sideBones.empty();
  stack.clear();
  stack.push_back({root, -1});
  while (!stack.empty()) {
    const btDbvtNode* node = stack.back().muscle;
    stack.pop_back();
    if (!Intersect(node->volume, box)) continue;
    if (node->isinternal()) {
      // φ is 1-Lipschitz: a node whose box (spheres included) lies well clear of the bone
      // holds no contact and no particle within its recovery band (twice its radius).
      const btVector3 centre = node->volume.Center();
      const btScalar halfDiagonal = node->volume.Extents().length();
      if (field.sample(toBone * centre).distance > 3 * halfDiagonal + 2 * field.cell()) continue;
      stack.push_back({node->childs[0], -1});
      stack.push_back({node->childs[1], -1});
      continue;
    }
    const uint32_t i = static_cast<uint32_t>(node->dataAsInt);
    if (settings.isFixed(i)) continue;
    ++log.candidates;
    const btScalar radius = settings.radii[i];
    const btVector3 local = toBone * muscle.positions[i];
    const BoneDistanceField::Sample s = field.sample(local);
    btVector3 push =
        recovery ? recoveryPush(muscle, i, static_cast<int32_t>(bone.slot), field, local, s, radius)
                 : btVector3(0, 0, 0);
    if (push.isZero() && s.distance < radius) push = s.gradient * (radius - s.distance);
    if (push.isZero()) continue;
    addBonePush(muscle, i, bone.slot, toWorld * push);
    log.add(muscle.positions[i], muscle.positions[i] - toWorld * (s.gradient * s.distance));
  }
}

class MuscleMusclePairs final : public btDbvt::ICollide {
 public:
  MuscleMusclePairs(MuscleState& a, MuscleState& b, ContactLog& log) : a_(a), b_(b), log_(log) {}
  using btDbvt::ICollide::Process;
  void Process(const btDbvtNode* leafA, const btDbvtNode* leafB) override {
    ++log_.candidates;
    const uint32_t i = static_cast<uint32_t>(leafA->dataAsInt);
    const uint32_t j = static_cast<uint32_t>(leafB->dataAsInt);
    const MuscleSettings& sa = *a_.settings;
    const MuscleSettings& sb = *b_.settings;
    const bool fixedA = sa.isFixed(i);
    const bool fixedB = sb.isFixed(j);
    if (fixedA && fixedB) return;
    btVector3 direction;
    btScalar depth;
    if (!sphereOverlap(a_.positions[i], sa.radii[i], b_.positions[j], sb.radii[j], direction,
                       depth))
      return;
    const btScalar shareA = fixedA ? 0 : (fixedB ? 1 : btScalar(0.5));
    const btScalar shareB = 1 - shareA;
    if (shareA > 0) addPush(a_, i, direction * (depth * shareA));
    if (shareB > 0) addPush(b_, j, direction * (-depth * shareB));
    log_.add(a_.positions[i], b_.positions[j]);
  }

 private:
  MuscleState& a_;
  MuscleState& b_;
  ContactLog& log_;
};

}  // namespace

void refitTree(MuscleState& muscle) {
  const MuscleSettings& settings = *muscle.settings;
  muscle.tree.refit(settings.boundaryParticles, muscle.positions, settings.radii);
}

void rebuildTree(MuscleState& muscle) {
  const MuscleSettings& settings = *muscle.settings;
  muscle.tree.rebuild(settings.boundaryParticles, muscle.positions, settings.radii);
}

void collideMuscles(MuscleState& a, MuscleState& b, ContactLog& log) {
  if (!a.tree.root() || !b.tree.root()) return;
  if (!Intersect(a.tree.root()->volume, b.tree.root()->volume)) return;
  MuscleMusclePairs pairs(a, b, log);
  collideTrees(a.tree, a.tree.root(), b.tree.root(), pairs);
}

void collideMuscleBone(MuscleState& muscle, const BoneState& bone, MuscleBoneStack& stack,
                       ContactLog& log) {
  if (bone.field) {
    collideWithField(muscle, bone, stack, log);
    return;
  }
  const MuscleSettings& settings = *muscle.settings;
  const std::vector<btScalar>& boneRadii = bone.settings->sphereRadii;
  collideWithBone(stack, muscle.tree.root(), bone.tree,
                  [&](const btDbvtNode* leaf, int32_t sphere) {
                    ++log.candidates;
                    const uint32_t i = static_cast<uint32_t>(leaf->dataAsInt);
                    if (settings.isFixed(i)) return;
                    const btVector3& centre = bone.tree.centre(sphere);
                    btVector3 direction;
                    btScalar depth;
                    if (!sphereOverlap(muscle.positions[i], settings.radii[i], centre,
                                       boneRadii[sphere], direction, depth))
                      return;
                    addBonePush(muscle, i, bone.slot, direction * depth);
                    log.add(muscle.positions[i], centre);
                  });
}

void forgetBoneSides(MuscleState& muscle) {
  std::fill(muscle.sideBones.begin(), muscle.sideBones.end(), -1);
}

void applyPushes(MuscleState& muscle, bool hasVelocities) {
  ++muscle.contactRound;
  const bool sliding = solverParameters(muscle).slidingContacts;
  size_t pinched = 0;
  for (uint32_t i : muscle.settings->boundaryParticles) {
    if (muscle.pushCounts[i] == 0) continue;
    btVector3 push = muscle.pushes[i];
    if (muscle.pinchBones[i] >= 0) {
      if (pinchPush(muscle.firstBonePushes[i], muscle.otherBonePushes[i], push)) ++pinched;
      muscle.pinchBones[i] = -1;
      muscle.firstBonePushes[i].setZero();
      muscle.otherBonePushes[i].setZero();
    }
    const btScalar depth = push.length();
    if (sliding && depth > 0) {
      const btVector3 normal = push / depth;
      const btVector3 moved = withoutApproach(muscle.positions[i] - muscle.previous[i], normal);
      muscle.positions[i] += push;
      muscle.previous[i] = muscle.positions[i] - moved;
      if (hasVelocities) muscle.velocities[i] = withoutApproach(muscle.velocities[i], normal);
    } else {
      muscle.positions[i] += push;
      muscle.previous[i] = muscle.positions[i];
      if (hasVelocities) muscle.velocities[i].setZero();
    }
    muscle.pushes[i].setZero();
    muscle.pushCounts[i] = 0;
  }
  muscle.pinched = pinched;
}

}  // namespace fibremss
