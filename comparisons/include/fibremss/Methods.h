#pragma once
// The methods `compare` runs, one entry each: its name, whether it runs by default, the knobs its
// variants take and the front it is swept over, how it runs, and what the report says of it.
// The method parser, the runner (runComparison), the report and the command line read them.
#include <string>
#include <vector>

#include "fibremss/Compare.h"
#include "fibremss/FibreRun.h"

namespace fibremss {

/// What one method's run is given by runComparison.
struct MethodRun {
  const MethodSpec& spec;                     ///< the method, its knobs made absolute
  const std::string& sceneNameOrPath;         ///< the scene as named (a variant reloads it)
  const std::vector<std::string>& overrides;  ///< the scene's --set overrides
  const LoadedScene& scene;                   ///< the scene as loaded
  const PreparedScene& prepared;              ///< and prepared
  const CompareOptions& options;              ///< the comparison's options
  const FibreRunOptions& fibre;               ///< a FibreMSS run's options (name, cancel, progress)
  const MethodRunOptions& baseline;           ///< a baseline's options (progress, cancel, budget)
};

/// The context a knob's "xF" value is made absolute in.
struct KnobBase {
  const LoadedScene& scene;       ///< the scene as loaded
  const PreparedScene& prepared;  ///< and prepared
  const CompareOptions& options;  ///< the baselines' definitions
};

/// What a method's runs are to the other runs of a comparison.
enum class MethodRole {
  Compared,       ///< measured against the runs of the roles below
  Reference,      ///< the reference every run's accuracy is measured against
  SelfReference,  ///< FibreMSS converged in time step and iterations: its own convergence's basis
  Equilibrium,    ///< FibreMSS's model solved to equilibrium: the time-to-accuracy figure's basis
};

/// The method name of the reference's run (CalculiX's static equilibria; no entry of methods()).
inline constexpr const char* kReferenceMethod = "calculix";

/// One comparison method.
struct Method {
  const char* name = "";   ///< its name, the family of its variants ("name:key=value")
  const char* help = "";   ///< what it is, in a few words, for --methods ("" for none)
  bool byDefault = false;  ///< among compare's default methods
  /// Its variants are FibreMSS scene overrides ("fibremss:<key>=<value>[+...]", any scene key)
  /// rather than knobs of its own.
  bool sceneVariants = false;
  /// The knobs a variant may set ("key=N", N > 0 or xF) and the speed–error plot draws a line
  /// for; with sceneVariants, the scene keys that set its cost. Empty: it takes no variants.
  std::vector<std::string> knobs = {};
  /// Its front, cheapest first, for a scene with these settings (nullptr: the method alone).
  std::vector<std::string> (*front)(const MuscleSystemDef& simulation) = nullptr;
  /// The absolute value of knob `key` given as `value` ("xF": F times its default), "" where
  /// the knob takes no factor (nullptr: none does).
  std::string (*factorValue)(const std::string& key, const std::string& value,
                             const KnobBase& base) = nullptr;
  /// Runs the method on every pose of the scene.
  RunMetrics (*run)(const MethodRun& run) = nullptr;
  /// Its entry in the report's "How each method was measured" (Markdown, one bullet).
  const char* description = "";
  /// Its runs solve FibreMSS's own model (for a variant: unless it changes the model), so that
  /// they count in the time-to-accuracy figure.
  bool solvesFibreModel = false;
  /// The report states its runs' iterations per pose (their iterations vary by pose).
  bool iterationsPerPose = false;
  /// What its runs are to the others (a method with a role other than Compared takes no
  /// variants).
  MethodRole role = MethodRole::Compared;
};

/// Every method, in the order the report describes them.
const std::vector<Method>& methods();

/// The method of that name, or nullptr.
const Method* findMethod(const std::string& name);

/// The method a run's name ("fem", "fibremss:iterations=20") is of, or nullptr.
const Method* methodOf(const std::string& runName);

/// What the run named `runName` is to the others: Reference for kReferenceMethod, its method's
/// role for a method's own name, Compared for any other (a variant, "fibremss:iterations=20").
MethodRole roleOf(const std::string& runName);

/// The --methods help: every method, its variants and the default ones.
std::string methodsHelp();

}  // namespace fibremss
