// fibremss.Simulation: a prepared scene in a MuscleSystem, stepped from Python. Particle arrays
// are numpy views of the solver's own memory (read-only; set_positions writes them).
#include <pybind11/stl.h>

#include <optional>
#include <string>
#include <vector>

#include "Bindings.h"
#include "Convert.h"
#include "Simulation.h"

namespace fibremss::python {
namespace {

/// The index of a muscle or bone given by index or by name (IndexError, KeyError otherwise).
template <typename Input>
size_t lookup(const py::handle key, const std::vector<Input>& inputs, const char* what) {
  if (py::isinstance<py::str>(key)) {
    const auto name = key.cast<std::string>();
    for (size_t i = 0; i < inputs.size(); ++i)
      if (inputs[i].name == name) return i;
    throw py::key_error(std::string("no ") + what + " named '" + name + "'");
  }
  const auto i = key.cast<py::ssize_t>();
  if (i < 0 || size_t(i) >= inputs.size())
    throw py::index_error(std::string(what) + " " + std::to_string(i) + " of " +
                          std::to_string(inputs.size()));
  return size_t(i);
}

MuscleHandle muscle(const Simulation& s, const py::handle key) {
  return s.muscles()[lookup(key, s.scene().muscles, "muscle")];
}

BoneHandle bone(const Simulation& s, const py::handle key) {
  return s.bones()[lookup(key, s.scene().bones, "bone")];
}

py::dict stepDict(const StepStats& stats) {
  py::dict timing;
  timing["total"] = stats.timing.total;
  timing["mss"] = stats.timing.mss;
  timing["volume"] = stats.timing.volume;
  timing["muscle_cd"] = stats.timing.muscleCd;
  timing["bone_cd"] = stats.timing.boneCd;
  timing["response"] = stats.timing.response;
  timing["output"] = stats.timing.output;
  py::dict d;
  d["iterations"] = stats.iterations;
  d["simulated_time_s"] = stats.simulatedTime;
  d["last_time_step_s"] = stats.lastTimeStep;
  d["mean_displacement_m"] = stats.meanDisplacement;
  d["contacts"] = stats.contacts;
  d["spring_deviation_ratio"] = stats.springDeviationRatio;
  d["nan"] = stats.nan;
  d["exploded"] = stats.exploded;
  d["failed"] = stats.failed;
  d["rolled_back"] = stats.rolledBack;
  d["retries"] = stats.retries;
  d["frozen_muscles"] = stats.frozenMuscles;
  d["interrupted"] = stats.interrupted;
  d["timing_ms"] = timing;
  return d;
}

py::dict residualDict(const ForceResidual& r) {
  py::dict d;
  d["particles"] = r.particles;
  d["contact_particles"] = r.contactParticles;
  d["rms_force_n"] = r.rmsForce;
  d["max_force_n"] = r.maxForce;
  d["rms_displacement_m"] = r.rmsDisplacement;
  d["max_displacement_m"] = r.maxDisplacement;
  return d;
}

/// A muscle's series row as a dict: the keys of summary.json's "series" plus the per-bone
/// penetration, the worst spring and the spring deviation. bone_contacts (run's sphere test)
/// is left out.
py::dict measureDict(const SeriesRow& row) {
  py::dict d = pythonObject(seriesJson({row}).at(0));
  PyDict_DelItemString(d.ptr(), "bone_contacts");
  d["penetration_mm"] = row.measures.penetrationMm;
  d["worst_spring_ratio"] = row.measures.worstSpringRatio;
  d["spring_deviation_ratio"] = row.measures.springDeviationRatio;
  d["finite"] = row.measures.finite;
  return d;
}

/// Defines `name(muscle)`: `view(system, handle, owner)`, a numpy view that keeps the Python
/// Simulation (`owner`) alive.
template <typename View>
void defineView(py::class_<Simulation>& c, const char* name, View view, const char* doc) {
  c.def(
      name,
      [view](py::object self, py::handle m) {
        const Simulation& s = self.cast<const Simulation&>();
        return view(s.system(), muscle(s, m), self);
      },
      py::arg("muscle"), doc);
}

/// Views of one muscle's particle data (no copy), and set_positions.
void bindMuscleArrays(py::class_<Simulation>& c) {
  using System = const MuscleSystem&;
  defineView(
      c, "positions",
      [](System s, MuscleHandle m, py::handle owner) { return pointView(s.positions(m), owner); },
      "Particles (N,3) [m]: a read-only view of the solver's, no copy");
  defineView(
      c, "rest_positions",
      [](System s, MuscleHandle m, py::handle o) {
        return pointView(s.settings(m).restPositions, o);
      },
      "Rest particles (N,3) [m], a view");
  defineView(
      c, "radii",
      [](System s, MuscleHandle m, py::handle o) {
        return arrayView<btScalar>(s.settings(m).radii, o);
      },
      "Collision sphere radius per particle (N,) [m] (0: inner), a view");
  defineView(
      c, "fixed_particles",
      [](System s, MuscleHandle m, py::handle o) {
        return arrayView<uint32_t>(s.settings(m).fixedParticles, o);
      },
      "Indices of the particles attached to bones, a view");
  defineView(
      c, "surface",
      [](System s, MuscleHandle m, py::handle o) { return pointView(s.surface(m), o); },
      "Deformed surface vertices (V,3) [m] as of the last step, a view");
  defineView(
      c, "surface_triangles",
      [](System s, MuscleHandle m, py::handle o) {
        const auto& triangles = s.settings(m).restSurface.triangles;
        return arrayView<uint32_t>({triangles.data()->data(), 3 * triangles.size()}, o, 3);
      },
      "Surface triangles (T,3), vertex indices, a view");
  defineView(
      c, "residual_forces",
      [](System s, MuscleHandle m, py::handle o) { return pointView(s.residualForces(m), o); },
      "Per-particle force residual (N,3) [N] of the last force_residual, a view");
  c.def(
      "set_positions",
      [](Simulation& s, py::handle m, const ScalarArray& x) {
        s.system().setPositions(muscle(s, m), points(x, "positions"));
      },
      py::arg("muscle"), py::arg("positions"),
      "Moves the particles to (N,3) positions [m], at rest there");
}

/// Bones, forces, residuals and measures.
void bindQueries(py::class_<Simulation>& c) {
  c.def(
       "bone_transform",
       [](const Simulation& s, py::handle b) {
         return matrix(s.system().boneTransform(bone(s, b)));
       },
       py::arg("bone"), "Bone's current 4x4 transform (rest to current) [m]")
      .def(
          "set_bone_transform",
          [](Simulation& s, py::handle b, const py::array_t<double>& t) {
            s.system().setBoneTransform(bone(s, b), transform(t));
          },
          py::arg("bone"), py::arg("transform"), "Bone's 4x4 target, reached by the next step")
      .def(
          "set_external_forces",
          [](Simulation& s, py::handle m, const std::vector<uint32_t>& particles,
             const ScalarArray& forces) {
            const std::vector<btVector3> f = points(forces, "forces");
            if (f.size() != particles.size())
              throw py::value_error("expected one force per particle");
            for (size_t i = 0; i < f.size(); ++i)
              s.system().setExternalForce(muscle(s, m), particles[i], f[i]);
          },
          py::arg("muscle"), py::arg("particles"), py::arg("forces"),
          "Holds forces (K,3) [N] on K free particles until changed or cleared")
      .def(
          "clear_external_forces",
          [](Simulation& s, py::handle m) { s.system().clearExternalForces(muscle(s, m)); },
          py::arg("muscle"), "Removes every external force of the muscle")
      .def(
          "force_residual", [](Simulation& s) { return residualDict(s.system().forceResidual()); },
          "Distance from static equilibrium, all muscles: RMS/max force [N], displacement [m]")
      .def(
          "measures",
          [](Simulation& s) {
            py::list rows;
            for (const SeriesRow& row : s.measure()) rows.append(measureDict(row));
            return rows;
          },
          "Each muscle measured now as `fibremss run` does (volume change [%], fibre length "
          "[mm], stretch, penetration per bone [mm], residual [mm]): one dict per muscle");
}

}  // namespace

void bindSimulation(py::module_& module) {
  py::class_<Simulation> c(module, "Simulation",
                           "A scene prepared into a MuscleSystem (particles, springs, bone "
                           "spheres), stepped from Python.");
  c.def(py::init([](const LoadedScene& scene, std::optional<int> threads) {
          py::gil_scoped_release release;
          return std::make_unique<Simulation>(scene, threads);
        }),
        py::arg("scene"), py::arg("threads") = py::none(),
        "Prepares the scene (threads: solver threads, None: the scene's)")
      .def_property_readonly("scene", &Simulation::scene, "The scene it was prepared from")
      .def_property_readonly("time", &Simulation::time, "Simulated time of all steps [s]")
      .def_property_readonly("steps", &Simulation::steps, "Steps so far")
      .def(
          "particle_count",
          [](const Simulation& s, py::handle m) {
            return s.system().settings(muscle(s, m)).particleCount();
          },
          py::arg("muscle"), "Particles of a muscle")
      .def("set_pose", &Simulation::setPose, py::arg("pose"),
           "Every bone's target for the next step: the scene's transform at this pose")
      .def(
          "step",
          [](Simulation& s, std::optional<double> duration) {
            {
              py::gil_scoped_release release;
              s.step(duration);
            }
            return stepDict(s.system().lastStep());
          },
          py::arg("duration") = py::none(),
          "One step (a pose; with duration [s], exactly that much simulated time); its stats")
      .def_property_readonly(
          "last_step", [](const Simulation& s) { return stepDict(s.system().lastStep()); },
          "Statistics of the last step: iterations, contacts, timing [ms], failures");
  bindMuscleArrays(c);
  bindQueries(c);
}

}  // namespace fibremss::python
