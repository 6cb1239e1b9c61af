// fibremss_bench: Google Benchmark suite of the step's kernels on thigh13 (R = 20, 40), each
// timed alone on one thread while the other parts of the iteration run untimed, plus whole
// iterations with 1 and 2 threads, and the haptic query MuscleWorld/MuscleSystem::contactWrench
// of a probe pressed into a muscle. `fibremss_bench --callgrind-kernels R` instead runs each
// kernel once under callgrind's client requests (comparisons/bench/callgrind.sh);
// `fibremss_bench --thread-scaling R [ROUNDS]` alternates 1 and 2 threads in one run, alone and
// with a busy loop of its own on one core, and prints the medians and their ratio.
#include <BulletCollision/CollisionShapes/btSphereShape.h>
#include <BulletDynamics/Dynamics/btRigidBody.h>
#include <benchmark/benchmark.h>
#include <pthread.h>
#include <sched.h>
#include <valgrind/callgrind.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "BenchScene.h"

namespace fibremss::bench {
namespace {

/// Iterations per step in the whole-iteration benchmarks.
constexpr int kIterationsPerStep = 10;

/// One scene per (resolution, threads), prepared on first use and kept for later benchmarks.
BenchScene& sceneFor(int resolution, int threads) {
  static std::map<std::pair<int, int>, std::unique_ptr<BenchScene>> scenes;
  auto& scene = scenes[{resolution, threads}];
  if (!scene) scene = std::make_unique<BenchScene>(resolution, threads);
  return *scene;
}

/// Times one part; the parts before and after it run untimed so the state keeps evolving like
/// a simulation's.
void benchPart(benchmark::State& state, Part part) {
  BenchScene& scene = sceneFor(static_cast<int>(state.range(0)), 1);
  for (auto _ : state) {
    state.PauseTiming();
    for (Part before : kParts) {
      if (before == part) break;
      scene.run(before);
    }
    state.ResumeTiming();
    scene.run(part);
    state.PauseTiming();
    bool after = false;
    for (Part later : kParts) {
      if (after) scene.run(later);
      after = after || later == part;
    }
    state.ResumeTiming();
  }
  state.counters["particles"] = static_cast<double>(scene.particles());
}

/// Whole steps of kIterationsPerStep iterations, bones moving; reports time per iteration.
void benchIteration(benchmark::State& state) {
  BenchScene& scene = sceneFor(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  scene.system().parameters().iterations = kIterationsPerStep;
  scene.system().parameters().stopRule = StopRule::Iterations;
  for (auto _ : state) scene.stepPose();
  state.counters["iteration"] =
      benchmark::Counter(static_cast<double>(state.iterations() * kIterationsPerStep),
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["particles"] = static_cast<double>(scene.particles());
}

/// The haptic query: a kinematic sphere probe (radius 5 mm) pressed 2 mm into the surface of
/// thigh13's first muscle at the middle of a fibre, its contact taken by one step; then
/// contactWrench at a pose up to 0.2 mm deeper, moving by 25 µm per call (a device read at 1 kHz
/// between the muscles' steps). Its own scene: the contact body changes the others' steps.
void benchContactWrench(benchmark::State& state) {
  static std::map<int, std::unique_ptr<BenchScene>> scenes;
  const int resolution = static_cast<int>(state.range(0));
  auto& scene = scenes[resolution];
  if (!scene) scene = std::make_unique<BenchScene>(resolution, 1);
  MuscleSystem& system = scene->system();
  const MuscleHandle muscle = system.muscles().front();
  const MuscleSettings& settings = system.settings(muscle);
  const std::span<const btVector3> positions = system.positions(muscle);
  btVector3 centroid(0, 0, 0);
  for (const btVector3& p : positions) centroid += p;
  centroid /= static_cast<btScalar>(positions.size());
  // The middle particle of the first fibre whose middle is a free boundary particle.
  uint32_t middle = settings.boundaryParticles.front();
  for (size_t f = 0; f < settings.fibreCount(); ++f) {
    const uint32_t i =
        settings.fibreParticles[(settings.fibreOffsets[f] + settings.fibreOffsets[f + 1]) / 2];
    if (settings.isBoundary(i) && !settings.isFixed(i)) {
      middle = i;
      break;
    }
  }
  const btVector3 touched = positions[middle];
  const btScalar radius = btScalar(0.005);
  const btVector3 outward = (touched - centroid).normalized();
  const btScalar particleRadius = settings.radii[middle];
  const btVector3 centre = touched + outward * (radius + particleRadius - btScalar(0.002));
  btSphereShape shape(radius);
  btRigidBody probe(0, nullptr, &shape);
  probe.setCollisionFlags(probe.getCollisionFlags() | btCollisionObject::CF_KINEMATIC_OBJECT);
  probe.setWorldTransform(btTransform(btQuaternion::getIdentity(), centre));
  const btCollisionObject* bodies[] = {&probe};
  system.setContactBodies(bodies);
  system.step();  // bones still: the muscle takes the probe's dent
  state.counters["step_contacts"] = static_cast<double>(system.bodyContact(&probe).contacts);
  size_t contacts = 0;
  int call = 0;
  for (auto _ : state) {
    const btVector3 jitter = outward * (btScalar(2.5e-5) * static_cast<btScalar>(++call % 8));
    const ContactWrench wrench =
        system.contactWrench(probe, btTransform(btQuaternion::getIdentity(), centre - jitter));
    contacts = std::max(contacts, wrench.contacts);
    benchmark::DoNotOptimize(wrench);
  }
  system.setContactBodies({});
  state.counters["contacts"] = static_cast<double>(contacts);  // most in one query
  state.counters["particles"] = static_cast<double>(scene->particles());
}

void registerAll() {
  for (Part part : kParts)
    benchmark::RegisterBenchmark(partName(part), benchPart, part)
        ->Arg(20)
        ->Arg(40)
        ->Unit(benchmark::kMicrosecond);
  benchmark::RegisterBenchmark("iteration", benchIteration)
      ->ArgsProduct({{20, 40}, {1, 2}})
      ->ArgNames({"R", "threads"})
      ->Unit(benchmark::kMillisecond)
      ->UseRealTime();
  benchmark::RegisterBenchmark("contact-wrench", benchContactWrench)
      ->Arg(20)
      ->Arg(40)
      ->ArgName("R")
      ->Unit(benchmark::kMicrosecond);
}

/// Each kernel once (after two warm-up iterations), then one whole step of kIterationsPerStep
/// iterations (its output included), each between a zeroing and a named dump of callgrind's
/// counters.
int callgrindKernels(int resolution) {
  BenchScene scene(resolution, 1);
  for (int warm = 0; warm < 2; ++warm)
    for (Part part : kParts) scene.run(part);
  CALLGRIND_START_INSTRUMENTATION;
  for (Part part : kParts) {
    CALLGRIND_ZERO_STATS;
    scene.run(part);
    CALLGRIND_DUMP_STATS_AT(partName(part));
  }
  scene.system().parameters().iterations = kIterationsPerStep;
  scene.system().parameters().stopRule = StopRule::Iterations;
  CALLGRIND_ZERO_STATS;
  scene.stepPose();
  CALLGRIND_DUMP_STATS_AT("step-10-iterations");
  CALLGRIND_STOP_INSTRUMENTATION;
  return 0;
}

/// Milliseconds per iteration of `steps` whole steps of kIterationsPerStep iterations with
/// `threads` solver threads.
double msPerIteration(BenchScene& scene, int threads, int steps) {
  scene.system().parameters().threads = threads;
  scene.stepPose();  // starts the pool for this thread count outside the timing
  const auto start = std::chrono::steady_clock::now();
  for (int k = 0; k < steps; ++k) scene.stepPose();
  const std::chrono::duration<double, std::milli> elapsed =
      std::chrono::steady_clock::now() - start;
  return elapsed.count() / (steps * kIterationsPerStep);
}

double median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  const size_t n = values.size();
  return n % 2 ? values[n / 2] : (values[n / 2 - 1] + values[n / 2]) / 2;
}

/// A CPU-bound loop on core 0 (another process's work on one core) while it lives.
class BusyCore {
 public:
  BusyCore()
      : thread_([this] {
          cpu_set_t core;
          CPU_ZERO(&core);
          CPU_SET(0, &core);
          pthread_setaffinity_np(pthread_self(), sizeof(core), &core);
          volatile uint64_t spin = 0;
          while (!stop_.load(std::memory_order_relaxed)) spin = spin + 1;
        }) {}
  ~BusyCore() {
    stop_ = true;
    thread_.join();
  }

 private:
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

/// Thread scaling in one run (issue 18): 1 and 2 solver threads alternated `rounds` times on
/// thigh13 at `resolution`, then again with a busy loop on one core; medians per configuration.
int threadScaling(int resolution, int rounds) {
  BenchScene scene(resolution, 1);
  scene.system().parameters().iterations = kIterationsPerStep;
  scene.system().parameters().stopRule = StopRule::Iterations;
  constexpr int kSteps = 4;
  std::printf("thigh13 R=%d, %zu particles, %d rounds of %d iterations per configuration\n",
              resolution, scene.particles(), rounds, kSteps * kIterationsPerStep);
  for (const bool busy : {false, true}) {
    std::optional<BusyCore> loop;
    if (busy) loop.emplace();
    std::vector<double> one, two;
    for (int round = 0; round < rounds; ++round) {
      one.push_back(msPerIteration(scene, 1, kSteps));
      two.push_back(msPerIteration(scene, 2, kSteps));
    }
    std::ifstream loadavg("/proc/loadavg");
    std::string load;
    std::getline(loadavg, load);
    std::printf("%-22s 1 thread %.3f ms/iteration, 2 threads %.3f ms/iteration: %.2fx  (load %s)\n",
                busy ? "one core busy:" : "alone:", median(one), median(two),
                median(one) / median(two), load.c_str());
  }
  return 0;
}

}  // namespace
}  // namespace fibremss::bench

int main(int argc, char** argv) {
  if (argc == 3 && std::strcmp(argv[1], "--callgrind-kernels") == 0)
    return fibremss::bench::callgrindKernels(std::atoi(argv[2]));
  if (argc >= 3 && std::strcmp(argv[1], "--thread-scaling") == 0)
    return fibremss::bench::threadScaling(std::atoi(argv[2]), argc > 3 ? std::atoi(argv[3]) : 15);
  fibremss::bench::registerAll();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
