#include "CollisionPairs.h"

namespace fibremss {
namespace {

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
    if (shareA > 0) {
      a_.pushes[i] += direction * (depth * shareA);
      ++a_.pushCounts[i];
    }
    if (shareB > 0) {
      b_.pushes[j] -= direction * (depth * shareB);
      ++b_.pushCounts[j];
    }
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
                    muscle.pushes[i] += direction * depth;
                    ++muscle.pushCounts[i];
                    log.add(muscle.positions[i], centre);
                  });
}

void applyPushes(MuscleState& muscle, bool zeroVelocities) {
  for (uint32_t i : muscle.settings->boundaryParticles) {
    if (muscle.pushCounts[i] == 0) continue;
    muscle.positions[i] += muscle.pushes[i];
    muscle.previous[i] = muscle.positions[i];
    if (zeroVelocities) muscle.velocities[i].setZero();
    muscle.pushes[i].setZero();
    muscle.pushCounts[i] = 0;
  }
}

}  // namespace fibremss
