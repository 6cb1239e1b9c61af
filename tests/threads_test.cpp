// The solver's threads (plugin/core/src/solver/TaskPool.h, MuscleSystemStep.cpp): every task runs
// once on a valid thread, and a step gives bit-identical particles for any thread count, because
// each muscle's work is independent and every sum runs in a fixed order; frozen muscles only ride
// with their bones.
#include <gtest/gtest.h>

#include <atomic>
#include <cstring>
#include <memory>
#include <vector>

#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "solver/MuscleSystemAccess.h"
#include "support/ThighSteps.h"

using namespace fibremss;

TEST(TaskPool, RunsEveryTaskOnceOnAThreadItOwns) {
  for (unsigned threads : {1u, 2u, 3u}) {
    TaskPool pool(threads);
    ASSERT_EQ(pool.threads(), threads);
    for (size_t count : {size_t{0}, size_t{1}, size_t{7}, size_t{1000}}) {
      std::vector<std::atomic<int>> runs(count);
      std::atomic<bool> threadInRange{true};
      pool.run(count, [&](size_t index, unsigned thread) {
        runs[index].fetch_add(1);
        if (thread >= threads) threadInRange = false;
      });
      for (size_t i = 0; i < count; ++i) EXPECT_EQ(runs[i].load(), 1) << i << " of " << count;
      EXPECT_TRUE(threadInRange.load());
    }
  }
}

TEST(TaskPool, ZeroMeansTheHardwareThreads) {
  EXPECT_EQ(TaskPool::resolve(0), std::max(1u, std::thread::hardware_concurrency()));
  EXPECT_EQ(TaskPool::resolve(3), 3u);
}

namespace {

using Outcome = fibremss::testing::StepOutcome;

/// Two steps through the first poses with `threads` threads; `freeze` (if ≥ 0) freezes that
/// muscle before stepping; `alone`: that muscle is the only one added.
Outcome simulate(int threads, int freeze = -1, bool alone = false) {
  LoadedScene scene;
  const PreparedScene& prepared = fibremss::testing::preparedThigh(scene);
  std::vector<std::shared_ptr<const MuscleSettings>> muscles;
  for (size_t m = 0; m < prepared.muscles.size(); ++m)
    if (!alone || static_cast<int>(m) == freeze) muscles.push_back(prepared.muscles[m]);
  return fibremss::testing::stepThroughPoses(
      scene, prepared, muscles, threads,
      [&](MuscleSystem& system, const std::vector<MuscleHandle>& handles) {
        if (freeze >= 0)
          MuscleSystemAccess::impl(system)
              .muscles.states[handles[alone ? 0 : freeze].index]
              ->frozen = true;
      });
}

bool sameBits(const std::vector<btVector3>& a, const std::vector<btVector3>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(btVector3)) == 0;
}

}  // namespace

TEST(Threads, AnyThreadCountGivesTheSameBits) {
  const Outcome one = simulate(1);
  EXPECT_GT(one.contacts, 0u);  // the muscles touch: the muscle pairs ran
  for (int threads : {2, 3}) {
    const Outcome many = simulate(threads);
    ASSERT_EQ(many.positions.size(), one.positions.size());
    for (size_t m = 0; m < one.positions.size(); ++m) {
      EXPECT_TRUE(sameBits(one.positions[m], many.positions[m]))
          << "muscle " << m << ", " << threads << " threads";
      EXPECT_TRUE(sameBits(one.surfaces[m], many.surfaces[m]))
          << "muscle " << m << ", " << threads << " threads";
    }
    EXPECT_EQ(many.contacts, one.contacts);
  }
}

// Pairs whose contacts overflow their records (room for one) are traversed again by both muscles'
// tasks at once, each with its thread's stack: still the same bits as the recorded pushes.
TEST(Threads, ContactsBeyondTheirRecordsGiveTheSameBits) {
  LoadedScene scene;
  const PreparedScene& prepared = fibremss::testing::preparedThigh(scene);
  const auto cramped = [&](int threads) {
    return fibremss::testing::stepThroughPoses(
        scene, prepared, prepared.muscles, threads,
        [](MuscleSystem& system, const std::vector<MuscleHandle>&) {
          MuscleSystemAccess::Impl& impl = MuscleSystemAccess::impl(system);
          for (uint32_t slot : impl.muscles.order)
            for (CandidateList& list : impl.muscles.states[slot]->muscleLists)
              list.pairs = std::vector<CandidatePair>(1);
        });
  };
  const Outcome roomy = simulate(1);
  for (int threads : {1, 3}) {
    const Outcome many = cramped(threads);
    for (size_t m = 0; m < roomy.positions.size(); ++m)
      EXPECT_TRUE(sameBits(roomy.positions[m], many.positions[m]))
          << "muscle " << m << ", " << threads << " threads";
    EXPECT_EQ(many.contacts, roomy.contacts);
  }
}

TEST(Threads, AFrozenMuscleIsSkippedByEveryPart) {
  const Outcome moving = simulate(2);
  const Outcome frozen = simulate(2, 0);
  // It only rides with its bones (MuscleSystemGuard.cpp): exactly as it does alone, on one thread;
  // no part of the step, the pairs with the other muscles included, touched it.
  const Outcome alone = simulate(1, 0, true);
  EXPECT_TRUE(sameBits(frozen.positions[0], alone.positions[0]));
  EXPECT_TRUE(sameBits(frozen.surfaces[0], alone.surfaces[0]));
  EXPECT_FALSE(sameBits(moving.positions[0], frozen.positions[0]));
}
