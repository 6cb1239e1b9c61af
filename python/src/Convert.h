#pragma once
// Between Bullet / FibreMSS values and Python: numpy views of particle arrays (no copy), 4×4
// transforms, points read from numpy, JSON as Python objects and scene overrides.
#include <LinearMath/btTransform.h>
#include <LinearMath/btVector3.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

namespace fibremss::python {

namespace py = pybind11;

/// numpy's array of btScalar (float32, or float64 in the double-precision build).
using ScalarArray = py::array_t<btScalar, py::array::c_style | py::array::forcecast>;

/// A read-only (N, 3) numpy view of `points` [m] that keeps `owner` alive (no copy).
py::array pointView(std::span<const btVector3> points, py::handle owner);

/// A read-only numpy view of `values` (shape (N,) or (N, columns)) that keeps `owner` alive.
template <typename T>
py::array arrayView(std::span<const T> values, py::handle owner, size_t columns = 1) {
  std::vector<py::ssize_t> shape{py::ssize_t(values.size() / columns)};
  if (columns > 1) shape.push_back(py::ssize_t(columns));
  py::array view(py::dtype::of<T>(), shape, {}, values.data(), owner);
  view.attr("flags").attr("writeable") = false;
  return view;
}

/// The points of an (N, 3) array [m]; ValueError for another shape.
std::vector<btVector3> points(const ScalarArray& array, const char* name);

/// A rigid transform as a 4×4 homogeneous matrix (rotation, translation [m]).
py::array_t<double> matrix(const btTransform& transform);
/// A 4×4 homogeneous matrix as a rigid transform; ValueError for another shape.
btTransform transform(const py::array_t<double, py::array::c_style | py::array::forcecast>& m);

/// A JSON value as Python objects (dict, list, str, float, int, bool, None).
py::object pythonObject(const nlohmann::json& value);

/// Scene overrides as loadScene takes them: a dict {key: value} (True → "true") or a list of
/// "key=value" strings; None gives none.
std::vector<std::string> overrides(const py::object& given);

}  // namespace fibremss::python
