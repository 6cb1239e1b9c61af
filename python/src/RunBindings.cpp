// fibremss.run and fibremss.compare: a whole run or comparison as the command-line tool does
// it, its summary as Python objects; fibremss.columns turns rows of dicts into numpy columns.
#include <pybind11/stl.h>

#include <algorithm>
#include <optional>
#include <string>
#include <vector>

#include "Bindings.h"
#include "Convert.h"
#include "Interruptible.h"
#include "fibremss/CompareReport.h"
#include "fibremss/FibreRun.h"
#include "fibremss/SceneSystem.h"
#include "fibremss/Stability.h"

namespace fibremss::python {
namespace {

struct RunSettings {
  int steps = -1;
  std::string outDir;
  int frameEvery = -1;
  std::vector<std::string> formats;
  std::optional<int> threads;
  const std::atomic<bool>* cancel = nullptr;  ///< stop within the running step when true
};

/// Prepares and runs the scene (runFibreMSS); the summary's keys as `fibremss run` writes them.
nlohmann::json runScene(LoadedScene scene, const RunSettings& settings) {
  if (settings.threads) scene.simulation.threads = *settings.threads;
  const PreparedScene prepared = prepareScene(scene);
  FibreRunOptions options;
  options.outDir = settings.outDir;
  options.steps = settings.steps;
  options.frameEvery = settings.frameEvery;
  options.vtkFrames = std::ranges::count(settings.formats, "vtk") > 0;
  options.gltfFrames = std::ranges::count(settings.formats, "gltf") > 0;
  options.keepPoseSurfaces = false;
  options.cancel = settings.cancel;
  nlohmann::json summary = toJson(runFibreMSS(scene, prepared, options));
  summary["scene_source"] = scene.source;
  summary["poses"] = scene.poseCount;
  summary["preparation_seconds"] = prepared.report.seconds;
  return summary;
}

/// runComparison with the options Python gives, its summary, written to `outDir` when given.
nlohmann::json compareScene(const std::string& scene, const std::vector<std::string>& keys,
                            CompareOptions options, const std::string& outDir) {
  options.methods = expandIntegratorMethods(options.methods, {});
  const Comparison comparison = runComparison(scene, keys, options);
  nlohmann::json summary = summaryJson(comparison, "fibremss.compare('" + scene + "')");
  if (!outDir.empty()) writeComparison(summary, outDir);
  return summary;
}

/// Rows of dicts as columns: numbers (None: NaN) as float64 arrays, anything else as lists.
py::dict columns(const py::list& rows) {
  py::dict result;
  if (rows.empty()) return result;
  const py::module_ numpy = py::module_::import("numpy");
  for (const auto& [key, first] : rows[0].cast<py::dict>()) {
    py::list values;
    bool numeric = true;
    for (const py::handle row : rows) {
      py::object value = row[key];
      numeric = numeric && (value.is_none() || py::isinstance<py::float_>(value) ||
                            py::isinstance<py::int_>(value));
      values.append(value.is_none() ? py::float_(NAN) : value);
    }
    result[key] = numeric ? numpy.attr("array")(values, "float64") : py::object(values);
  }
  return result;
}

}  // namespace

void bindRuns(py::module_& module) {
  module.def(
      "run",
      [](const LoadedScene& scene, int steps, const std::string& outDir, int frameEvery,
         const std::vector<std::string>& formats, std::optional<int> threads) {
        return pythonObject(interruptible([&](const std::atomic<bool>* cancel) {
          return runScene(scene, {steps, outDir, frameEvery, formats, threads, cancel});
        }));
      },
      py::arg("scene"), py::arg("steps") = -1, py::arg("out_dir") = "", py::arg("frame_every") = -1,
      py::arg("formats") = std::vector<std::string>{"vtk"}, py::arg("threads") = py::none(),
      "Runs the scene as `fibremss run` (one step per pose): its summary.json as a dict, "
      "'muscles' and the per-step 'series' included; frames into out_dir when given. Ctrl-C "
      "stops it within its running step (KeyboardInterrupt).");
  module.def(
      "compare",
      [](const std::string& scene, const py::object& given, std::vector<std::string> methods,
         bool fronts, bool reference, double methodBudget, const std::string& outDir) {
        CompareOptions options;
        options.methods = std::move(methods);
        options.fronts = fronts;
        options.withReference = reference;
        options.reference.cachedOnly = true;
        options.methodBudgetSeconds = methodBudget;
        const std::vector<std::string> keys = overrides(given);
        return pythonObject(interruptible([&](const std::atomic<bool>* cancel) {
          options.cancel = cancel;
          return compareScene(scene, keys, options, outDir);
        }));
      },
      py::arg("scene"), py::arg("overrides") = py::none(),
      py::arg("methods") = std::vector<std::string>{"fibremss", "btsoftbody"},
      py::arg("fronts") = false, py::arg("reference") = false, py::arg("method_budget") = 0.0,
      py::arg("out_dir") = "",
      "Runs a scene (name or .json) through several methods as `fibremss compare` does "
      "(reference: the cached CalculiX reference only); summary.json as a dict, and with "
      "out_dir summary.json, report.md and the plots there. method_budget: seconds per method. "
      "Ctrl-C stops it within its running step (KeyboardInterrupt).");
  module.def("columns", &columns, py::arg("rows"),
             "Rows of dicts (a summary's 'series', measures()) as {key: numpy array or list}.");
}

}  // namespace fibremss::python
