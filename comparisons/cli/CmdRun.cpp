// `fibremss run SCENE`: prepare a scene, simulate every pose of its motion with FibreMSS,
// report progress, write frames and summary.json. Ctrl-C or SIGTERM stops within the current step.
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "Commands.h"
#include "Interrupt.h"
#include "SceneArgs.h"
#include "Validators.h"
#include "fibremss/Analytic.h"
#include "fibremss/FibreRun.h"
#include "fibremss/Messages.h"
#include "fibremss/MuscleMetrics.h"
#include "fibremss/Output.h"
#include "fibremss/Progress.h"
#include "fibremss/ToolRun.h"

namespace fibremss::cli {
namespace {

struct RunArgs {
  SceneArgs scene;       ///< SCENE and --set overrides
  std::string out;       ///< --out DIR ("" writes nothing)
  int steps = -1;        ///< --steps N (< 0: one per pose)
  int frameEvery = -1;   ///< --frame-every K (< 0: the scene's outputs.frame_every)
  bool json = false;     ///< --json: the summary as JSON on stdout
  bool loop = false;     ///< --loop: sweep the motion forth and back past its last pose
  long sampleEvery = 0;  ///< --sample-every K: soak sample every K iterations (0: none)
  std::vector<std::string> formats{"vtk"};  ///< --format: frame formats (vtk, gltf)
};

/// Exit codes beyond 0 (done), 1 (error) and 2 (bad input).
constexpr int kExitSimulationFailed = 3;
/// Every step ran, but the guard froze muscles on the way (on_failure=stop-body).
constexpr int kExitMuscleFrozen = 4;

/// What the numerical guard did, for summary.json.
nlohmann::json guardJson(const FibreRunDetails& details, FailurePolicy policy) {
  nlohmann::json frozen = nlohmann::json::array(), rollbacks = nlohmann::json::array();
  for (const Rollback& rollback : details.rollbacks)
    rollbacks.push_back({{"step", rollback.step},
                         {"muscle", rollback.muscle},
                         {"attempts", rollback.attempts},
                         {"cause", rollback.nan ? "nan" : "exploded"}});
  for (const FrozenMuscle& muscle : details.frozen)
    frozen.push_back({{"muscle", muscle.name},
                      {"step", muscle.step},
                      {"cause", muscle.nan ? "nan" : "exploded"}});
  return {{"policy", toString(policy)},
          {"rolled_back_steps", details.rolledBackSteps},
          {"retries", details.retries},
          {"frozen", frozen},
          {"rollbacks", rollbacks}};
}

/// Muscles trapped between bones (StepStats::trappedMuscles), for summary.json.
nlohmann::json trappedJson(const FibreRunDetails& details) {
  return {{"steps", details.trappedSteps},
          {"first_step", details.firstTrappedStep},
          {"particles_max", details.trappedParticlesMax}};
}

/// Soak samples as CSV, one line per sample.
std::string soakCsv(const std::vector<SoakSample>& samples) {
  std::string csv = "step,iterations,seconds,ms_per_iteration,resident_mb,fixed_drift_mm,finite\n";
  char line[256];
  for (const SoakSample& s : samples) {
    std::snprintf(line, sizeof line, "%d,%ld,%.3f,%.5g,%.1f,%.3g,%d\n", s.step, s.iterations,
                  s.seconds, s.msPerIteration, s.residentMb, s.fixedDriftMm, s.finite ? 1 : 0);
    csv += line;
  }
  return csv;
}

/// The soak figures over all samples: memory first/last/largest, fixed-particle drift, NaN, and
/// the spread of the time per iteration between samples.
nlohmann::json soakJson(const std::vector<SoakSample>& samples) {
  std::vector<double> ms;
  double driftMax = 0, residentMax = 0;
  bool finite = true;
  for (const SoakSample& s : samples) {
    ms.push_back(s.msPerIteration);
    driftMax = std::max(driftMax, s.fixedDriftMm);
    residentMax = std::max(residentMax, s.residentMb);
    finite = finite && s.finite;
  }
  std::sort(ms.begin(), ms.end());
  return {{"samples", samples.size()},
          {"resident_mb_first", samples.front().residentMb},
          {"resident_mb_last", samples.back().residentMb},
          {"resident_mb_max", residentMax},
          {"fixed_drift_mm_max", driftMax},
          {"all_finite", finite},
          {"ms_per_iteration_min", ms.front()},
          {"ms_per_iteration_median", ms[ms.size() / 2]},
          {"ms_per_iteration_max", ms.back()}};
}

void printSummary(const RunMetrics& m, const FibreRunDetails& details, const RunArgs& args,
                  const nlohmann::json& summary) {
  std::printf("%s: %s, %s: %d steps, %ld iterations, %.3g ms per iteration (median)\n",
              m.scene.c_str(), m.method.c_str(), m.integrator.c_str(), m.steps, m.iterations,
              m.msPerIteration);
  std::printf("  particles %zu (boundary %zu), springs %zu, bone spheres %zu\n", m.particles,
              m.boundaryParticles, m.springs, m.boneSpheres);
  std::printf(
      "  ms per iteration: mss %.3g (volume term %.3g), muscle CD %.3g, bone CD %.3g, response "
      "%.3g, output %.3g\n",
      m.timing.mss, m.timing.volume, m.timing.muscleCd, m.timing.boneCd, m.timing.response,
      m.timing.output);
  std::printf(
      "  penetration max %.3g mm, mean %.3g mm; volume change %.3g %%; spring deviation %.3g\n",
      m.maxPenetrationMm, m.meanPenetrationMm, m.volumeChangePct, m.springDeviationRatio);
  if (!m.worstVolumeMuscle.empty())
    std::printf("  worst muscle volume change at any pose: %+.3g %% (%s)\n",
                m.worstMuscleVolumeChangePct, m.worstVolumeMuscle.c_str());
  if (!m.analytic.type.empty()) std::printf("  %s\n", analyticLine(m.analytic).c_str());
  if (std::isfinite(details.implicitSurfaceMsPerFrame))
    std::printf("  implicit surface: %.3g ms per frame (median, all muscles)\n",
                details.implicitSurfaceMsPerFrame);
  std::printf("  particle spheres in bones: max %.3g mm, mean %.3g mm (%zu of %zu sphere tests)\n",
              details.spherePenetration.maxMm, details.spherePenetration.meanMm,
              details.spherePenetration.penetrating, details.spherePenetration.points);
  if (m.failedStep >= 0)
    std::printf("  FAILED at step %d:%s%s\n", m.failedStep, m.nan ? " NaN/inf" : "",
                m.exploded ? " exploded (a spring beyond 3x its rest length)" : "");
  if (details.rolledBackSteps > 0)
    std::printf("  numerical guard: %d step(s) rolled back, %d retries with a smaller dt\n",
                details.rolledBackSteps, details.retries);
  for (const Rollback& rollback : details.rollbacks)
    std::printf("  step %d rolled back: muscle '%s' failed %d attempt(s) (%s)\n", rollback.step,
                rollback.muscle.c_str(), rollback.attempts,
                rollback.nan ? "NaN/inf" : "a spring beyond 3x its rest length");
  if (!m.muscles.empty()) std::printf("\n%s\n", muscleTable(m.muscles).c_str());
  for (const FrozenMuscle& muscle : details.frozen)
    std::printf("  muscle '%s' frozen at step %d (%s)\n", muscle.name.c_str(), muscle.step,
                muscle.nan ? "NaN/inf" : "exploded");
  if (details.trappedSteps > 0)
    std::printf(
        "  trapped between bones after %d step(s) (first: step %d), up to %zu particle(s) "
        "caught\n",
        details.trappedSteps, details.firstTrappedStep, details.trappedParticlesMax);
  if (summary.contains("soak")) {
    const nlohmann::json& soak = summary.at("soak");
    std::printf(
        "  soak: %zu samples; resident %.1f -> %.1f MB (max %.1f); fixed drift max %.3g mm; %s; "
        "ms per iteration %.3g / %.3g / %.3g (min / median / max)\n",
        soak.at("samples").get<size_t>(), soak.at("resident_mb_first").get<double>(),
        soak.at("resident_mb_last").get<double>(), soak.at("resident_mb_max").get<double>(),
        soak.at("fixed_drift_mm_max").get<double>(),
        soak.at("all_finite").get<bool>() ? "no NaN" : "NaN/inf seen",
        soak.at("ms_per_iteration_min").get<double>(),
        soak.at("ms_per_iteration_median").get<double>(),
        soak.at("ms_per_iteration_max").get<double>());
  }
  if (m.interrupted) std::printf("  interrupted after %d steps\n", m.steps);
  if (args.out.empty()) return;
  std::string frames;
  if (details.frames > 0) {
    const bool vtk = std::ranges::count(args.formats, "vtk") > 0;
    const bool gltf = std::ranges::count(args.formats, "gltf") > 0;
    frames = " and " + std::to_string(details.frames) + " frame(s) (" +
             (vtk ? args.out + "/run.pvd" : "") + (vtk && gltf ? ", " : "") +
             (gltf ? args.out + "/gltf/*.glb" : "") + ")";
  }
  std::printf("  wrote %s/summary.json, %s/series.csv%s\n", args.out.c_str(), args.out.c_str(),
              frames.c_str());
}

/// Locks args.out against a second run into it, removes what an interrupted or earlier run left
/// there (a previous run's files would mislead) and writes the scene.
void openOutDir(const RunArgs& args, const LoadedScene& scene,
                std::optional<OutputDirectory>& outDir) {
  outDir.emplace(args.out);
  if (outDir->removedTemporaries() > 0)
    std::fprintf(stderr, "removed %zu temporary file(s) an interrupted run left in %s\n",
                 outDir->removedTemporaries(), args.out.c_str());
  for (const char* file : {"/summary.json", "/soak.csv", "/series.csv", "/ticks.csv"})
    removeOutputFile(args.out + file);
  writeFileAtomically(args.out + "/scene.json", scene.json);
}

/// The runner's options from the command line (without progress).
FibreRunOptions runOptions(const RunArgs& args) {
  FibreRunOptions options;
  options.outDir = args.out;
  options.vtkFrames = std::ranges::count(args.formats, "vtk") > 0;
  options.gltfFrames = std::ranges::count(args.formats, "gltf") > 0;
  options.frameEvery = args.frameEvery;
  options.steps = args.steps;
  options.keepPoseSurfaces = false;
  options.cancel = &interruptRequested;
  options.loopMotion = args.loop;
  options.sampleEvery = args.sampleEvery;
  return options;
}

/// The frames' rounding steps as FrameWriter applies them and the error bounds they give (half a
/// step per value, against the frames written exactly); null when frames are written exactly.
nlohmann::json quantisationJson(const OutputSettings& outputs, double unitScale) {
  if (outputs.quantiseMm == 0 && outputs.quantiseStrain == 0) return nullptr;
  const double lengthMm = powerOfTwoStep(outputs.quantiseMm / 1000 / unitScale) * unitScale * 1000;
  const double strain = powerOfTwoStep(outputs.quantiseStrain);
  return {{"length_step_mm", lengthMm},
          {"length_error_bound_mm", lengthMm / 2},
          {"strain_step", strain},
          {"strain_error_bound", strain / 2}};
}

/// The run's summary.json: its metrics, the scene's figures and what the guard did.
nlohmann::json runSummary(const LoadedScene& scene, const PreparedScene& prepared,
                          const RunMetrics& metrics, const FibreRunDetails& details, bool loop) {
  nlohmann::json summary = toJson(metrics);
  summary["scene_source"] = scene.source;
  summary["poses"] = scene.poseCount;
  summary["preparation_seconds"] = prepared.report.seconds;
  summary["max_sphere_penetration_mm"] = details.spherePenetration.maxMm;
  summary["mean_sphere_penetration_mm"] = details.spherePenetration.meanMm;
  summary["frames"] = details.frames;
  if (auto quantisation = quantisationJson(scene.outputs, scene.unitScale); !quantisation.is_null())
    summary["frame_quantisation"] = std::move(quantisation);
  if (std::isfinite(details.measureMsPerStep))
    summary["measure_ms_per_step"] = details.measureMsPerStep;
  if (std::isfinite(details.implicitSurfaceMsPerFrame))
    summary["implicit_surface_ms_per_frame"] = details.implicitSurfaceMsPerFrame;
  summary["guard"] = guardJson(details, scene.simulation.onFailure);
  summary["trapped"] = trappedJson(details);
  summary["loop_motion"] = loop;
  if (!details.samples.empty()) summary["soak"] = soakJson(details.samples);
  return summary;
}

/// Writes soak.csv (when sampled), series.csv and summary.json into `out`.
void writeRunFiles(const std::string& out, const RunMetrics& metrics,
                   const FibreRunDetails& details, const nlohmann::json& summary) {
  if (!details.samples.empty()) writeFileAtomically(out + "/soak.csv", soakCsv(details.samples));
  writeFileAtomically(out + "/series.csv", seriesCsv(metrics.series));
  writeFileAtomically(out + "/summary.json", summary.dump(2) + "\n");
}

/// A scene with a tool: its script tick by tick (HapticTool), the force trace into ticks.csv, the
/// figures into summary.json and on stdout.
void runToolTicks(const RunArgs& args, const LoadedScene& scene, const PreparedScene& prepared) {
  std::fprintf(stderr, "%d ticks of %.3g ms ...\n", scene.tool.ticks(), scene.tool.tickTime * 1e3);
  const ToolRunResult result = runTool(scene, prepared);
  const double peak = result.peakForce;
  const nlohmann::json summary{
      {"scene_source", scene.source},
      {"tool",
       {{"ticks", result.ticks.size()},
        {"tick_ms", scene.tool.tickTime * 1e3},
        {"threads", result.threads},
        {"integrator", toString(scene.simulation.integrator)},
        {"whole_every", scene.tool.wholeEvery},
        {"whole_ticks", result.wholeTicks},
        {"wall_seconds", result.wallSeconds},
        {"cpu_seconds", result.cpuSeconds},
        {"iterations_per_tick",
         double(result.iterations) / double(std::max<size_t>(result.ticks.size(), 1))},
        {"ticks_per_second", result.ticksPerSecond},
        {"peak_force_n", peak},
        {"slide_max_jump_n", result.slideJump},
        {"slide_max_jump_of_peak", peak > 0 ? result.slideJump / peak : 0},
        {"first_contact_tick", result.firstContact},
        {"failed", result.failed}}}};
  if (!args.out.empty()) {
    writeFileAtomically(args.out + "/ticks.csv", ticksCsv(scene, result));
    writeFileAtomically(args.out + "/summary.json", summary.dump(2) + "\n");
  }
  if (args.json) {
    std::cout << summary.dump(2) << "\n";
  } else {
    std::printf(
        "%s: %zu ticks of %.3g ms in %.3f s wall (%.3f s CPU): %.0f ticks per second "
        "(%d threads)\n",
        scene.name.c_str(), result.ticks.size(), scene.tool.tickTime * 1e3, result.wallSeconds,
        result.cpuSeconds, result.ticksPerSecond, result.threads);
    std::printf(
        "  peak force %.4g N; first contact at tick %d; largest tick-to-tick jump while "
        "sliding %.4g N (%.2f %% of the peak)\n",
        peak, result.firstContact, result.slideJump,
        peak > 0 ? 100 * result.slideJump / peak : 0.0);
    if (!args.out.empty())
      std::printf("  wrote %s/ticks.csv, %s/summary.json\n", args.out.c_str(), args.out.c_str());
  }
  std::fflush(stdout);
  if (result.failed) throw CLI::RuntimeError(kExitSimulationFailed);
}

void run(const RunArgs& args) {
  const LoadedScene scene = loadScene(args.scene.scene, args.scene.overrides);
  printWarnings(scene.warnings);
  printNotes(scene.notes);
  // A run that cannot write fails before preparing, and writes nothing before it prepared.
  if (!args.out.empty()) requireWritableDirectory(args.out);
  std::fprintf(stderr, "preparing %s ...\n", scene.name.c_str());
  const PreparedScene prepared =
      prepareScene(scene.bones, scene.muscles, scene.simulation.seed, scene.simulation.threads);
  printWarnings(prepared.report.warnings);
  printWarnings(attachmentWarnings(scene, prepared));
  std::fprintf(stderr, "prepared in %s\n", formatDuration(prepared.report.seconds).c_str());
  std::optional<OutputDirectory> outDir;  // locked against a second run into it
  if (!args.out.empty()) openOutDir(args, scene, outDir);
  if (scene.tool.present) return runToolTicks(args, scene, prepared);

  FibreRunOptions options = runOptions(args);
  const int steps = args.steps >= 0 ? args.steps : std::max(scene.poseCount, 1);
  ProgressBar bar(scene.name, steps);
  options.progress = [&bar, interactive = isatty(fileno(stderr)) != 0](const RunProgress& p) {
    const StepStats& stats = *p.lastStep;
    // On its own line, ahead of the bar (which a terminal redraws in place).
    if (stats.trappedMuscles > 0)
      std::fprintf(
          stderr, "%sstep %d: %zu muscle(s) trapped between bones, %zu particle(s) caught\n",
          interactive ? "\r\x1b[K" : "", p.step - 1, stats.trappedMuscles, stats.trappedParticles);
    bar.update(p.step, p.iterations, p.seconds);
  };

  RunMetrics metrics;
  FibreRunDetails details;
  {
    InterruptGuard guard;
    metrics = runFibreMSS(scene, prepared, options, &details);
  }
  bar.finish();
  const nlohmann::json summary = runSummary(scene, prepared, metrics, details, args.loop);
  if (!args.out.empty()) writeRunFiles(args.out, metrics, details, summary);

  if (args.json)
    std::cout << summary.dump(2) << "\n";
  else
    printSummary(metrics, details, args, summary);
  std::fflush(stdout);
  if (metrics.interrupted) throw CLI::RuntimeError(interruptExitCode());
  // Under stop-body the others went on past a frozen muscle: every step ran.
  const bool wentOn = scene.simulation.onFailure == FailurePolicy::StopBody &&
                      !details.frozen.empty() && metrics.steps == steps;
  if (metrics.failedStep >= 0)
    throw CLI::RuntimeError(wentOn ? kExitMuscleFrozen : kExitSimulationFailed);
}

}  // namespace

void addRunCommand(CLI::App& app) {
  auto args = std::make_shared<RunArgs>();
  CLI::App* command = app.add_subcommand(
      "run", "Simulate a scene with FibreMSS: progress, a summary, frames and summary.json");
  command->footer(
      "One step per pose of the scene's motion. With --out DIR: DIR/frames/*.vtp and DIR/run.pvd "
      "(open in ParaView; binary, in the scene's units, at simulated seconds, arrays in "
      "docs/outputs.md), DIR/scene.json (the complete scene), DIR/series.csv (per step and muscle: "
      "pose label, "
      "simulated time, volume, mean fibre length, largest fibre stretch, deepest penetration, "
      "contacts; the same as summary.json 'series') and DIR/summary.json (with what "
      "the numerical guard did: rolled-back steps, retries, frozen muscles; and per muscle: "
      "volume, "
      "penetration per bone, fixed particles, fibre length, worst spring). Ctrl-C or SIGTERM "
      "stops the running step at the end of its current iteration (it is not written); the "
      "steps before it are kept and every file written stays valid. Soak run: --loop --steps N "
      "--sample-every 1000. A scene with a tool (`tool`, the built-in probe) runs the tool's "
      "ticks instead: DIR/ticks.csv (the force on the tool per tick) and DIR/summary.json "
      "(ticks per second, the peak force, the largest tick-to-tick jump while sliding).");
  addSceneArgs(*command, args->scene);
  command->add_option("--out", args->out,
                      "Directory for frames/*.vtp, run.pvd, scene.json and summary.json");
  command
      ->add_option("--steps", args->steps,
                   "Steps to run (default: one per pose; later steps hold the last pose)")
      ->check(nonNegativeInteger());
  command
      ->add_option("--frame-every", args->frameEvery,
                   "Write a frame every K-th step (0: no frames; default: the scene's "
                   "outputs.frame_every)")
      ->check(nonNegativeInteger());
  command
      ->add_option("--format", args->formats,
                   "Frame formats, comma-separated: vtk (frames/*.vtp and run.pvd for ParaView, "
                   "scene units) and/or gltf (gltf/frame_NNNNN.glb, glTF 2.0 binary in metres: "
                   "muscle surfaces and bones, for game engines, three.js, glTF viewers)")
      ->delimiter(',')
      ->check(oneOf({"vtk", "gltf"}))
      ->type_name("vtk|gltf")
      ->capture_default_str();
  command->add_flag("--json", args->json, "Print the summary as JSON instead of text");
  command->add_flag("--loop", args->loop,
                    "Past the last pose, sweep the motion back to the first and forth again (with "
                    "--steps: a soak run)");
  command
      ->add_option("--sample-every", args->sampleEvery,
                   "Every K iterations record resident memory, fixed-particle drift from T*rest, "
                   "NaN and the time per iteration (summary.json 'soak', DIR/soak.csv)")
      ->check(nonNegativeInteger());
  command->callback([args] { run(*args); });
}

}  // namespace fibremss::cli
