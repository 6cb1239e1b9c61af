// Determinism: the same scene, seed and thread count give the same output bit for bit (two
// independent preparations and systems stepped side by side in one process); different thread
// counts give the same output to a stated tolerance.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"

namespace fibremss {
namespace {

/// thigh13 (13 muscles over five bones) small enough for a unit test, walking.
const char* const kScene = "thigh13";
const std::vector<std::string> kOverrides = {"resolution=8"};
constexpr int kSteps = 4;
/// Across thread counts: largest particle distance allowed [m] (a thousandth of the particle
/// spacing at this resolution). Tasks own whole muscles, so today the results agree exactly;
/// the tolerance admits a different summation order in reductions over muscles.
constexpr double kThreadTolerance = 1e-5;

/// A prepared scene in a MuscleSystem with `threads` worker threads.
struct Simulation {
  LoadedScene scene;
  PreparedScene prepared;
  std::unique_ptr<MuscleSystem> system;
  std::vector<BoneHandle> bones;
  std::vector<MuscleHandle> muscles;

  explicit Simulation(int threads)
      : scene(loadScene(kScene, kOverrides)),
        prepared(prepareScene(scene.bones, scene.muscles, scene.simulation.seed)) {
    MuscleSystemDef parameters = scene.simulation;
    parameters.threads = threads;
    system = std::make_unique<MuscleSystem>(parameters);
    for (const auto& bone : prepared.bones) bones.push_back(system->addBone(bone));
    for (const auto& muscle : prepared.muscles) muscles.push_back(system->addMuscle(muscle, bones));
  }
  void step(int s) {
    const int pose = std::min(s, std::max(scene.poseCount, 1) - 1);
    for (size_t b = 0; b < bones.size(); ++b)
      system->setBoneTransform(bones[b], scene.bonePose(b, pose));
    system->step();
  }
  /// Every particle and surface vertex of every muscle, in order.
  std::vector<btVector3> output() const {
    std::vector<btVector3> all;
    for (MuscleHandle m : muscles) {
      const auto x = system->positions(m);
      const auto surface = system->surface(m);
      all.insert(all.end(), x.begin(), x.end());
      all.insert(all.end(), surface.begin(), surface.end());
    }
    return all;
  }
};

/// Index of the first value that differs in any bit (size() when none does).
size_t firstDifference(const std::vector<btVector3>& a, const std::vector<btVector3>& b) {
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i)
    if (std::memcmp(a[i].m_floats, b[i].m_floats, 3 * sizeof(btScalar)) != 0) return i;
  return a.size() == b.size() ? a.size() : std::min(a.size(), b.size());
}

double largestDistance(const std::vector<btVector3>& a, const std::vector<btVector3>& b) {
  double largest = 0;
  for (size_t i = 0; i < a.size(); ++i) largest = std::max(largest, double(a[i].distance(b[i])));
  return largest;
}

class SameThreadCount : public ::testing::TestWithParam<int> {};

TEST_P(SameThreadCount, TwoSystemsSideBySideAgreeBitForBit) {
  Simulation first(GetParam()), second(GetParam());
  ASSERT_EQ(first.muscles.size(), second.muscles.size());
  ASSERT_GT(first.muscles.size(), 1u);
  ASSERT_EQ(first.output().size(), second.output().size());
  EXPECT_EQ(firstDifference(first.output(), second.output()), first.output().size())
      << "prepared rest state";
  for (int s = 0; s < kSteps; ++s) {
    first.step(s);
    second.step(s);
    const std::vector<btVector3> a = first.output(), b = second.output();
    ASSERT_EQ(firstDifference(a, b), a.size()) << "step " << s;
    EXPECT_EQ(first.system->lastStep().iterations, second.system->lastStep().iterations);
    EXPECT_EQ(first.system->lastStep().lastTimeStep, second.system->lastStep().lastTimeStep);
    EXPECT_EQ(first.system->lastStep().contacts, second.system->lastStep().contacts);
  }
}

INSTANTIATE_TEST_SUITE_P(Threads, SameThreadCount, ::testing::Values(1, 2, 4));

TEST(Determinism, ThreadCountsAgreeWithinTolerance) {
  Simulation one(1), two(2), four(4);
  for (int s = 0; s < kSteps; ++s) {
    one.step(s);
    two.step(s);
    four.step(s);
    const std::vector<btVector3> reference = one.output();
    EXPECT_LE(largestDistance(reference, two.output()), kThreadTolerance)
        << "2 threads, step " << s;
    EXPECT_LE(largestDistance(reference, four.output()), kThreadTolerance)
        << "4 threads, step " << s;
    EXPECT_EQ(one.system->lastStep().iterations, four.system->lastStep().iterations);
  }
  // The comparison is about a moving simulation, not a resting one.
  Simulation rest(1);
  EXPECT_GT(largestDistance(rest.output(), one.output()), 100 * kThreadTolerance);
}

}  // namespace
}  // namespace fibremss
