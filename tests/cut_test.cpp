// Cutting (MuscleSystem::addBlade): the built-in `cut` scene's blade sweeps across fusiform and
// leaves two pieces whose particles are finite, whose tetrahedra hold the volume the muscle's did
// before the cut within 5 %, with the fixed particles on their bones, no failed step, no
// allocation in the steps, and the same bits for one thread and two; bad blades are input errors.
#include <LinearMath/btAlignedAllocator.h>
#include <gtest/gtest.h>

#include <cmath>
#include <numeric>
#include <span>
#include <string>
#include <vector>

#include "fibremss/Error.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "fibremss/SceneSystem.h"
#include "support/AllocationCounter.h"
#include "support/SameTear.h"

namespace fibremss {
namespace {

/// The union-find root of particle i.
uint32_t root(std::vector<uint32_t>& parent, uint32_t i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

/// Per particle, the smallest particle of its piece (the components of the unbroken springs).
std::vector<uint32_t> piecesOf(const MuscleSettings& settings) {
  std::vector<uint32_t> parent(settings.particleCount());
  std::iota(parent.begin(), parent.end(), 0u);
  for (const Spring& spring : settings.springs) {
    const uint32_t a = root(parent, spring.a), b = root(parent, spring.b);
    parent[std::max(a, b)] = std::min(a, b);
  }
  for (uint32_t i = 0; i < parent.size(); ++i) parent[i] = root(parent, i);
  return parent;
}

/// The volume the pieces hold [m³]: Σ over the unbroken tetrahedra whose four particles lie in
/// one piece of their signed volume at `x` (a tetrahedron the cut broke belongs to no piece).
double piecesVolume(const MuscleSettings& settings, std::span<const btVector3> x) {
  const std::vector<uint32_t> piece = piecesOf(settings);
  double volume = 0;
  for (size_t k = 0; k < settings.tetRestGradient.size(); ++k) {
    const uint32_t* t = settings.tetParticles.data() + 4 * k;
    if (settings.tetRestGradient[k] == 0 || piece[t[1]] != piece[t[0]] ||
        piece[t[2]] != piece[t[0]] || piece[t[3]] != piece[t[0]])
      continue;
    volume += double((x[t[1]] - x[t[0]]).dot((x[t[2]] - x[t[0]]).cross(x[t[3]] - x[t[0]]))) / 6;
  }
  return volume;
}

/// What a run of the cut scene left.
struct Cut {
  std::vector<btVector3> positions;  ///< the muscle's particles after the last step [m]
  MuscleTear tear;                   ///< what the blade cut
  double wholeVolume = 0;            ///< the pieces' volume before the blade moved [m³]
  double piecesVolume = 0;           ///< the pieces' volume after the last step [m³]
  double fixedOffBone = 0;           ///< largest distance of a fixed particle from its bone [m]
  int failures = 0;                  ///< step attempts the guard found failing
  long allocations = 0;              ///< allocations in the steps after the first
};

Cut run(int threads) {
  const LoadedScene scene = loadScene("cut");
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  MuscleSystemDef def = scene.simulation;
  def.threads = threads;
  MuscleSystem system(def);
  const SceneHandles handles = addScene(system, prepared);
  const std::vector<BoneHandle>& bones = handles.bones;
  const MuscleHandle muscle = handles.muscles[0];
  const BladeHandle blade = addBlades(system, scene)[0];
  Cut cut;
  btAlignedAllocSetCustom(testing::countingAlloc, std::free);
  for (int pose = 0; pose < scene.poseCount; ++pose) {
    for (size_t b = 0; b < bones.size(); ++b)
      system.setBoneTransform(bones[b], scene.bonePose(b, pose));
    system.setBladeTransform(blade, scene.bladePose(0, pose));
    testing::allocationCount = 0;
    testing::countingArmed = pose > 0;
    system.step();
    testing::countingArmed = false;
    if (pose > 0) cut.allocations += testing::allocationCount.load();
    // The blade stands still until pose 2.
    if (pose == 1)
      cut.wholeVolume = piecesVolume(system.settings(muscle), system.positions(muscle));
  }
  btAlignedAllocSetCustom(nullptr, nullptr);
  const MuscleSettings& settings = system.settings(muscle);
  const std::span<const btVector3> x = system.positions(muscle);
  cut.positions.assign(x.begin(), x.end());
  cut.tear = system.tear(muscle);
  cut.piecesVolume = piecesVolume(settings, x);
  cut.failures = system.failures(muscle).attempts;
  for (uint32_t i : settings.fixedParticles) {
    const btTransform bone = system.boneTransform(bones[size_t(settings.fixedBone[i])]);
    cut.fixedOffBone =
        std::max(cut.fixedOffBone, double(x[i].distance(bone * settings.restPositions[i])));
  }
  return cut;
}

TEST(Cut, TheBladeLeavesTwoFinitePiecesThatKeepTheVolume) {
  const Cut cut = run(1);
  RecordProperty("cut_springs", std::to_string(cut.tear.cutSprings));
  RecordProperty("volume_ratio", std::to_string(cut.piecesVolume / cut.wholeVolume));
  EXPECT_GT(cut.tear.cutSprings, 0u);
  EXPECT_EQ(cut.tear.brokenSprings, 0u);
  EXPECT_EQ(cut.tear.pieces, 2u);
  for (const btVector3& p : cut.positions)
    ASSERT_TRUE(std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z()));
  EXPECT_EQ(cut.failures, 0);
  EXPECT_GT(cut.wholeVolume, 0);
  EXPECT_NEAR(cut.piecesVolume / cut.wholeVolume, 1, 0.05);
}

TEST(Cut, FixedParticlesStayOnTheirBones) {
  EXPECT_LT(run(1).fixedOffBone, 1e-6);
}

TEST(Cut, StepsThatCutAllocateNothing) {
  EXPECT_EQ(run(0).allocations, 0);
}

TEST(Cut, IsTheSameForOneThreadAndTwo) {
  const Cut one = run(1), two = run(2);
  testing::expectSameTear(one.tear, two.tear, one.positions, two.positions);
}

TEST(Cut, BladesWithoutAnEdgeAreInputErrors) {
  MuscleSystem system;
  const btVector3 point(0, 0, 0);
  EXPECT_THROW(system.addBlade(point, point), InputError);
  const btVector3 far(btScalar(1e7), 0, 0);
  EXPECT_THROW(system.addBlade(point, far), InputError);
  const BladeHandle blade = system.addBlade(point, btVector3(1, 0, 0));
  btTransform bad = btTransform::getIdentity();
  bad.setOrigin(btVector3(btScalar(NAN), 0, 0));
  EXPECT_THROW(system.setBladeTransform(blade, bad), InputError);
  EXPECT_THROW(system.setBladeTransform(BladeHandle{}, btTransform::getIdentity()), InputError);
}

}  // namespace
}  // namespace fibremss
