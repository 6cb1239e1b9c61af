// The solver's threads (fibremss/TaskPool.h, MuscleSystemStep.cpp) and a host's
// scheduler in their place (fibremss/TaskScheduler.h): every task runs once on a valid thread, and
// a step gives bit-identical particles for any thread count, because each task's work is
// independent and every sum runs in a fixed order (a muscle's force chunks too: ForceChunks.h);
// frozen muscles only ride with their bones; a step with force chunks allocates nothing.
#include <BulletCollision/CollisionShapes/btBoxShape.h>
#include <BulletDynamics/Dynamics/btRigidBody.h>
#include <LinearMath/btAlignedAllocator.h>
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "fibremss/Error.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "kernels/ForceChunks.h"
#include "kernels/VolumeForces.h"
#include "solver/MuscleSystemAccess.h"
#include "support/AllocationCounter.h"
#include "support/BackwardsScheduler.h"
#include "support/BoxMuscle.h"
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

TEST(TaskPool, ASystemThatStartsFewerThreadsIsAnInputErrorNotAnAbort) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "AddressSanitizer maps terabytes of shadow memory: no address-space limit fits";
#endif
  const pid_t child = ::fork();
  if (child == 0) {  // room for a few thread stacks above what the process maps now
    long pages = 0;
    std::ifstream("/proc/self/statm") >> pages;
    const rlim_t bytes = rlim_t(pages) * rlim_t(::sysconf(_SC_PAGESIZE)) + (rlim_t{48} << 20);
    const rlimit limit{bytes, bytes};
    int code = ::setrlimit(RLIMIT_AS, &limit) == 0 ? 3 : 4;
    try {
      TaskPool pool(64);
    } catch (const InputError& e) {
      code = std::string(e.what()).find("simulation.threads") != std::string::npos ? 0 : 2;
    }
    ::_exit(code);  // 3: every thread started, no limit reached
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status)) << "ended by signal " << WTERMSIG(status);
  EXPECT_EQ(WEXITSTATUS(status), 0);
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

/// Expects `other` (a run on `threads` threads) to have `one`'s bits: every muscle's particles,
/// surface and force residual, and the last iteration's contacts.
void expectSameBits(const Outcome& one, const Outcome& other, int threads) {
  ASSERT_EQ(other.positions.size(), one.positions.size());
  for (size_t m = 0; m < one.positions.size(); ++m) {
    EXPECT_TRUE(sameBits(one.positions[m], other.positions[m]))
        << "muscle " << m << ", " << threads << " threads";
    EXPECT_TRUE(sameBits(one.surfaces[m], other.surfaces[m]))
        << "muscle " << m << ", " << threads << " threads";
    EXPECT_TRUE(sameBits(one.residuals[m], other.residuals[m]))
        << "muscle " << m << ", " << threads << " threads";
  }
  EXPECT_EQ(other.contacts, one.contacts);
  EXPECT_EQ(other.residual.rmsDisplacement, one.residual.rmsDisplacement) << threads << " threads";
  EXPECT_EQ(other.residual.maxForce, one.residual.maxForce) << threads << " threads";
  EXPECT_EQ(other.residual.contactParticles, one.residual.contactParticles);
}

}  // namespace

TEST(Threads, AnyThreadCountGivesTheSameBits) {
  const Outcome one = simulate(1);
  EXPECT_GT(one.contacts, 0u);                   // the muscles touch: the muscle pairs ran
  EXPECT_GT(one.residual.contactParticles, 0u);  // and the residual has particles they hold
  EXPECT_GT(one.residual.rmsDisplacement, 0);
  for (int threads : {2, 3}) expectSameBits(one, simulate(threads), threads);
}

// The projective solver refactors a muscle's matrix when its contacts change, inside that
// muscle's task: the same bits for any thread count too.
TEST(Threads, TheProjectiveSolversContactsGiveTheSameBits) {
  const auto run = [](int threads) {
    LoadedScene scene;
    const PreparedScene& prepared = fibremss::testing::preparedThigh(scene);
    scene.simulation.integrator = Integrator::Projective;
    return fibremss::testing::stepThroughPoses(scene, prepared, prepared.muscles, threads);
  };
  const Outcome one = run(1);
  EXPECT_GT(one.contacts, 0u);
  for (int threads : {2, 3}) expectSameBits(one, run(threads), threads);
}

namespace {

/// hip-pelvis at resolution 8 (three muscles pressed on the pelvis from the first poses),
/// prepared once, with the surface push.
const PreparedScene& preparedHipPelvis(LoadedScene& scene) {
  static LoadedScene loaded = loadScene("hip-pelvis", {"resolution=8", "surface_push=true"});
  static const PreparedScene prepared =
      prepareScene(loaded.bones, loaded.muscles, loaded.simulation.seed);
  scene = loaded;
  return prepared;
}

}  // namespace

// The surface push runs in each muscle's own bone contact: the same bits for any thread count;
// and it moves the muscles (it ran).
TEST(Threads, TheSurfacePushGivesTheSameBits) {
  const auto run = [](int threads, bool push) {
    LoadedScene scene;
    const PreparedScene& prepared = preparedHipPelvis(scene);
    scene.simulation.surfacePush = push;
    return fibremss::testing::stepThroughPoses(scene, prepared, prepared.muscles, threads);
  };
  const Outcome one = run(1, true);
  const Outcome off = run(1, false);
  size_t moved = 0;
  for (size_t m = 0; m < one.positions.size(); ++m)
    moved += sameBits(one.positions[m], off.positions[m]) ? 0 : 1;
  EXPECT_GT(moved, 0u);
  for (int threads : {2, 3}) expectSameBits(one, run(threads, true), threads);
}

namespace {

/// The first two muscles of thigh13 stepped as simulate() does with `threads` threads (0: on
/// backwards(), reported as 0 threads), their forces passes split into chunks of about `chunkWork`
/// (resolution 8 gives about 1 000 springs and 500 tetrahedra per muscle); checks that each has
/// more than one chunk when `chunked`.
Outcome simulateChunked(int threads, size_t chunkWork, bool chunked) {
  LoadedScene scene;
  const PreparedScene& prepared = fibremss::testing::preparedThigh(scene);
  if (threads == 0) scene.simulation.scheduler = fibremss::testing::backwards();
  return fibremss::testing::stepThroughPoses(
      scene, prepared, {prepared.muscles[0], prepared.muscles[1]}, std::max(threads, 1),
      [&](MuscleSystem& system, const std::vector<MuscleHandle>& handles) {
        MuscleSystemAccess::Impl& impl = MuscleSystemAccess::impl(system);
        impl.forceChunkWork = chunkWork;
        impl.prepareWorkers();  // plans the chunks
        for (MuscleHandle handle : handles)
          EXPECT_EQ(impl.muscles.states[handle.index]->forceChunks.size() > 1, chunked);
      });
}

}  // namespace

// Chunks of one muscle finish in another order on other thread counts, and in the reverse order
// on a scheduler that runs the tasks backwards: each chunk sums into its own buffer and the
// buffers are added in chunk order, so the bits do not change (summed in the order they finish,
// the backwards run's would). Against one task per muscle the chunks may change the bits, by
// rounding only.
TEST(Threads, ChunkedForcesGiveTheSameBitsInAnyOrder) {
  constexpr size_t kWork = 100;
  const Outcome one = simulateChunked(1, kWork, true);
  for (int threads : {0, 2, 3}) expectSameBits(one, simulateChunked(threads, kWork, true), threads);
  const Outcome whole = simulateChunked(1, SIZE_MAX, false);
  double largest = 0;
  for (size_t m = 0; m < one.positions.size(); ++m)
    for (size_t i = 0; i < one.positions[m].size(); ++i)
      largest = std::max(largest, double(one.positions[m][i].distance(whole.positions[m][i])));
  EXPECT_LT(largest, 1e-4);  // metres: rounding, against a particle spacing of centimetres
}

// Every kernel's chunks take each spring and tetrahedron once, in ranges that begin where the
// kernel may begin (a run of one a, a group of eight lanes; for the fans a whole number of lane
// groups into a class of fans, or its end), and touch only particles inside their window; their
// forces add up to the whole pass's (to rounding).
TEST(ForceChunks, TakeEverySpringAndTetrahedronOnce) {
  LoadedScene scene;
  const MuscleSettings& settings = *fibremss::testing::preparedThigh(scene).muscles.front();
  const size_t n = settings.particleCount();
  std::vector<btVector3> x(settings.restPositions.begin(), settings.restPositions.end());
  for (size_t i = 0; i < n; ++i)  // off rest, so that every spring and tetrahedron pulls
    x[i] += btVector3(btScalar(1e-3) * std::sin(btScalar(i)),
                      btScalar(1e-3) * std::cos(btScalar(i)), 0);
  for (SpringKernel kernel : {SpringKernel::scalar, SpringKernel::sse2, SpringKernel::avx2}) {
    if (!springKernelAvailable(kernel)) continue;
    const std::vector<ForceChunk> chunks = forceChunks(settings, kernel, 300);
    ASSERT_GT(chunks.size(), 3u) << springKernelName(kernel);
    EXPECT_EQ(chunks.front().springBegin, 0u);
    EXPECT_EQ(chunks.back().springEnd, springLayoutSize(settings, kernel));
    EXPECT_EQ(chunks.back().fanEnd(), settings.fanInverseVolume.size());
    std::vector<btVector3> whole(n), sum(n, btVector3(0, 0, 0)), part(n);
    springForces(settings, x, whole, kernel);
    addLocalVolumeForces(settings, x, whole, kernel);
    for (size_t c = 0; c < chunks.size(); ++c) {
      const ForceChunk& chunk = chunks[c];
      if (c > 0) {
        EXPECT_EQ(chunk.springBegin, chunks[c - 1].springEnd);
        EXPECT_EQ(chunk.fanBegin(), chunks[c - 1].fanEnd());
      }
      EXPECT_EQ(springLayoutBoundary(settings, kernel, chunk.springBegin), chunk.springBegin);
      const auto count = [&](size_t k) {
        return settings.fanOffsets[k + 1] - settings.fanOffsets[k];
      };
      size_t classStart = chunk.fanEnd();  // of the class fan fanEnd − 1 and fanEnd share, if any
      if (chunk.fanEnd() < settings.fanInverseVolume.size() && chunk.fanEnd() > 0 &&
          count(chunk.fanEnd() - 1) == count(chunk.fanEnd()))
        while (classStart > 0 && count(classStart - 1) == count(chunk.fanEnd())) --classStart;
      EXPECT_EQ((chunk.fanEnd() - classStart) % kFanLaneGroup, 0u) << "chunk " << c;
      std::fill(part.begin(), part.end(), btVector3(0, 0, 0));
      addSpringForces(settings, x, part, kernel, chunk.springBegin, chunk.springEnd);
      addLocalVolumeForces(settings, x, part, kernel, chunk.fanBegin(), chunk.fanEnd());
      for (uint32_t i = 0; i < n; ++i) {
        const bool outside = i < chunk.lower || i >= chunk.upper;
        EXPECT_TRUE(!outside || part[i] == btVector3(0, 0, 0))
            << "chunk " << c << ", particle " << i;
        sum[i] += part[i];
      }
    }
    double largest = 0, scale = 0;
    for (size_t i = 0; i < n; ++i) {
      largest = std::max(largest, double((sum[i] - whole[i]).length()));
      scale = std::max(scale, double(whole[i].length()));
    }
    EXPECT_GT(scale, 0);
    EXPECT_LT(largest, 1e-5 * scale) << springKernelName(kernel);
  }
}

// A chunk's buffer added to the muscle's forces lane by lane and left clear, whatever the length
// (the wide kernel's blocks and the rest): the bits of the scalar sums.
TEST(ForceChunks, BuffersMoveLaneByLane) {
  for (size_t n : {0, 1, 3, 4, 5, 9, 37}) {
    std::vector<btVector3> to(n), from(n), expected(n);
    for (size_t i = 0; i < n; ++i) {
      const auto v = static_cast<btScalar>(i);
      to[i] = btVector3(std::sin(v), btScalar(1) / (v + 3), -v);
      from[i] = btVector3(std::cos(v), v * btScalar(0.1), btScalar(1) / (v + 7));
      for (int k = 0; k < 4; ++k) expected[i].m_floats[k] = to[i].m_floats[k] + from[i].m_floats[k];
    }
    moveForces(to, from);
    // memcmp's pointers must not be null, which an empty vector's data() may be.
    if (n > 0) {
      EXPECT_EQ(std::memcmp(to.data(), expected.data(), n * sizeof(btVector3)), 0) << n;
    }
    for (const btVector3& v : from) EXPECT_EQ(v, btVector3(0, 0, 0)) << n;
    clearForces(to);
    for (const btVector3& v : to) EXPECT_EQ(v, btVector3(0, 0, 0)) << n;
  }
}

TEST(Threads, PreparationGivesTheSameBitsForAnyThreadCount) {
  const LoadedScene scene = loadScene("hip-flexion");  // four muscles: tasks to share
  const PreparedScene one = prepareScene(scene.bones, scene.muscles, scene.simulation.seed, 1);
  const PreparedScene two = prepareScene(scene.bones, scene.muscles, scene.simulation.seed, 2);
  ASSERT_EQ(one.muscles.size(), two.muscles.size());
  for (size_t m = 0; m < one.muscles.size(); ++m) {
    const MuscleSettings &a = *one.muscles[m], &b = *two.muscles[m];
    EXPECT_TRUE(sameBits(a.restPositions, b.restPositions)) << "muscle " << m;
    ASSERT_EQ(a.radii.size(), b.radii.size());
    EXPECT_EQ(std::memcmp(a.radii.data(), b.radii.data(), a.radii.size() * sizeof(btScalar)), 0);
    EXPECT_EQ(a.springs.size(), b.springs.size()) << "muscle " << m;
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

namespace {

/// A host application's task system in the Box2D v3 style: every enqueued task runs on worker
/// threads of the host's own (started per task, ranges handed out by a counter), never on the
/// caller's; it counts the tasks and items it ran.
class HostScheduler {
 public:
  explicit HostScheduler(uint32_t workers) : workers_(workers) {}

  TaskScheduler scheduler() { return {&enqueue, &finish, this, workers_}; }
  size_t tasks() const { return tasks_.load(); }
  size_t items() const { return items_.load(); }

 private:
  struct Job {
    TaskCallback task = nullptr;
    void* context = nullptr;
    uint32_t count = 0;
    std::atomic<uint32_t> next{0};
    std::vector<std::thread> threads;
  };

  static void* enqueue(TaskCallback task, uint32_t count, uint32_t minRange, void* context,
                       void* user) {
    HostScheduler& host = *static_cast<HostScheduler*>(user);
    auto job = std::make_unique<Job>();
    job->task = task;
    job->context = context;
    job->count = count;
    ++host.tasks_;
    const uint32_t range = std::max(1u, minRange);
    for (uint32_t worker = 0; worker < host.workers_; ++worker)
      job->threads.emplace_back([&host, running = job.get(), worker, range] {
        for (uint32_t begin = running->next.fetch_add(range); begin < running->count;
             begin = running->next.fetch_add(range)) {
          const uint32_t end = std::min(running->count, begin + range);
          running->task(begin, end, worker, running->context);
          host.items_ += end - begin;
        }
      });
    return job.release();
  }

  static void finish(void* handle, void*) {
    const std::unique_ptr<Job> job(static_cast<Job*>(handle));
    for (std::thread& thread : job->threads) thread.join();
  }

  uint32_t workers_;
  std::atomic<size_t> tasks_{0};
  std::atomic<size_t> items_{0};
};

}  // namespace

// MuscleSystemDef::scheduler: the host's task system runs every task of the step (none on
// the plugin's pool, which starts no thread) with the same bits as the plugin's own threads.
TEST(HostScheduler, RunsTheStepWithTheSameBitsAsThePool) {
  const Outcome own = simulate(1);
  HostScheduler host(3);
  LoadedScene scene;
  const PreparedScene& prepared = fibremss::testing::preparedThigh(scene);
  scene.simulation.scheduler = host.scheduler();
  const Outcome hosted = fibremss::testing::stepThroughPoses(
      scene, prepared, prepared.muscles, 2,
      [&](MuscleSystem& system, const std::vector<MuscleHandle>&) {
        EXPECT_EQ(system.threads(), 3u);
      });
  EXPECT_GT(host.tasks(), 2u * 20u);  // several tasks per iteration, 20 iterations per step
  EXPECT_GE(host.items(), host.tasks());
  for (size_t m = 0; m < own.positions.size(); ++m) {
    EXPECT_TRUE(sameBits(own.positions[m], hosted.positions[m])) << "muscle " << m;
    EXPECT_TRUE(sameBits(own.surfaces[m], hosted.surfaces[m])) << "muscle " << m;
  }
  EXPECT_EQ(hosted.contacts, own.contacts);
}

TEST(HostScheduler, RunsPreparationWithTheSameBits) {
  const LoadedScene scene = loadScene("hip-flexion");
  const PreparedScene own = prepareScene(scene.bones, scene.muscles, scene.simulation.seed, 1);
  HostScheduler host(2);
  const PreparedScene hosted =
      prepareScene(scene.bones, scene.muscles, scene.simulation.seed, 1, host.scheduler());
  EXPECT_GE(host.tasks(), 5u);  // bones, three muscle stages, coverage
  EXPECT_GE(host.items(), scene.bones.size() + 4 * scene.muscles.size());
  ASSERT_EQ(own.muscles.size(), hosted.muscles.size());
  for (size_t m = 0; m < own.muscles.size(); ++m) {
    EXPECT_TRUE(sameBits(own.muscles[m]->restPositions, hosted.muscles[m]->restPositions));
    EXPECT_EQ(own.muscles[m]->springs.size(), hosted.muscles[m]->springs.size());
  }
}

namespace fibremss {
namespace {

using testing::makeBone;
using testing::makeBox;
using testing::zelenyDamping;

// A step allocates nothing, with each muscle's forces in one task and in chunks (a chunk work
// below the default splits these small boxes).
TEST(Allocation, StepAllocatesNothing) {
  btAlignedAllocSetCustom(testing::countingAlloc, std::free);
  {
    MuscleSystemDef parameters = testing::verletDef();
    parameters.stepSettings.iterations = 20;
    // A box pressed into the side of the first muscle: the contact body path.
    btBoxShape boxShape(btVector3(0.004f, 0.01f, 0.005f));
    btRigidBody box(0.05f, nullptr, &boxShape, btVector3(1e-5f, 1e-5f, 1e-5f));
    box.setWorldTransform(
        btTransform(btQuaternion::getIdentity(), btVector3(-0.0055f, 0.005f, 0.015f)));
    box.setLinearVelocity(btVector3(0.05f, 0, 0));  // moving in: impulses in every step
    const btCollisionObject* bodies[] = {&box};
    // The forces of a box in one task, and in chunks (kForceChunkWork splits larger muscles).
    for (size_t chunkWork : {kForceChunkWork, size_t{64}})
      for (bool rebuild : {false, true})
        for (bool contact : {false, true}) {
          parameters.rebuildEveryStep = rebuild;
          // The residual rule checks (never met at 0) run in the step too.
          parameters.stepSettings.stopRule = StopRule::Residual;
          parameters.stepSettings.tolerance = 0;
          MuscleSystem system(parameters);
          MuscleSystemAccess::impl(system).forceChunkWork = chunkWork;
          const BoneHandle bone = system.addBone(makeBone({{0.005, 0.005, 0.03}}, {0.006}));
          auto a = makeBox(3, 3, 8, 0.005, 1, 1.0, 3e-5, 0);
          auto b = makeBox(3, 3, 8, 0.005, 1, 1.0, 3e-5, 0, btVector3(0.012, 0.002, 0.001));
          a->damping = b->damping = zelenyDamping(*a);
          system.addMuscle(a, std::span(&bone, 1));
          system.addMuscle(b, std::span(&bone, 1));
          if (contact) system.setContactBodies(bodies);
          size_t contacts = 0, touched = 0;
          testing::allocationCount = 0;
          testing::countingArmed = true;
          for (int s = 0; s < 10; ++s) {
            system.setBoneTransform(bone, btTransform(btQuaternion(btVector3(0, 0, 1), 0.05 * s)));
            system.step();
            contacts += system.lastStep().contacts;
            touched += system.bodyContact(&box).impulse.isZero() ? 0 : 1;
          }
          testing::countingArmed = false;
          EXPECT_GT(contacts, 0u);  // collision ran
          if (contact) {
            EXPECT_GT(touched, 0u) << "the box touched";
          }
          EXPECT_EQ(MuscleSystemAccess::impl(system).chunked, chunkWork < kForceChunkWork);
          EXPECT_EQ(testing::allocationCount.load(), 0)
              << (rebuild ? "rebuild" : "animation") << " mode" << (contact ? ", contact body" : "")
              << ", chunks of " << chunkWork;
        }
  }
  btAlignedAllocSetCustom(nullptr, nullptr);
}

// With the surface push (hip-pelvis' muscles pressed on the pelvis) a step allocates nothing.
TEST(Allocation, StepsWithTheSurfacePushAllocateNothing) {
  LoadedScene scene;
  const PreparedScene& prepared = preparedHipPelvis(scene);
  btAlignedAllocSetCustom(testing::countingAlloc, std::free);
  testing::allocationCount = 0;
  const testing::StepOutcome outcome = testing::stepThroughPoses(
      scene, prepared, prepared.muscles, 1,
      [](MuscleSystem&, const std::vector<MuscleHandle>&) { testing::countingArmed = true; },
      [] { testing::countingArmed = false; });
  btAlignedAllocSetCustom(nullptr, nullptr);
  EXPECT_GT(outcome.contacts, 0u);
  EXPECT_EQ(testing::allocationCount.load(), 0);
}

}  // namespace
}  // namespace fibremss
