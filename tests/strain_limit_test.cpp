// The strain limit (SpringParameters::strainLimit): a muscle pulled hard ends every step with no
// spring beyond its limit, with the default solver and with Verlet, and the same positions for one
// thread and two.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <memory>
#include <vector>

#include "fibremss/Error.h"
#include "fibremss/Measures.h"
#include "fibremss/MuscleSystem.h"
#include "support/GridMuscle.h"
#include "support/SolverFixtures.h"

namespace fibremss {
namespace {

/// The grid muscle (GridMuscle.h) with the springs of its last free layer and bone 1's fixed
/// layer (x ≥ 8 mm) a tenth as stiff: pulled, they take most of the stretch (2.3× at 8 mm).
std::shared_ptr<const MuscleSettings> softEndMuscle(btScalar strainLimit) {
  auto muscle = std::make_shared<MuscleSettings>(*testing::gridMuscle("soft end"));
  const auto atEnd = [&](uint32_t p) { return muscle->restPositions[p].x() > btScalar(0.0079); };
  for (Spring& spring : muscle->springs)
    if (atEnd(spring.a) && atEnd(spring.b)) spring.stiffness *= btScalar(0.1);
  muscle->strainLimit = strainLimit;
  return muscle;
}

struct Pulled {
  double worstRatio = 0;             ///< largest l / L0 of any spring after any step
  std::vector<btVector3> positions;  ///< after the last step [m]
  int failedSteps = 0;               ///< steps the guard rolled back or retried
};

/// The muscle's bone 1 pulled 8 mm along the fibres in four steps.
Pulled pull(const MuscleSystemDef& parameters, btScalar strainLimit) {
  MuscleSystem system(parameters);
  const BoneHandle bones[] = {system.addBone(testing::cubeBone("left", btVector3(-0.02f, 0, 0))),
                              system.addBone(testing::cubeBone("right", btVector3(0.02f, 0, 0)))};
  const auto settings = softEndMuscle(strainLimit);
  const MuscleHandle muscle = system.addMuscle(settings, bones);
  Pulled result;
  for (int s = 1; s <= 4; ++s) {
    system.setBoneTransform(
        bones[1], btTransform(btQuaternion::getIdentity(), btVector3(btScalar(0.002) * s, 0, 0)));
    system.step();
    result.worstRatio =
        std::max(result.worstRatio, worstSpringRatio(settings->springs, system.positions(muscle)));
    const StepStats& stats = system.lastStep();
    result.failedSteps += stats.rolledBack || stats.retries > 0 ? 1 : 0;
  }
  const std::span<const btVector3> positions = system.positions(muscle);
  result.positions.assign(positions.begin(), positions.end());
  return result;
}

MuscleSystemDef withThreads(MuscleSystemDef parameters, int threads) {
  parameters.threads = threads;
  return parameters;
}

constexpr btScalar kLimit = btScalar(1.6);

TEST(StrainLimit, NoSpringOfAPulledMuscleEndsAStepBeyondIt) {
  for (const MuscleSystemDef& parameters : {MuscleSystemDef{}, testing::verletDef()}) {
    const char* solver = toString(parameters.integrator);
    const Pulled free = pull(parameters, 0);
    EXPECT_GT(free.worstRatio, 2.0) << solver << ": without the limit the soft end stretches";
    const Pulled limited = pull(parameters, kLimit);
    EXPECT_LE(limited.worstRatio, double(kLimit)) << solver;
    EXPECT_GT(limited.worstRatio, double(kLimit) - 0.01) << solver << ": springs held at it";
    EXPECT_EQ(limited.failedSteps, 0) << solver;
  }
}

TEST(StrainLimit, IsTheSameForOneThreadAndTwo) {
  const Pulled one = pull(withThreads(MuscleSystemDef{}, 1), kLimit);
  const Pulled two = pull(withThreads(MuscleSystemDef{}, 2), kLimit);
  ASSERT_EQ(one.positions.size(), two.positions.size());
  EXPECT_EQ(std::memcmp(one.positions.data(), two.positions.data(),
                        one.positions.size() * sizeof(btVector3)),
            0);
}

TEST(StrainLimit, AtOrBelowOneIsRejected) {
  MuscleSystem system;
  const BoneHandle bones[] = {system.addBone(testing::cubeBone("left", btVector3(-0.02f, 0, 0))),
                              system.addBone(testing::cubeBone("right", btVector3(0.02f, 0, 0)))};
  EXPECT_THROW(system.addMuscle(softEndMuscle(1), bones), InputError);
  EXPECT_NO_THROW(system.addMuscle(softEndMuscle(0), bones));
}

}  // namespace
}  // namespace fibremss
