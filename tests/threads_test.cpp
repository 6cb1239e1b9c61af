// The solver's threads (plugin/src/TaskPool.h, MuscleSystemStep.cpp): every task runs once on
// a valid thread, and a step gives bit-identical particles for any thread count, because each
// muscle's work is independent and every sum runs in a fixed order; frozen muscles stay put.
#include <gtest/gtest.h>

#include <atomic>
#include <cstring>
#include <memory>
#include <vector>

#include "../plugin/src/MuscleSystemAccess.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"

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

/// thigh13 at a low resolution (13 muscles, many muscle pairs), prepared once.
const PreparedScene& thigh(LoadedScene& scene) {
  static LoadedScene loaded = loadScene("thigh13", {"resolution=8"});
  static const PreparedScene prepared =
      prepareScene(loaded.bones, loaded.muscles, loaded.simulation.seed);
  scene = loaded;
  return prepared;
}

struct Outcome {
  std::vector<std::vector<btVector3>> positions;  ///< per muscle after the steps
  std::vector<std::vector<btVector3>> surfaces;   ///< per muscle after the steps
  size_t contacts = 0;                            ///< contacts of the last iteration
};

/// Two steps through the first poses with `threads` threads; `freeze` (if ≥ 0) freezes that
/// muscle before stepping.
Outcome simulate(int threads, int freeze = -1) {
  LoadedScene scene;
  const PreparedScene& prepared = thigh(scene);
  SimulationParameters parameters = scene.simulation;
  parameters.threads = threads;
  parameters.iterations = 20;
  MuscleSystem system(parameters);
  std::vector<BoneHandle> bones;
  for (const auto& bone : prepared.bones) bones.push_back(system.addBone(bone));
  std::vector<MuscleHandle> muscles;
  for (const auto& muscle : prepared.muscles) muscles.push_back(system.addMuscle(muscle, bones));
  if (freeze >= 0)
    MuscleSystemAccess::impl(system).muscles.states[muscles[freeze].index]->frozen = true;
  for (int pose = 1; pose <= 2; ++pose) {
    for (size_t b = 0; b < bones.size(); ++b)
      system.setBoneTransform(bones[b], scene.bonePose(b, pose % scene.poseCount));
    system.step();
  }
  Outcome run;
  for (MuscleHandle muscle : muscles) {
    auto x = system.positions(muscle);
    auto surface = system.surface(muscle);
    run.positions.emplace_back(x.begin(), x.end());
    run.surfaces.emplace_back(surface.begin(), surface.end());
  }
  run.contacts = system.lastStep().contacts;
  return run;
}

bool sameBits(const std::vector<btVector3>& a, const std::vector<btVector3>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(btVector3)) == 0;
}

}  // namespace

TEST(Threads, AnyThreadCountGivesTheSameBits) {
  const Outcome one = simulate(1);
  EXPECT_GT(one.contacts, 0u);  // the muscles touch: the pair rounds ran
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

TEST(Threads, AFrozenMuscleIsSkippedByEveryPart) {
  LoadedScene scene;
  const PreparedScene& prepared = thigh(scene);
  const Outcome moving = simulate(2);
  const Outcome frozen = simulate(2, 0);
  // Where it was added: placed at its bones, never stepped.
  MuscleSystem reference(scene.simulation);
  std::vector<BoneHandle> bones;
  for (const auto& bone : prepared.bones) bones.push_back(reference.addBone(bone));
  const MuscleHandle first = reference.addMuscle(prepared.muscles[0], bones);
  auto start = reference.positions(first);
  EXPECT_TRUE(sameBits(frozen.positions[0], {start.begin(), start.end()}));
  EXPECT_FALSE(sameBits(moving.positions[0], frozen.positions[0]));
}
