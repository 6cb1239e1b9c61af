// The Verlet skin of the collision (CollisionPairs.h: refitTree, collideMuscles,
// collideMuscleBone): fat leaves refit only when a particle leaves its skin, and candidate lists
// reused while both trees and the bone hold must give exactly the contacts of tight trees
// refit and traversed every iteration — whatever moved the particles, and when a list overflows.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <memory>
#include <vector>

#include "collision/CollisionPairs.h"
#include "fibremss/MuscleSystem.h"
#include "solver/MuscleSystemAccess.h"
#include "support/GridMuscle.h"
#include "support/SolverFixtures.h"
#include "support/ThighSteps.h"

namespace fibremss {
namespace {

/// Makes every muscle of the system use tight trees (skin 0): refit whenever a particle moved,
/// traversed every iteration, nothing listed — the collision without the skin.
void withoutSkin(MuscleSystem& system) {
  MuscleSystemAccess::Impl& impl = MuscleSystemAccess::impl(system);
  for (uint32_t slot : impl.muscles.order) {
    impl.muscles.states[slot]->treeSkin = 0;
    impl.muscles.states[slot]->treeReach = 0;
  }
}

/// Leaves every candidate list room for one pair (each listing overflows and falls back).
void withTinyLists(MuscleSystem& system) {
  MuscleSystemAccess::Impl& impl = MuscleSystemAccess::impl(system);
  for (uint32_t slot : impl.muscles.order) {
    MuscleState& state = *impl.muscles.states[slot];
    for (auto* lists : {&state.muscleLists, &state.boneLists})
      for (CandidateList& list : *lists) {
        list.pairs = std::vector<CandidatePair>(1);
        list.valid = false;
      }
  }
}

/// Tree refits (epochs) summed over the muscles.
uint64_t refits(MuscleSystem& system) {
  MuscleSystemAccess::Impl& impl = MuscleSystemAccess::impl(system);
  uint64_t sum = 0;
  for (uint32_t slot : impl.muscles.order) sum += impl.muscles.states[slot]->tree.epoch();
  return sum;
}

/// thigh13 (resolution 8) in one-iteration steps: 20 moving the bones from pose 0 to pose 1
/// (interpolated), then 30 with the bones still, while the muscles settle.
class ThighRun {
 public:
  explicit ThighRun(int threads) {
    const PreparedScene& prepared = testing::preparedThigh(scene_);
    MuscleSystemDef parameters = scene_.simulation;
    parameters.integrator = Integrator::Verlet;  // particles that move every iteration
    parameters.threads = threads;
    parameters.stepSettings.iterations = 1;
    parameters.stepSettings.stopRule = StopRule::Iterations;
    // A contact per overlapping sphere pair, as contactsOfEveryPair counts them (the lists are
    // the same when the pairs push against the bones' meshes).
    parameters.boneCollision = BoneCollision::Spheres;
    system_ = std::make_unique<MuscleSystem>(parameters);
    for (const auto& bone : prepared.bones) bones_.push_back(system_->addBone(bone));
    for (const auto& muscle : prepared.muscles)
      muscles_.push_back(system_->addMuscle(muscle, bones_));
  }
  MuscleSystem& system() { return *system_; }
  static constexpr int kSteps = 50;  ///< one-iteration steps of a run
  /// Step k (0 ≤ k < kSteps).
  void step(int k) {
    aimBones(k);
    system_->step();
  }
  /// Sets the bones' targets of step k: interpolated for k < 20, then pose 1.
  void aimBones(int k) {
    const btScalar share = std::min(btScalar(1), btScalar(k + 1) / 20);
    for (size_t b = 0; b < bones_.size(); ++b) {
      const btTransform from = scene_.bonePose(b, 0), to = scene_.bonePose(b, 1);
      system_->setBoneTransform(bones_[b],
                                btTransform(from.getRotation().slerp(to.getRotation(), share),
                                            from.getOrigin().lerp(to.getOrigin(), share)));
    }
  }
  /// Whether both runs' particles are bitwise equal.
  bool samePositions(ThighRun& other) {
    for (size_t m = 0; m < muscles_.size(); ++m) {
      const auto x = system_->positions(muscles_[m]);
      const auto y = other.system_->positions(other.muscles_[m]);
      if (x.size() != y.size() || std::memcmp(x.data(), y.data(), x.size_bytes()) != 0)
        return false;
    }
    return true;
  }

 private:
  LoadedScene scene_;
  std::unique_ptr<MuscleSystem> system_;
  std::vector<BoneHandle> bones_;
  std::vector<MuscleHandle> muscles_;
};

// Same tree topology (a refit keeps it) and the lists in traversal order: the pushes are summed
// in the same order, so the skin changes no bit — while bones move and while muscles settle.
TEST(CandidateLists, GiveTheContactsOfTightTreesBitForBit) {
  ThighRun skinned(1), tight(1);
  withoutSkin(tight.system());
  size_t contacts = 0, fewerTested = 0;
  for (int k = 0; k < ThighRun::kSteps; ++k) {
    skinned.step(k);
    tight.step(k);
    const StepStats& a = skinned.system().lastStep();
    const StepStats& b = tight.system().lastStep();
    ASSERT_EQ(a.contacts, b.contacts) << "iteration " << k;
    ASSERT_TRUE(skinned.samePositions(tight)) << "iteration " << k;
    EXPECT_EQ(a.candidateOverflows, 0u) << "iteration " << k;
    contacts += a.contacts;
    fewerTested += a.candidates < b.candidates ? 1 : 0;
  }
  EXPECT_GT(contacts, 0u);
  // The skin did its work: fewer refits, and lists shorter than the tight traversals' pairs.
  EXPECT_LT(refits(skinned.system()), refits(tight.system()) / 2);
  EXPECT_GT(fewerTested, 0u);
}

/// Overlapping sphere pairs of the system found by testing every pair (muscle–muscle pairs not
/// both fixed, free muscle particles against bone spheres): the contacts an exact test finds.
size_t contactsOfEveryPair(MuscleSystemAccess::Impl& impl) {
  size_t count = 0;
  btVector3 direction;
  btScalar depth;
  const std::vector<uint32_t>& order = impl.muscles.order;
  for (size_t x = 0; x < order.size(); ++x) {
    const MuscleState& a = *impl.muscles.states[order[x]];
    const MuscleSettings& sa = *a.settings;
    for (size_t y = x + 1; y < order.size(); ++y) {
      const MuscleState& b = *impl.muscles.states[order[y]];
      const MuscleSettings& sb = *b.settings;
      for (uint32_t i : sa.boundaryParticles)
        for (uint32_t j : sb.boundaryParticles)
          if (!(sa.isFixed(i) && sb.isFixed(j)) &&
              sphereOverlap(a.positions[i], sa.radii[i], b.positions[j], sb.radii[j], direction,
                            depth))
            ++count;
    }
    for (uint32_t slot : impl.bones.order) {
      const BoneState& bone = *impl.bones.states[slot];
      for (uint32_t i : sa.boundaryParticles)
        for (uint32_t k = 0; k < bone.settings->sphereRadii.size(); ++k)
          if (!sa.isFixed(i) &&
              sphereOverlap(a.positions[i], sa.radii[i], bone.tree.centre(static_cast<int32_t>(k)),
                            bone.settings->sphereRadii[k], direction, depth))
            ++count;
    }
  }
  return count;
}

/// Whether every boundary particle of the muscle has its snapshot at `positions`.
bool snapshotAt(const MuscleState& muscle, const std::vector<btVector3>& positions) {
  for (uint32_t i : muscle.settings->boundaryParticles)
    if (muscle.treeSnapshot[i] != positions[i]) return false;
  return true;
}

/// One iteration's collision as the step runs it: trees refitted, pairs, response.
void collideOnce(MuscleSystemAccess::Impl& impl) {
  impl.forEachMuscle("refit", [](MuscleState& state, uint32_t, unsigned) {
    refitTree(*state.settings, state, state);
  });
  impl.collide();
  impl.applyResponse();
}

// While bones carry the muscles faster than their skins, the tight trees refit without their
// snapshots; every contact of an exact test over all sphere pairs is still found, iteration by
// iteration, and in the iteration the bones arrive the refit takes the snapshot again.
TEST(CandidateLists, TreesCarriedByBonesFindEveryContact) {
  ThighRun run(2);
  for (int k = 0; k < 3; ++k) run.step(k);
  MuscleSystemAccess::Impl& impl = MuscleSystemAccess::impl(run.system());
  for (uint32_t slot : impl.bones.order) ASSERT_FALSE(impl.bones.states[slot]->field);
  const std::vector<uint32_t>& order = impl.muscles.order;
  std::vector<std::vector<btVector3>> before(order.size());
  // A step's bone-motion iterations without the spring pass: bones, follow, collide.
  constexpr int kIterations = 6;
  run.aimBones(8);
  size_t contacts = 0, skipped = 0;
  for (int k = 1; k <= kIterations; ++k) {
    impl.moveBones(btScalar(k) / kIterations, k == kIterations);
    impl.forEachMuscle("follow bones", [&](MuscleState& state, uint32_t, unsigned) {
      impl.followBones(*state.settings, state, state);
    });
    for (size_t m = 0; m < order.size(); ++m) before[m] = impl.muscles.states[order[m]]->positions;
    const size_t exact = contactsOfEveryPair(impl);
    collideOnce(impl);
    ASSERT_EQ(impl.stats.contacts, exact) << "iteration " << k;
    contacts += exact;
    for (size_t m = 0; m < order.size(); ++m) {
      const MuscleState& muscle = *impl.muscles.states[order[m]];
      if (muscle.treeReach > 0) continue;  // skin held, or refit with a snapshot
      const bool taken = snapshotAt(muscle, before[m]);
      if (k == kIterations) {
        EXPECT_TRUE(taken) << "muscle " << m << " when the bones arrived";
      }
      skipped += taken ? 0 : 1;
    }
  }
  EXPECT_GT(contacts, 0u);
  EXPECT_GT(skipped, 0u);  // the snapshot-free refit ran
  // The bones stopped: the contacts stay exact.
  const size_t exact = contactsOfEveryPair(impl);
  collideOnce(impl);
  EXPECT_EQ(impl.stats.contacts, exact);
}

// A listing that overflows falls back to traversing the trees: counted, the same contacts.
TEST(CandidateLists, AnOverflowFallsBackToTheTreesWithTheSameContacts) {
  ThighRun tiny(2), tight(2);
  withTinyLists(tiny.system());
  withoutSkin(tight.system());
  size_t overflows = 0;
  for (int k = 0; k < ThighRun::kSteps; ++k) {
    tiny.step(k);
    tight.step(k);
    ASSERT_EQ(tiny.system().lastStep().contacts, tight.system().lastStep().contacts) << k;
    ASSERT_TRUE(tiny.samePositions(tight)) << "iteration " << k;
    overflows += tiny.system().lastStep().candidateOverflows;
  }
  EXPECT_GT(overflows, 0u);
}

/// Two grid muscles 1 cm apart along y (not touching), stepped until their trees settle.
struct TwoGrids {
  TwoGrids() : system(definition()) {
    const BoneHandle bones[] = {system.addBone(testing::cubeBone("left", btVector3(-0.02f, 0, 0))),
                                system.addBone(testing::cubeBone("right", btVector3(0.02f, 0, 0)))};
    first = system.addMuscle(testing::gridMuscle("first", 0), bones);
    // 4 mm between the grids' facing layers, more than two radii (3 mm): no contact but the
    // test's own, whatever the rounding of the five settling steps.
    second = system.addMuscle(testing::gridMuscle("second", btScalar(0.012)), bones);
    for (int k = 0; k < 5; ++k) system.step();
  }
  static MuscleSystemDef definition() {
    MuscleSystemDef p = testing::verletDef();
    p.stepSettings.iterations = 1;
    p.stepSettings.stopRule = StopRule::Iterations;
    p.threads = 1;
    return p;
  }
  MuscleState& state(MuscleHandle muscle) {
    return *MuscleSystemAccess::impl(system).muscles.states[muscle.index];
  }
  MuscleSystem system;
  MuscleHandle first, second;
};

// However far a particle is moved by hand (a user, a rollback, the guard), the tree holds it:
// within the skin no refit and the list finds the new contact; past it the tree refits.
TEST(CandidateLists, AParticleMovedByHandIsCaughtWithinAndPastTheSkin) {
  for (btScalar share : {btScalar(0.3), btScalar(0.45), btScalar(0.55), btScalar(3)}) {
    TwoGrids grids;
    MuscleSystemAccess::Impl& impl = MuscleSystemAccess::impl(grids.system);
    MuscleState& a = grids.state(grids.first);
    MuscleState& b = grids.state(grids.second);
    // Particle 10 of each grid: boundary and free.
    const uint32_t i = 10;
    ASSERT_TRUE(a.settings->isBoundary(i) && !a.settings->isFixed(i));
    ASSERT_GT(b.treeReach, 0);
    // b's particle put just out of reach of a's, its tree refit there; then moved by hand
    // share·skin straight into a's sphere.
    const btScalar reach = a.settings->radii[i] + b.settings->radii[i];
    const btScalar move = share * b.treeSkin;
    const btVector3 up(0, 1, 0);
    b.positions[i] = b.previous[i] = a.positions[i] + up * (reach + move * btScalar(0.8));
    b.treeSnapshot[i] = b.positions[i];
    b.tree.refit(b.treeSnapshot, b.settings->radii, b.treeReach);
    collideOnce(impl);
    ASSERT_EQ(grids.system.lastStep().contacts, 0u) << share;
    const uint64_t epoch = b.tree.epoch();
    b.positions[i] = b.previous[i] = b.positions[i] - up * move;
    const btVector3 before = a.positions[i];
    collideOnce(impl);
    EXPECT_EQ(b.tree.epoch() != epoch, share > btScalar(0.5)) << share;
    EXPECT_EQ(grids.system.lastStep().contacts, 1u) << share;
    EXPECT_LT(a.positions[i].y(), before.y()) << share;  // pushed away from b's particle
  }
}

/// The pushes of both muscles (and their counts) as bytes, then cleared as a response would.
std::vector<unsigned char> takePushes(MuscleState& a, MuscleState& b) {
  std::vector<unsigned char> bytes;
  for (MuscleState* muscle : {&a, &b}) {
    const auto* p = reinterpret_cast<const unsigned char*>(muscle->pushes.data());
    bytes.insert(bytes.end(), p, p + muscle->pushes.size() * sizeof(btVector3));
    for (uint32_t count : muscle->pushCounts) bytes.push_back(static_cast<unsigned char>(count));
    for (btVector3& push : muscle->pushes) push.setZero();
    std::fill(muscle->pushCounts.begin(), muscle->pushCounts.end(), 0u);
  }
  return bytes;
}

// A pair's contacts are recorded, then pushed into each muscle; contacts beyond the records'
// room are found again by traversing the trees: the same pushes, bit for bit, and counted.
TEST(CandidateLists, ContactsBeyondTheirRecordsAreFoundAgainInOrder) {
  ThighRun run(1);
  for (int k = 0; k < 10; ++k) run.step(k);
  MuscleSystemAccess::Impl& impl = MuscleSystemAccess::impl(run.system());
  TreeTraversalStack stack;
  ContactLog log;
  size_t pairsInContact = 0;
  const std::vector<uint32_t>& order = impl.muscles.order;
  for (size_t x = 0; x < order.size(); ++x)
    for (size_t y = x + 1; y < order.size(); ++y) {
      MuscleState& a = *impl.muscles.states[order[x]];
      MuscleState& b = *impl.muscles.states[order[y]];
      std::vector<MuscleContact> room(a.muscleLists[b.slot].pairs.size() + 1);
      MuscleContacts full{room.data(), room.size()}, none{room.data(), 0};
      CandidateList* list = candidateList(a.muscleLists, b.slot);
      collideMuscles(a.colliding(), b.colliding(), list, stack, log, full);
      ASSERT_LE(full.count, full.capacity);
      for (bool onFirst : {true, false})
        pushMuscleContacts(a.colliding(), b.colliding(), onFirst, onFirst ? a : b, stack, full);
      const std::vector<unsigned char> recorded = takePushes(a, b);
      collideMuscles(a.colliding(), b.colliding(), list, stack, log, none);
      ASSERT_EQ(none.count, full.count);
      for (bool onFirst : {true, false})
        EXPECT_EQ(
            pushMuscleContacts(a.colliding(), b.colliding(), onFirst, onFirst ? a : b, stack, none),
            none.count > 0);
      EXPECT_TRUE(takePushes(a, b) == recorded) << x << " with " << y;
      pairsInContact += full.count > 0 ? 1 : 0;
    }
  EXPECT_GT(pairsInContact, 0u);
}

}  // namespace
}  // namespace fibremss
