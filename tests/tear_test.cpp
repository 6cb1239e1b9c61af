// Tearing (SpringParameters::breakStretch): the built-in `tear` scene's notch tears apart with no
// spring a particle shares beyond the threshold after a step, without allocating in the steps that
// break, with the same bits for one thread and two; a threshold that nothing reaches changes no
// bit; thresholds outside (1, strain_limit) are input errors.
#include <LinearMath/btAlignedAllocator.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <climits>
#include <cstdint>
#include <cstring>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "fibremss/Error.h"
#include "fibremss/Measures.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "fibremss/SceneSystem.h"
#include "support/AllocationCounter.h"
#include "support/GridMuscle.h"
#include "support/SameTear.h"

namespace fibremss {
namespace {

/// What a run of a scene's poses left.
struct Torn {
  std::vector<btVector3> positions;        ///< the muscle's particles after the last step [m]
  MuscleTear tear;                         ///< what tearing did
  double worstRatio = 0;                   ///< worstSharedSpring after any step
  long allocations = 0;                    ///< allocations in the steps after the first
  size_t brokenWhileCounting = 0;          ///< springs broken in those steps
  std::map<int64_t, unsigned> pieceBones;  ///< per piece at the end: the bones it holds (bits)
  double farthestBreak = 0;                ///< the largest |rest y| of a broken spring's middle [m]
};

/// Per particle of `settings`: the smallest particle of its component of the unbroken springs but
/// spring `skip`, or -1 for a particle with no unbroken spring.
std::vector<int64_t> components(const MuscleSettings& settings, size_t skip = SIZE_MAX) {
  std::vector<uint32_t> parent(settings.particleCount());
  for (uint32_t i = 0; i < parent.size(); ++i) parent[i] = i;
  const auto root = [&](uint32_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  std::vector<int64_t> component(parent.size(), -1);
  for (size_t s = 0; s < settings.springs.size(); ++s) {
    const Spring& spring = settings.springs[s];
    if (spring.a == spring.b) continue;
    component[spring.a] = component[spring.b] = 0;
    if (s != skip)
      parent[std::max(root(spring.a), root(spring.b))] = std::min(root(spring.a), root(spring.b));
  }
  for (uint32_t i = 0; i < parent.size(); ++i)
    if (component[i] >= 0) component[i] = root(i);
  return component;
}

/// Per component of the unbroken springs of `settings` but spring `skip` (by its smallest
/// particle): the bones whose fixed particles it holds, as a bit set.
std::map<int64_t, unsigned> bonesPerPiece(const MuscleSettings& settings, size_t skip = SIZE_MAX) {
  const std::vector<int64_t> component = components(settings, skip);
  std::map<int64_t, unsigned> bones;
  for (const int64_t c : component)
    if (c >= 0) bones[c] |= 0;
  for (const uint32_t f : settings.fixedParticles)
    if (component[f] >= 0) bones[component[f]] |= 1u << settings.fixedBone[f];
  return bones;
}

/// Whether the unbroken springs of `settings` but spring `skip` leave a piece that holds no fixed
/// particle.
bool freesAPiece(const MuscleSettings& settings, size_t skip) {
  const std::map<int64_t, unsigned> bones = bonesPerPiece(settings, skip);
  return std::any_of(bones.begin(), bones.end(),
                     [](const auto& piece) { return piece.second == 0; });
}

/// The largest l / L0 of the unbroken springs of `settings` at `x` that are not the last of one
/// of their particles (a particle's last spring does not break) and whose break would free no
/// piece that no bone holds (such a spring does not break either).
double worstSharedSpring(const MuscleSettings& settings, std::span<const btVector3> x) {
  std::vector<int> counts(settings.particleCount(), 0);
  for (const Spring& spring : settings.springs)
    if (spring.a != spring.b) ++counts[spring.a], ++counts[spring.b];
  double worst = 0;
  for (size_t s = 0; s < settings.springs.size(); ++s) {
    const Spring& spring = settings.springs[s];
    if (spring.a == spring.b || counts[spring.a] == 1 || counts[spring.b] == 1) continue;
    const double ratio = x[spring.a].distance(x[spring.b]) / spring.restLength;
    if (ratio > worst && (ratio <= settings.breakStretch || !freesAPiece(settings, s)))
      worst = ratio;
  }
  return worst;
}

/// Runs the first muscle of `name` with `overrides` through every pose of the scene.
Torn run(const std::string& name, std::vector<std::string> overrides, int threads = 0) {
  const LoadedScene scene = loadScene(name, overrides);
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  MuscleSystemDef def = scene.simulation;
  def.threads = threads;
  MuscleSystem system(def);
  const SceneHandles handles = addScene(system, prepared);
  const std::vector<BoneHandle>& bones = handles.bones;
  const MuscleHandle muscle = handles.muscles[0];
  Torn torn;
  const std::vector<Spring> intact = system.settings(muscle).springs;
  btAlignedAllocSetCustom(testing::countingAlloc, std::free);
  for (int pose = 0; pose < scene.poseCount; ++pose) {
    for (size_t b = 0; b < bones.size(); ++b)
      system.setBoneTransform(bones[b], scene.bonePose(b, pose));
    const size_t before = system.tear(muscle).brokenSprings;
    testing::allocationCount = 0;
    testing::countingArmed = pose > 0;
    system.step();
    testing::countingArmed = false;
    if (pose > 0) {
      torn.allocations += testing::allocationCount.load();
      torn.brokenWhileCounting += system.tear(muscle).brokenSprings - before;
    }
    torn.worstRatio = std::max(
        torn.worstRatio, worstSharedSpring(system.settings(muscle), system.positions(muscle)));
  }
  btAlignedAllocSetCustom(nullptr, nullptr);
  const std::span<const btVector3> positions = system.positions(muscle);
  torn.positions.assign(positions.begin(), positions.end());
  torn.tear = system.tear(muscle);
  const MuscleSettings& settings = system.settings(muscle);
  torn.pieceBones = bonesPerPiece(settings);
  for (size_t s = 0; s < intact.size(); ++s) {
    const btVector3 middle =
        (settings.restPositions[intact[s].a] + settings.restPositions[intact[s].b]) / 2;
    if (settings.springs[s].a == settings.springs[s].b)
      torn.farthestBreak = std::max(torn.farthestBreak, double(std::abs(middle.y())));
  }
  return torn;
}

const std::vector<std::string> kCoarse{"resolution=12", "fibre_count=48"};

TEST(Tear, NoSharedSpringEndsAStepBeyondTheThresholdAndTheNotchTearsApart) {
  const Torn torn = run("tear", kCoarse);
  RecordProperty("broken_springs", std::to_string(torn.tear.brokenSprings));
  RecordProperty("pieces", std::to_string(torn.tear.pieces));
  EXPECT_GT(torn.tear.brokenSprings, 0u);
  EXPECT_GT(torn.tear.brokenVolumeTerms, 0u);
  EXPECT_LE(torn.worstRatio, 1.5);
  EXPECT_GE(torn.tear.pieces, 2u);
}

TEST(Tear, AtItsDefaultResolutionTheMuscleTearsAtTheNotchIntoOnePieceOnEachPlate) {
  const Torn torn = run("tear", {});
  RecordProperty("broken_springs", std::to_string(torn.tear.brokenSprings));
  EXPECT_EQ(torn.tear.pieces, 2u);
  // Plate-lower is bone 0, plate-upper bone 1: one piece holds each, none holds both or neither.
  std::vector<unsigned> bones;
  for (const auto& piece : torn.pieceBones) bones.push_back(piece.second);
  std::sort(bones.begin(), bones.end());
  EXPECT_EQ(bones, (std::vector<unsigned>{1u, 2u}));
  // Every break within a spring's length (about 5 mm) of the notch (4 mm either side of the
  // middle), none at the attachments 50 mm away.
  EXPECT_LT(torn.farthestBreak, 0.01);
  EXPECT_LE(torn.worstRatio, 1.5);
}

TEST(Tear, AThresholdNothingReachesChangesNoBit) {
  // cylinder-stretch's springs stay below 1.3 (10 % stretch): tearing on breaks nothing.
  const Torn off = run("cylinder-stretch", kCoarse);
  std::vector<std::string> on = kCoarse;
  on.push_back("break_stretch=1.9");
  const Torn unbroken = run("cylinder-stretch", on);
  EXPECT_EQ(unbroken.tear.brokenSprings, 0u);
  EXPECT_EQ(unbroken.tear.pieces, 1u);
  EXPECT_EQ(off.tear.pieces, 1u);
  ASSERT_EQ(off.positions.size(), unbroken.positions.size());
  EXPECT_EQ(std::memcmp(off.positions.data(), unbroken.positions.data(),
                        off.positions.size() * sizeof(btVector3)),
            0);
}

TEST(Tear, StepsThatBreakAllocateNothing) {
  const Torn torn = run("tear", kCoarse);
  EXPECT_GT(torn.brokenWhileCounting, 0u);
  EXPECT_EQ(torn.allocations, 0);
}

TEST(Tear, IsTheSameForOneThreadAndTwo) {
  const Torn one = run("tear", kCoarse, 1);
  const Torn two = run("tear", kCoarse, 2);
  testing::expectSameTear(one.tear, two.tear, one.positions, two.positions);
}

TEST(Tear, ThresholdsOutsideOneToTheStrainLimitAreInputErrors) {
  EXPECT_THROW(loadScene("tear", {"break_stretch=0.5"}), InputError);
  EXPECT_THROW(loadScene("tear", {"break_stretch=1"}), InputError);
  EXPECT_THROW(loadScene("tear", {"break_stretch=2.5"}), InputError);  // strain_limit 2
  EXPECT_NO_THROW(loadScene("tear", {"break_stretch=2.5", "strain_limit=0"}));
  auto settings = std::make_shared<MuscleSettings>(*testing::gridMuscle("grid"));
  settings->strainLimit = 2;
  settings->breakStretch = 3;
  MuscleSystem system;
  const BoneHandle bones[] = {system.addBone(testing::cubeBone("left", btVector3(-0.02f, 0, 0))),
                              system.addBone(testing::cubeBone("right", btVector3(0.02f, 0, 0)))};
  EXPECT_THROW(system.addMuscle(settings, bones), InputError);
}

}  // namespace
}  // namespace fibremss
