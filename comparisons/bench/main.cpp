// fibremss_bench: Google Benchmark suite of the step's kernels on thigh13 (R = 20, 40), each
// timed alone on one thread while the other parts of the iteration run untimed, plus whole
// iterations with 1 and 2 threads of Verlet and of the default solver (projective: its cost per
// iteration against Verlet's), and the haptic query MuscleWorld/MuscleSystem::contactWrench
// of a probe pressed into a muscle. `fibremss_bench --callgrind-kernels R` instead runs each
// kernel once under callgrind's client requests (comparisons/bench/callgrind.sh);
// `fibremss_bench --thread-scaling R [ROUNDS]` alternates 1 and 2 threads in one run, alone and
// with a busy loop of its own on one core, and prints the medians and their ratio;
// `fibremss_bench --implicit-surface R [ROUNDS]` measures the implicit surface
// (ImplicitSurfaceBench.cpp).
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
#include <tuple>
#include <utility>
#include <vector>

#include "BenchScene.h"
#include "ImplicitSurfaceBench.h"

namespace fibremss::bench {
namespace {

/// Iterations per step in the whole-iteration benchmarks.
constexpr int kIterationsPerStep = 10;

/// One scene per (resolution, threads, integrator), prepared on first use and kept for later
/// benchmarks.
BenchScene& sceneFor(int resolution, int threads, Integrator integrator = Integrator::Verlet) {
  static std::map<std::tuple<int, int, Integrator>, std::unique_ptr<BenchScene>> scenes;
  auto& scene = scenes[{resolution, threads, integrator}];
  if (!scene) scene = std::make_unique<BenchScene>(resolution, threads, integrator);
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

/// Whole steps of kIterationsPerStep iterations, bones moving; reports time per iteration (the
/// iterations counted: the default solver may run more per bone turn). The third argument: 0
/// Verlet, 1 the default solver (MuscleSystemDef::integrator).
void benchIteration(benchmark::State& state) {
  const Integrator integrator = state.range(2) ? MuscleSystemDef{}.integrator : Integrator::Verlet;
  BenchScene& scene =
      sceneFor(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)), integrator);
  scene.countIterations(kIterationsPerStep);
  int64_t iterations = 0;
  for (auto _ : state) {
    scene.stepPose();
    iterations += scene.system().lastStep().iterations;
  }
  state.counters["iteration"] = benchmark::Counter(
      static_cast<double>(iterations), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
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
      ->ArgsProduct({{20, 40}, {1, 2}, {0, 1}})
      ->ArgNames({"R", "threads", "default_solver"})
      ->Unit(benchmark::kMillisecond)
      ->UseRealTime();
  benchmark::RegisterBenchmark("contact-wrench", benchContactWrench)
      ->Arg(20)
      ->Arg(40)
      ->ArgName("R")
      ->Unit(benchmark::kMicrosecond);
}

/// Two iterations of every kernel, before any is counted.
void warmUp(BenchScene& scene) {
  for (int warm = 0; warm < 2; ++warm)
    for (Part part : kParts) scene.run(part);
}

/// One whole step of kIterationsPerStep iterations (its output included), counted as `name`.
/// Returns whether it ran exactly that many (the default solver's minimum per degree of a bone's
/// turn may add some), so that callgrind.sh's ratio of two such steps is one per iteration.
bool countStep(BenchScene& scene, const char* name) {
  scene.countIterations(kIterationsPerStep);
  CALLGRIND_ZERO_STATS;
  scene.stepPose();
  CALLGRIND_DUMP_STATS_AT(name);
  const int iterations = scene.system().lastStep().iterations;
  if (iterations == kIterationsPerStep) return true;
  std::fprintf(stderr, "%s ran %d iterations, not %d\n", name, iterations, kIterationsPerStep);
  return false;
}

/// Each kernel once (after two warm-up iterations), then one whole step of kIterationsPerStep
/// iterations, each between a zeroing and a named dump of callgrind's counters; then the default
/// solver's advance and step, its cost per iteration against Verlet's.
int callgrindKernels(int resolution) {
  BenchScene scene(resolution, 1);
  warmUp(scene);
  CALLGRIND_START_INSTRUMENTATION;
  for (Part part : kParts) {
    CALLGRIND_ZERO_STATS;
    scene.run(part);
    CALLGRIND_DUMP_STATS_AT(partName(part));
  }
  const bool verletExact = countStep(scene, "step-10-iterations");
  CALLGRIND_STOP_INSTRUMENTATION;
  BenchScene solver(resolution, 1, MuscleSystemDef{}.integrator);
  warmUp(solver);
  CALLGRIND_START_INSTRUMENTATION;
  CALLGRIND_ZERO_STATS;
  solver.run(Part::Integration);
  CALLGRIND_DUMP_STATS_AT("default-solver-integration");
  const bool solverExact = countStep(solver, "default-solver-step-10-iterations");
  CALLGRIND_STOP_INSTRUMENTATION;
  return verletExact && solverExact ? 0 : 1;
}

/// `steps` steps of the scene's poses; the iterations they ran (the guard's retries included).
int stepPoses(BenchScene& scene, int steps) {
  int iterations = 0;
  for (int k = 0; k < steps; ++k) {
    scene.stepPose();
    iterations += scene.system().lastStep().iterations;
  }
  return iterations;
}

/// Milliseconds per iteration of `steps` steps.
double msPerIteration(BenchScene& scene, int steps) {
  scene.stepPose();  // brings the scene back into the caches outside the timing
  const auto start = std::chrono::steady_clock::now();
  const int iterations = stepPoses(scene, steps);
  const std::chrono::duration<double, std::milli> elapsed =
      std::chrono::steady_clock::now() - start;
  return elapsed.count() / iterations;
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

/// The balance of an iteration's tasks at 1 thread, from thread CPU time (which
/// other processes' load does not inflate): per phase its share of the iteration, its largest
/// task's share of the phase and its speed-up on 2 threads under the pool's schedule of the
/// measured tasks; then two bounds of the whole iteration's speed-up on 2–4 threads, the work
/// outside tasks counted serial: the critical path (each phase max(largest task, work / T)) and
/// the pool's schedule (TaskProfile::Phase::scheduleMs).
void balanceReport(BenchScene& scene, int steps, size_t chunkWork) {
  MuscleSystem& system = scene.system();
  MuscleSystemAccess::impl(system).forceChunkWork = chunkWork;
  scene.stepPose();
  TaskProfile profile;
  TaskPool& pool = *MuscleSystemAccess::impl(system).pool;
  pool.attach(&profile);
  const int iterations = stepPoses(scene, steps);
  pool.attach(nullptr);
  const double perIteration = 1.0 / iterations;
  double tasksMs = 0, boundMs[4] = {}, scheduleMs[4] = {};
  for (const TaskProfile::Phase& phase : profile.phases) tasksMs += phase.taskMs * perIteration;
  const double serial = profile.outsideMs * perIteration;
  const double iterationMs = tasksMs + serial;
  std::printf("%-20s %8s %9s %10s %9s %12s %11s\n", "phase (1 thread)", "runs/it", "tasks/run",
              "CPU ms/it", "of the it", "largest task", "2 threads");
  for (const TaskProfile::Phase& phase : profile.phases) {
    if (!phase.name) break;
    for (unsigned t = 1; t < 4; ++t) {
      boundMs[t] += phase.boundMs[t] * perIteration;
      scheduleMs[t] += phase.scheduleMs[t] * perIteration;
    }
    std::printf("%-20s %8.2f %9.1f %10.4f %8.1f%% %11.1f%% %10.2fx\n", phase.name,
                static_cast<double>(phase.runs) * perIteration,
                static_cast<double>(phase.tasks) / static_cast<double>(phase.runs),
                phase.taskMs * perIteration, 100 * phase.taskMs * perIteration / iterationMs,
                100 * phase.largestMs / phase.taskMs, phase.taskMs / phase.scheduleMs[1]);
  }
  std::printf("iteration %.3f ms CPU, %.3f ms outside tasks (%.1f%%)\n", iterationMs, serial,
              100 * serial / iterationMs);
  for (const auto& [name, ms] :
       {std::pair{"critical-path bound", boundMs}, std::pair{"pool's schedule", scheduleMs}})
    std::printf("  speed-up, %-20s 2 threads %.2fx, 3 threads %.2fx, 4 threads %.2fx\n", name,
                iterationMs / (serial + ms[1]), iterationMs / (serial + ms[2]),
                iterationMs / (serial + ms[3]));
}

/// Per-thread busy time (thread CPU time in tasks) of the scene's 2 threads over `steps` steps,
/// against their wall time.
void busyReport(BenchScene& scene, int steps) {
  MuscleSystem& system = scene.system();
  scene.stepPose();
  TaskProfile profile;
  TaskPool& pool = *MuscleSystemAccess::impl(system).pool;
  pool.attach(&profile);
  const auto start = std::chrono::steady_clock::now();
  const int iterations = stepPoses(scene, steps);
  const std::chrono::duration<double, std::milli> wall = std::chrono::steady_clock::now() - start;
  pool.attach(nullptr);
  const double perIteration = 1.0 / iterations;
  std::printf(
      "2 threads: busy in tasks %.3f (caller) / %.3f (worker) ms per iteration of %.3f ms "
      "wall\n",
      profile.busyMs[0] * perIteration, profile.busyMs[1] * perIteration,
      wall.count() * perIteration);
}

/// Thread scaling in one run on whole poses of thigh13 at `resolution` (the scene's
/// iterations per pose): the balance of the tasks (balanceReport, with the forces phase in one
/// task per muscle and in chunks) and the busy time of 2 threads, then 1 and 2 solver threads
/// (a system each) alternated `rounds` times, alone and with a busy loop on one core; medians per
/// configuration in ms per iteration (the iterations counted, not assumed).
int threadScaling(int resolution, int rounds) {
  BenchScene scene(resolution, 1), pair(resolution, 2);
  const int iterations = scene.system().stepSettings().iterations;
  scene.countIterations(iterations);
  pair.countIterations(iterations);
  constexpr int kSteps = 2;
  std::printf(
      "thigh13 R=%d, %zu particles, poses of %d iterations, %d rounds of %d poses per "
      "configuration\n",
      resolution, scene.particles(), iterations, rounds, kSteps);
  std::printf("-- forces phase in one task per muscle:\n");
  balanceReport(scene, kSteps, SIZE_MAX);
  std::printf("-- forces phase in chunks (the default):\n");
  balanceReport(scene, kSteps, kForceChunkWork);
  busyReport(pair, kSteps);
  for (const bool busy : {false, true}) {
    std::optional<BusyCore> loop;
    if (busy) loop.emplace();
    std::vector<double> one, two;
    for (int round = 0; round < rounds; ++round) {
      one.push_back(msPerIteration(scene, kSteps));
      two.push_back(msPerIteration(pair, kSteps));
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
  if (argc >= 3 && std::strcmp(argv[1], "--implicit-surface") == 0)
    return fibremss::bench::implicitSurfaceReport(std::atoi(argv[2]),
                                                  argc > 3 ? std::atoi(argv[3]) : 15);
  fibremss::bench::registerAll();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
