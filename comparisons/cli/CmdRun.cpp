// `fibremss run SCENE`: prepare a scene, simulate every pose of its motion with FibreMSS,
// report progress, write frames and summary.json. Ctrl-C stops after the current step.
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>

#include "Commands.h"
#include "SceneArgs.h"
#include "fibremss/FibreRun.h"
#include "fibremss/Output.h"
#include "fibremss/Progress.h"

namespace fibremss::cli {
namespace {

struct RunArgs {
  SceneArgs scene;      ///< SCENE and --set overrides
  std::string out;      ///< --out DIR ("" writes nothing)
  int steps = -1;       ///< --steps N (< 0: one per pose)
  int frameEvery = -1;  ///< --frame-every K (< 0: the scene's outputs.frame_every)
  bool json = false;    ///< --json: the summary as JSON on stdout
};

/// Exit codes beyond 0 (done), 1 (error) and 2 (bad input).
constexpr int kExitSimulationFailed = 3;
constexpr int kExitInterrupted = 130;

std::atomic<bool> interruptRequested{false};

void onInterrupt(int) {
  interruptRequested.store(true);
  // write() is async-signal-safe; SA_RESETHAND made a second Ctrl-C end the process at once.
  const char message[] = "\nfibremss: interrupted, stopping after the current step\n";
  [[maybe_unused]] ssize_t written = write(STDERR_FILENO, message, sizeof message - 1);
}

/// Stops the run on SIGINT for as long as it lives, then restores the previous handler.
class InterruptGuard {
 public:
  InterruptGuard() {
    interruptRequested.store(false);
    struct sigaction action {};
    action.sa_handler = onInterrupt;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_RESETHAND;
    sigaction(SIGINT, &action, &previous_);
  }
  ~InterruptGuard() { sigaction(SIGINT, &previous_, nullptr); }
  InterruptGuard(const InterruptGuard&) = delete;
  InterruptGuard& operator=(const InterruptGuard&) = delete;

 private:
  struct sigaction previous_ {};
};

void printSummary(const RunMetrics& m, const FibreRunDetails& details, const RunArgs& args) {
  std::printf("%s: %s, %s: %d steps, %ld iterations, %.3g ms per iteration (median)\n",
              m.scene.c_str(), m.method.c_str(), m.integrator.c_str(), m.steps, m.iterations,
              m.msPerIteration);
  std::printf("  particles %zu (boundary %zu), springs %zu, bone spheres %zu\n", m.particles,
              m.boundaryParticles, m.springs, m.boneSpheres);
  std::printf(
      "  ms per iteration: mss %.3g, muscle CD %.3g, bone CD %.3g, response %.3g, output %.3g\n",
      m.timing.mss, m.timing.muscleCd, m.timing.boneCd, m.timing.response, m.timing.output);
  std::printf(
      "  penetration max %.3g mm, mean %.3g mm; volume change %.3g %%; spring deviation %.3g\n",
      m.maxPenetrationMm, m.meanPenetrationMm, m.volumeChangePct, m.springDeviationRatio);
  std::printf("  particle spheres in bones: max %.3g mm, mean %.3g mm (%zu of %zu sphere tests)\n",
              details.spherePenetration.maxMm, details.spherePenetration.meanMm,
              details.spherePenetration.penetrating, details.spherePenetration.points);
  if (m.failedStep >= 0)
    std::printf("  FAILED at step %d:%s%s\n", m.failedStep, m.nan ? " NaN/inf" : "",
                m.exploded ? " exploded (a spring beyond 3x its rest length)" : "");
  if (m.interrupted) std::printf("  interrupted after %d steps\n", m.steps);
  if (!args.out.empty() && details.frames > 0)
    std::printf("  wrote %s/summary.json and %d frame(s) (%s/run.pvd)\n", args.out.c_str(),
                details.frames, args.out.c_str());
  else if (!args.out.empty())
    std::printf("  wrote %s/summary.json\n", args.out.c_str());
}

void run(const RunArgs& args) {
  const LoadedScene scene = loadScene(args.scene.scene, args.scene.overrides);
  for (const std::string& warning : scene.warnings)
    std::fprintf(stderr, "warning: %s\n", warning.c_str());
  // The output directory first: a run that cannot write should fail before preparing.
  if (!args.out.empty()) {
    std::filesystem::create_directories(args.out);
    writeFileAtomically(args.out + "/scene.json", scene.json);
    std::filesystem::remove(args.out + "/summary.json");  // a previous run's would mislead
  }
  std::fprintf(stderr, "preparing %s ...\n", scene.name.c_str());
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  for (const std::string& warning : prepared.report.warnings)
    std::fprintf(stderr, "warning: %s\n", warning.c_str());
  std::fprintf(stderr, "prepared in %s\n", formatDuration(prepared.report.seconds).c_str());

  FibreRunOptions options;
  options.outDir = args.out;
  options.frameEvery = args.frameEvery;
  options.steps = args.steps;
  options.keepPoseSurfaces = false;
  options.cancel = &interruptRequested;
  const int steps = args.steps >= 0 ? args.steps : std::max(scene.poseCount, 1);
  ProgressBar bar(scene.name, steps);
  options.progress = [&bar](const RunProgress& p) { bar.update(p.step, p.iterations, p.seconds); };

  RunMetrics metrics;
  FibreRunDetails details;
  {
    InterruptGuard guard;
    metrics = runFibreMSS(scene, prepared, options, &details);
  }
  bar.finish();

  nlohmann::json summary = toJson(metrics);
  summary["scene_source"] = scene.source;
  summary["poses"] = scene.poseCount;
  summary["preparation_seconds"] = prepared.report.seconds;
  summary["max_sphere_penetration_mm"] = details.spherePenetration.maxMm;
  summary["mean_sphere_penetration_mm"] = details.spherePenetration.meanMm;
  summary["frames"] = details.frames;
  if (std::isfinite(details.measureMsPerStep))
    summary["measure_ms_per_step"] = details.measureMsPerStep;
  if (!args.out.empty()) writeFileAtomically(args.out + "/summary.json", summary.dump(2) + "\n");

  if (args.json)
    std::cout << summary.dump(2) << "\n";
  else
    printSummary(metrics, details, args);
  std::fflush(stdout);
  if (metrics.interrupted) throw CLI::RuntimeError(kExitInterrupted);
  if (metrics.failedStep >= 0) throw CLI::RuntimeError(kExitSimulationFailed);
}

}  // namespace

void addRunCommand(CLI::App& app) {
  auto args = std::make_shared<RunArgs>();
  CLI::App* command = app.add_subcommand(
      "run", "Simulate a scene with FibreMSS: progress, a summary, frames and summary.json");
  command->footer(
      "One step per pose of the scene's motion. With --out DIR: DIR/frames/*.vtp and DIR/run.pvd "
      "(open in ParaView), DIR/scene.json (the complete scene) and DIR/summary.json. Exit code 3 "
      "when the simulation failed (NaN or explosion), 130 when interrupted: Ctrl-C stops after "
      "the current step and every file written stays valid.");
  addSceneArgs(*command, args->scene);
  command->add_option("--out", args->out,
                      "Directory for frames/*.vtp, run.pvd, scene.json and summary.json");
  command
      ->add_option("--steps", args->steps,
                   "Steps to run (default: one per pose; later steps hold the last pose)")
      ->check(CLI::NonNegativeNumber);
  command
      ->add_option("--frame-every", args->frameEvery,
                   "Write a frame every K-th step (0: no frames; default: the scene's "
                   "outputs.frame_every)")
      ->check(CLI::NonNegativeNumber);
  command->add_flag("--json", args->json, "Print the summary as JSON instead of text");
  command->callback([args] { run(*args); });
}

}  // namespace fibremss::cli
