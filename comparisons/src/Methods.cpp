#include "fibremss/Methods.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>

#include "fibremss/Error.h"
#include "fibremss/SceneSystem.h"

namespace fibremss {
namespace {

/// The scene's value of a FibreMSS knob that takes any positive number (a stop rule's threshold,
/// lengths in the scene's units), as `--set` reads it; NaN for the other keys.
double realKnobBase(const std::string& key, const LoadedScene& scene) {
  const StepSettings& step = scene.simulation.stepSettings;
  if (key == "tolerance") return step.tolerance / scene.unitScale;
  if (key == "epsilon") return step.epsilon / scene.unitScale;
  if (key == "budget_ms") return step.budgetMs;
  if (key == "deviation_epsilon") return step.deviationEpsilon;
  return NAN;
}

/// A number as `--set` takes it, with 6 significant digits.
std::string shortNumber(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.6g", value);
  return text;
}

/// An integer knob's "xF" made absolute from its default `base` ("" when it has none, 0).
std::string integerFactor(const std::string& value, int base) {
  return base == 0 ? "" : std::to_string(knobValue(value, base));
}

/// The integer value of a resolved "key=N" knob of a spec, or `fallback`.
int knob(const MethodSpec& spec, const std::string& key, int fallback) {
  for (const std::string& part : spec.overrides)
    if (part.rfind(key + "=", 0) == 0) return knobValue(part.substr(key.size() + 1), fallback);
  return fallback;
}

/// A baseline's front: its knob ×0.5, its default, ×2.
std::vector<std::string> threePoints(const std::string& name, const std::string& key) {
  return {name + ":" + key + "=x0.5", name, name + ":" + key + "=x2"};
}

std::vector<std::string> fibreFront(const MuscleSystemDef& simulation) {
  const FibreKnob knob = fibreCostKnob(simulation.stepSettings);
  // Cheapest first: fewer iterations (a smaller budget), or a looser threshold.
  const std::array<const char*, 3> factors =
      knob.costGrows ? std::array{"x0.5", "x2", "x4"} : std::array{"x2", "x0.5", "x0.25"};
  const std::string at = "fibremss:" + knob.key + "=";
  return {at + factors[0],
          "fibremss",
          at + factors[1],
          at + factors[2],
          "fibremss:resolution=x0.5",
          "fibremss:resolution=x2"};
}

std::string fibreFactor(const std::string& key, const std::string& value, const KnobBase& base) {
  const double real = realKnobBase(key, base.scene);
  if (std::isfinite(real)) return shortNumber(std::strtod(value.c_str() + 1, nullptr) * real);
  if (key == "iterations")
    return integerFactor(value, base.scene.simulation.stepSettings.iterations);
  if (key == "resolution" && !base.scene.muscles.empty())
    return integerFactor(value, base.scene.muscles.front().parameters.resolution);
  return "";
}

RunMetrics runFibre(const MethodRun& run) {
  if (run.spec.overrides.empty()) return runFibreMSS(run.scene, run.prepared, run.fibre);
  std::vector<std::string> all = run.overrides;
  all.insert(all.end(), run.spec.overrides.begin(), run.spec.overrides.end());
  const LoadedScene variant = loadScene(run.sceneNameOrPath, all);
  return runFibreMSS(variant, prepareScene(variant), run.fibre);
}

RunMetrics runSelfReference(const MethodRun& run) {
  LoadedScene reference = run.scene;
  const int f = std::max(1, run.options.selfReferenceFactor);
  StepSettings& step = reference.simulation.stepSettings;
  step.timeStep /= static_cast<btScalar>(f);
  step.minTimeStep /= static_cast<btScalar>(f);
  step.iterations *= f;
  return runFibreMSS(reference, run.prepared, run.fibre);
}

RunMetrics runEquilibrium(const MethodRun& run) {
  LoadedScene converged = run.scene;
  converged.simulation =
      equilibriumSettings(run.scene.simulation, run.options.equilibriumIterations);
  FibreRunOptions options = run.fibre;
  int unconverged = 0;
  options.progress = [&](const RunProgress& p) {
    unconverged += p.lastStep->iterations >= converged.simulation.stepSettings.iterations ? 1 : 0;
    run.fibre.progress(p);
  };
  RunMetrics metrics = runFibreMSS(converged, run.prepared, options);
  metrics.unconvergedPoses = unconverged;
  if (unconverged > 0 && run.options.log)
    run.options.log("equilibrium: " + std::to_string(unconverged) +
                    " pose(s) reached the iteration cap before converging");
  return metrics;
}

std::string softBodyFactor(const std::string& key, const std::string& value, const KnobBase& base) {
  const SoftBodyDefinition& given = base.options.softBody;
  if (key == "iterations")
    return integerFactor(value, given.positionIterations > 0 ? given.positionIterations
                                                             : iterationsFor(base.prepared));
  return integerFactor(
      value, given.substepsPerPose > 0 ? given.substepsPerPose : substepsFor(base.prepared));
}

RunMetrics runSoftBody(const MethodRun& run) {
  SoftBodyDefinition definition = run.options.softBody;
  definition.poseDuration = static_cast<btScalar>(poseDuration(run.scene.simulation.stepSettings));
  definition.pretransformBlend = run.scene.simulation.pretransformBlend;
  definition.positionIterations = knob(run.spec, "iterations", definition.positionIterations);
  definition.substepsPerPose = knob(run.spec, "substeps", definition.substepsPerPose);
  return runBaseline(run.scene, "btsoftbody", run.prepared, run.baseline, [&](auto firstPose) {
    return std::make_unique<SoftBodyScene>(run.prepared, firstPose, definition);
  });
}

std::string femFactor(const std::string& key, const std::string& value, const KnobBase& base) {
  return integerFactor(value, key == "substeps" ? base.options.fem.substepsPerPose
                                                : base.options.fem.mesher.targetCells);
}

RunMetrics runFem(const MethodRun& run) {
  FemDefinition definition = run.options.fem;
  definition.poseDuration = static_cast<btScalar>(poseDuration(run.scene.simulation.stepSettings));
  definition.pretransformBlend = run.scene.simulation.pretransformBlend;
  definition.substepsPerPose = knob(run.spec, "substeps", definition.substepsPerPose);
  definition.mesher.targetCells = knob(run.spec, "cells", definition.mesher.targetCells);
  return runBaseline(run.scene, "fem", run.prepared, run.baseline, [&](auto firstPose) {
    return std::make_unique<FemScene>(run.prepared, firstPose, definition);
  });
}

std::vector<Method> makeMethods() {
  std::vector<Method> all;
  all.push_back({.name = "fibremss",
                 .byDefault = true,
                 .sceneVariants = true,
                 .knobs = {"iterations", "resolution", "tolerance", "epsilon", "budget_ms",
                           "deviation_epsilon"},
                 .front = fibreFront,
                 .factorValue = fibreFactor,
                 .run = runFibre,
                 .description =
                     "- **fibremss**: the scene's own settings (integrator, iterations, adaptive "
                     "dt).\n  **fibremss:k=v**: a variant with those scene overrides.\n",
                 .solvesFibreModel = true,
                 .iterationsPerPose = true});
  all.push_back({.name = "self-reference",
                 .byDefault = true,
                 .run = runSelfReference,
                 .description = "- **self-reference**: FibreMSS with dt/8 (and min dt/8) and 8× "
                                "the iterations, the same\n  simulated time per step.\n",
                 .solvesFibreModel = true,
                 .iterationsPerPose = true,
                 .role = MethodRole::SelfReference});
  all.push_back(
      {.name = "equilibrium",
       .help = "the projective solver until the force residual is below 1e-5 mm",
       .run = runEquilibrium,
       .description =
           "- **equilibrium**: FibreMSS's projective solver run at every pose until its force "
           "residual's RMS\n  equivalent displacement is below 1e-5 mm (checked every 16 "
           "iterations, at most 3 000\n  iterations; the bones move over as many iterations as "
           "in the scene): the model's own converged\n  state, the floor of its error. "
           "`rms_to_equilibrium_mm` of every run is measured against it.\n",
       .solvesFibreModel = true,
       .role = MethodRole::Equilibrium});
  all.push_back(
      {.name = "btsoftbody",
       .byDefault = true,
       .knobs = {"iterations", "substeps"},
       .front = [](const MuscleSystemDef&) { return threePoints("btsoftbody", "iterations"); },
       .factorValue = softBodyFactor,
       .run = runSoftBody,
       .description =
           "- **btsoftbody**: `btSoftBody` in a `btSoftRigidDynamicsWorld`: the same particles "
           "as nodes\n  (same masses), the springs as links (stiffness mapped to `m_kLST` per "
           "link from k = κ/L0,\n  the substep and the iteration count; solved softest first), "
           "fixed particles pinned (mass 0)\n  and moved with their bones every substep, bones "
           "as kinematic bodies with\n  `btBvhTriangleMeshShape` (SDF_RS), soft–soft collision "
           "by clusters (CL_SS); run in\n  centimetres because Bullet extrudes mesh triangles by "
           "a fixed 0.06 units. Substeps and link\n  iterations grow with the particles per "
           "fibre, n: ⌈n/4⌉ × ⌈2n/5⌉ per pose (the run's\n  integrator says which), the "
           "cheapest counts that kept thigh13's links within [1/3, 3]× at\n  resolutions 20 and "
           "40 (comparisons/README.md). One thread (Debian's Bullet has no task\n  scheduler). "
           "The simulated time of a pose is FibreMSS's iterations × dt.\n"});
  all.push_back(
      {.name = "fem",
       .byDefault = true,
       .knobs = {"substeps", "cells"},
       .front = [](const MuscleSystemDef&) { return threePoints("fem", "substeps"); },
       .factorValue = femFactor,
       .run = runFem,
       .description =
           "- **fem**: Bullet's own continuum (a speed peer): each muscle's surface voxelized "
           "and split\n  into positively oriented tetrahedra, `btDeformableNeoHookeanForce` (E "
           "matched to the spring\n  network, E ≈ Σκ·L0 / 3V; ν = 0.45) in a "
           "`btDeformableMultiBodyDynamicsWorld` (elastic forces\n  explicit, damping implicit; "
           "nodes too stiff for the substep get extra mass), nodes near fixed\n  particles "
           "pinned and moved with their bones, free nodes moved with their bones by FibreMSS's\n"
           "  blended pre-transform each substep, node contact with the bones' exact meshes "
           "(own\n  projection after every substep), surface vertices embedded in the "
           "tetrahedra. Its substeps\n  per pose and added mass are in the settings below.\n"});
  return all;
}

/// The forms a variant of each method takes ("fem:substeps|cells=N"), comma-separated.
std::string variantForms() {
  std::string forms;
  for (const Method& method : methods()) {
    std::string form = method.name;
    if (method.sceneVariants) {
      form += ":<key>=<value>[+<key>=<value>...]";
    } else if (!method.knobs.empty()) {
      form += ":";
      for (const std::string& key : method.knobs) form += (form.back() == ':' ? "" : "|") + key;
      form += "=N";
    } else {
      continue;
    }
    forms += (forms.empty() ? "" : ", ") + form;
  }
  return forms;
}

/// The method names, comma-separated, each with its help in parentheses when `withHelp`.
std::string methodNames(bool withHelp, bool defaultsOnly) {
  std::string names;
  for (const Method& method : methods()) {
    if (defaultsOnly && !method.byDefault) continue;
    names += (names.empty() ? "" : ", ") + std::string(method.name);
    if (withHelp && *method.help) names += std::string(" (") + method.help + ")";
  }
  return names;
}

std::vector<std::string> split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  size_t start = 0;
  for (size_t end; (end = text.find(separator, start)) != std::string::npos; start = end + 1) {
    parts.push_back(text.substr(start, end - start));
  }
  parts.push_back(text.substr(start));
  return parts;
}

/// Throws InputError unless `part` ("key=N") is a knob of `method` with a value N > 0 or xF.
void checkKnob(const Method& method, const std::string& name, const std::string& part) {
  const size_t equals = part.find('=');
  const std::string key = part.substr(0, equals);
  const bool known = std::find(method.knobs.begin(), method.knobs.end(), key) != method.knobs.end();
  if (known && knobValue(part.substr(equals + 1), 1) > 0) return;
  std::string takes;
  for (const std::string& k : method.knobs) takes += (takes.empty() ? "" : " or ") + k + "=N";
  throw InputError("--methods", name,
                   std::string(method.name) + " takes " + takes + " (N > 0, or xF)");
}

}  // namespace

const std::vector<Method>& methods() {
  static const std::vector<Method> all = makeMethods();
  return all;
}

const Method* findMethod(const std::string& name) {
  for (const Method& method : methods())
    if (name == method.name) return &method;
  return nullptr;
}

const Method* methodOf(const std::string& runName) {
  return findMethod(runName.substr(0, runName.find(':')));
}

MethodRole roleOf(const std::string& runName) {
  if (runName == kReferenceMethod) return MethodRole::Reference;
  const Method* method = findMethod(runName);
  return method ? method->role : MethodRole::Compared;
}

std::vector<std::string> defaultMethods() {
  std::vector<std::string> names;
  for (const Method& method : methods())
    if (method.byDefault) names.push_back(method.name);
  return names;
}

std::string methodsHelp() {
  return "Comma-separated methods: " + methodNames(true, false) +
         ", integrators (one FibreMSS variant per integrator), " + variantForms() +
         " (N or xF: F times the default); default " + methodNames(false, true);
}

MethodSpec parseMethod(const std::string& name) {
  MethodSpec spec;
  spec.name = name;
  const size_t colon = name.find(':');
  spec.family = name.substr(0, colon);
  const Method* method = findMethod(spec.family);
  if (!method) {
    throw InputError("--methods", name,
                     "unknown method; expected " + methodNames(false, false) + ", " +
                         variantForms() + " (N or xF, F times the default)");
  }
  if (colon == std::string::npos) return spec;
  if (!method->sceneVariants && method->knobs.empty())
    throw InputError("--methods", name, spec.family + " takes no variants");
  for (const std::string& part : split(name.substr(colon + 1), '+')) {
    const size_t equals = part.find('=');
    if (equals == std::string::npos || equals == 0) {
      throw InputError("--methods", name,
                       "variant part '" + part + "' is not <key>=<value> (parts joined by '+')");
    }
    if (!method->sceneVariants) checkKnob(*method, name, part);
    spec.overrides.push_back(part);
  }
  return spec;
}

std::vector<std::string> frontMethods(const std::vector<std::string>& names,
                                      const MuscleSystemDef& simulation) {
  std::vector<std::string> expanded;
  for (const std::string& name : names) {
    const Method* method = findMethod(name);
    if (method && method->front) {
      const std::vector<std::string> front = method->front(simulation);
      expanded.insert(expanded.end(), front.begin(), front.end());
    } else {
      expanded.push_back(name);
    }
  }
  return expanded;
}

}  // namespace fibremss
