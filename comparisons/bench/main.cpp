// fibremss_bench: Google Benchmark suite of the step's kernels on thigh13 (R = 20, 40), each
// timed alone on one thread while the other parts of the iteration run untimed, plus whole
// iterations with 1 and 2 threads. `fibremss_bench --callgrind-kernels R` instead runs each
// kernel once under callgrind's client requests (comparisons/bench/callgrind.sh).
#include <benchmark/benchmark.h>
#include <valgrind/callgrind.h>

#include <cstdlib>
#include <cstring>
#include <map>
#include <memory>
#include <string>
#include <utility>

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

}  // namespace
}  // namespace fibremss::bench

int main(int argc, char** argv) {
  if (argc == 3 && std::strcmp(argv[1], "--callgrind-kernels") == 0)
    return fibremss::bench::callgrindKernels(std::atoi(argv[2]));
  fibremss::bench::registerAll();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
