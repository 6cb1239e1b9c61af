#pragma once
// The parts of the `fibremss` Python module, each adding its classes and functions.
#include <pybind11/pybind11.h>

namespace fibremss::python {

/// fibremss.InputError (a ValueError) for fibremss::InputError, with source, where and problem.
void bindErrors(pybind11::module_& module);
/// fibremss.Scene, load_scene, build_scene, scenes, export_scene.
void bindScene(pybind11::module_& module);
/// fibremss.Simulation: a prepared scene stepped from Python.
void bindSimulation(pybind11::module_& module);
/// fibremss.run, fibremss.compare and fibremss.columns.
void bindRuns(pybind11::module_& module);

}  // namespace fibremss::python
