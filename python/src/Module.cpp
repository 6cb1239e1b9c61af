// The `fibremss` Python module: load or build a scene, step it with numpy views of its
// particles, run it as `fibremss run` does and compare methods as `fibremss compare` does.
#include "Bindings.h"
#include "fibremss/Error.h"

namespace fibremss::python {

void bindErrors(pybind11::module_& module) {
  namespace py = pybind11;
  // Held for the interpreter's life (a static py::object would be released after it ends).
  static const py::handle type =
      py::exception<InputError>(module, "InputError", PyExc_ValueError).release();
  type.attr("__doc__") =
      "Bad input (a file, a scene field or a parameter): the message names the file or field, "
      "where in it and what was expected; also as .source, .where and .problem.";
  py::register_exception_translator([](std::exception_ptr thrown) {
    try {
      if (thrown) std::rethrow_exception(thrown);
    } catch (const InputError& e) {
      py::object error = type(e.what());
      error.attr("source") = e.source();
      error.attr("where") = e.where();
      error.attr("problem") = e.problem();
      PyErr_SetObject(type.ptr(), error.ptr());
    }
  });
}

}  // namespace fibremss::python

PYBIND11_MODULE(fibremss, module) {
  module.doc() =
      "FibreMSS from Python: fibre-sampled mass-spring muscles (SI units: m, s, N) in scenes "
      "loaded from a built-in name or a .json file, or built from numpy meshes.";
  fibremss::python::bindErrors(module);
  fibremss::python::bindScene(module);
  fibremss::python::bindSimulation(module);
  fibremss::python::bindRuns(module);
}
