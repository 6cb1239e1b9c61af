// fibremss.Scene: a scene loaded from a built-in name or a .json file, or built from numpy meshes
// and fibres; its bones, muscles, poses and the main solver settings.
#include <pybind11/stl.h>

#include <algorithm>
#include <string>
#include <vector>

#include "Bindings.h"
#include "Convert.h"
#include "fibremss/Error.h"
#include "fibremss/Scene.h"

namespace fibremss::python {
namespace {

using IndexArray = py::array_t<uint32_t, py::array::c_style | py::array::forcecast>;

/// A closed triangle mesh from (V, 3) vertices [m] and (T, 3) vertex indices.
TriangleMesh mesh(const ScalarArray& vertices, const IndexArray& triangles, const char* name) {
  TriangleMesh result;
  result.vertices = points(vertices, name);
  if (triangles.ndim() != 2 || triangles.shape(1) != 3)
    throw py::value_error(std::string(name) + ": expected (T, 3) triangle indices");
  auto at = triangles.unchecked<2>();
  for (py::ssize_t t = 0; t < triangles.shape(0); ++t)
    result.triangles.push_back({at(t, 0), at(t, 1), at(t, 2)});
  return result;
}

/// A bone from a dict {"name", "vertices", "triangles"}.
BoneInput boneInput(const py::dict& bone) {
  BoneInput input;
  input.name = bone["name"].cast<std::string>();
  input.mesh = mesh(bone["vertices"].cast<ScalarArray>(), bone["triangles"].cast<IndexArray>(),
                    "bone vertices");
  return input;
}

/// A muscle from a dict {"name", "vertices", "triangles", "fibres": [(K, 3), ...],
/// "resolution": particles per fibre (optional)}.
MuscleInput muscleInput(const py::dict& muscle) {
  MuscleInput input;
  input.name = muscle["name"].cast<std::string>();
  input.surface = mesh(muscle["vertices"].cast<ScalarArray>(),
                       muscle["triangles"].cast<IndexArray>(), "muscle vertices");
  for (const py::handle fibre : muscle["fibres"])
    input.fibres.addFibre(points(fibre.cast<ScalarArray>(), "fibre"));
  if (muscle.contains("resolution")) input.parameters.resolution = muscle["resolution"].cast<int>();
  return input;
}

/// A scene from bones, muscles and per-bone poses ({bone name: (P, 4, 4) transforms}).
LoadedScene buildScene(const std::string& name, const py::list& bones, const py::list& muscles,
                       const py::dict& poses) {
  LoadedScene scene;
  scene.name = name;
  scene.source = "python";
  for (const py::handle bone : bones) scene.bones.push_back(boneInput(bone.cast<py::dict>()));
  for (const py::handle muscle : muscles)
    scene.muscles.push_back(muscleInput(muscle.cast<py::dict>()));
  scene.motions.resize(scene.bones.size());
  for (const auto& [key, value] : poses) {
    const auto bone = std::ranges::find(scene.bones, key.cast<std::string>(), &BoneInput::name);
    if (bone == scene.bones.end())
      throw InputError("build_scene", "poses", "no bone named '" + key.cast<std::string>() + "'");
    for (const py::handle pose : value)
      scene.motions[size_t(bone - scene.bones.begin())].poses.push_back(
          transform(pose.cast<py::array_t<double>>()));
  }
  for (const BoneMotion& motion : scene.motions)
    scene.poseCount = std::max(scene.poseCount, int(motion.poses.size()));
  return scene;
}

std::vector<std::string> boneNames(const LoadedScene& scene) {
  std::vector<std::string> names;
  for (const BoneInput& bone : scene.bones) names.push_back(bone.name);
  return names;
}

std::vector<std::string> muscleNames(const LoadedScene& scene) {
  std::vector<std::string> names;
  for (const MuscleInput& muscle : scene.muscles) names.push_back(muscle.name);
  return names;
}

/// The solver settings Python reads and sets on a scene, by their scene keys.
void bindSettings(py::class_<LoadedScene>& scene) {
  scene
      .def_property(
          "integrator", [](const LoadedScene& s) { return toString(s.simulation.integrator); },
          [](LoadedScene& s, const std::string& name) {
            if (!fromString(name, s.simulation.integrator))
              throw InputError("Scene.integrator", name, "expected an integrator's name");
          },
          "The solver: 'projective' (each pose to its equilibrium), 'verlet', ...")
      .def_property(
          "iterations", [](const LoadedScene& s) { return s.simulation.stepSettings.iterations; },
          [](LoadedScene& s, int n) { s.simulation.stepSettings.iterations = n; },
          "Iterations per step")
      .def_property(
          "time_step", [](const LoadedScene& s) { return s.simulation.stepSettings.timeStep; },
          [](LoadedScene& s, btScalar dt) { s.simulation.stepSettings.timeStep = dt; },
          "Fixed dt, or the upper clamp of the adaptive dt [s]")
      .def_property(
          "threads", [](const LoadedScene& s) { return s.simulation.threads; },
          [](LoadedScene& s, int n) { s.simulation.threads = n; },
          "Solver threads, the caller included (0: all hardware threads)")
      .def_property(
          "gravity",
          [](const LoadedScene& s) {
            const btVector3& g = s.simulation.gravity;
            return std::vector<double>{g.x(), g.y(), g.z()};
          },
          [](LoadedScene& s, const std::array<btScalar, 3>& g) {
            s.simulation.gravity = btVector3(g[0], g[1], g[2]);
          },
          "Acceleration of gravity on the free particles [m/s^2]");
}

}  // namespace

void bindScene(py::module_& module) {
  py::class_<LoadedScene> scene(module, "Scene",
                                "A scene: bones with their motion over poses, muscles, solver "
                                "settings (SI units).");
  scene.def_readonly("name", &LoadedScene::name, "Scene name (built-in name or file stem)")
      .def_readonly("source", &LoadedScene::source, "The file it came from, 'built-in' or 'python'")
      .def_readonly("json", &LoadedScene::json, "The whole scene JSON, defaults filled ('': built)")
      .def_readonly("description", &LoadedScene::description, "What the scene shows")
      .def_readonly("pose_count", &LoadedScene::poseCount, "Poses of the motion (steps of a run)")
      .def_readonly("pose_labels", &LoadedScene::poseLabels, "Label per pose (e.g. angle [deg])")
      .def_readonly("warnings", &LoadedScene::warnings, "What loading found that a run survives")
      .def_property_readonly("bone_names", &boneNames, "Bone names, in scene order")
      .def_property_readonly("muscle_names", &muscleNames, "Muscle names, in scene order")
      .def(
          "bone_pose",
          [](const LoadedScene& s, size_t b, int p) { return matrix(s.bonePose(b, p)); },
          py::arg("bone"), py::arg("pose"), "Bone's 4x4 transform (rest to posed) at a pose [m]");
  bindSettings(scene);

  module.def(
      "load_scene",
      [](const std::string& nameOrPath, const py::object& given) {
        const std::vector<std::string> keys = overrides(given);
        py::gil_scoped_release release;
        return loadScene(nameOrPath, keys);
      },
      py::arg("scene"), py::arg("overrides") = py::none(),
      "Loads a built-in scene or a .json file with overrides ({'resolution': 12} or "
      "['resolution=12']); InputError names the file, field and what was expected.");
  module.def("build_scene", &buildScene, py::arg("name"), py::arg("bones"), py::arg("muscles"),
             py::arg("poses") = py::dict(),
             "A scene from meshes [m]: bones [{'name', 'vertices' (V,3), 'triangles' (T,3)}], "
             "muscles [{... 'fibres': [(K,3), ...], 'resolution'}], poses {bone: (P,4,4)}.");
  module.def(
      "scenes",
      [] {
        std::vector<std::pair<std::string, std::string>> list;
        for (const BuiltInScene& s : builtInScenes()) list.emplace_back(s.name, s.description);
        return list;
      },
      "The built-in scenes: (name, one-line description) pairs.");
  module.def("export_scene", &exportBuiltInScene, py::arg("name"),
             "A built-in scene's JSON text, every default filled in (a file to start from).");
}

}  // namespace fibremss::python
