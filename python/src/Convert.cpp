#include "Convert.h"

#include <pybind11/stl.h>

namespace fibremss::python {

py::array pointView(std::span<const btVector3> points, py::handle owner) {
  static const btVector3 none(0, 0, 0);  // a valid address for an empty view
  const btScalar* first = points.empty() ? &none.x() : &points.front().x();
  py::array view(py::dtype::of<btScalar>(), {py::ssize_t(points.size()), py::ssize_t(3)},
                 {py::ssize_t(sizeof(btVector3)), py::ssize_t(sizeof(btScalar))}, first, owner);
  view.attr("flags").attr("writeable") = false;
  return view;
}

std::vector<btVector3> points(const ScalarArray& array, const char* name) {
  if (array.ndim() != 2 || array.shape(1) != 3)
    throw py::value_error(std::string(name) + ": expected an (N, 3) array");
  auto at = array.unchecked<2>();
  std::vector<btVector3> result(size_t(array.shape(0)));
  for (py::ssize_t i = 0; i < array.shape(0); ++i)
    result[size_t(i)] = {at(i, 0), at(i, 1), at(i, 2)};
  return result;
}

py::array_t<double> matrix(const btTransform& transform) {
  py::array_t<double> m({4, 4});
  auto at = m.mutable_unchecked<2>();
  const btMatrix3x3& basis = transform.getBasis();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) at(r, c) = basis[r][c];
    at(r, 3) = transform.getOrigin()[r];
    at(3, r) = 0;
  }
  at(3, 3) = 1;
  return m;
}

btTransform transform(const py::array_t<double, py::array::c_style | py::array::forcecast>& m) {
  if (m.ndim() != 2 || m.shape(0) != 4 || m.shape(1) != 4)
    throw py::value_error("expected a 4x4 homogeneous transform");
  auto at = m.unchecked<2>();
  const auto s = [](double v) { return static_cast<btScalar>(v); };
  const btMatrix3x3 basis(s(at(0, 0)), s(at(0, 1)), s(at(0, 2)), s(at(1, 0)), s(at(1, 1)),
                          s(at(1, 2)), s(at(2, 0)), s(at(2, 1)), s(at(2, 2)));
  return btTransform(basis, btVector3(s(at(0, 3)), s(at(1, 3)), s(at(2, 3))));
}

py::object pythonObject(const nlohmann::json& value) {
  return py::module_::import("json").attr("loads")(value.dump());
}

std::vector<std::string> overrides(const py::object& given) {
  if (given.is_none()) return {};
  if (!py::isinstance<py::dict>(given)) return given.cast<std::vector<std::string>>();
  std::vector<std::string> result;
  for (const auto& [key, value] : given.cast<py::dict>()) {
    const std::string text = py::isinstance<py::bool_>(value)
                                 ? (value.cast<bool>() ? "true" : "false")
                                 : py::str(value).cast<std::string>();
    result.push_back(py::str(key).cast<std::string>() + "=" + text);
  }
  return result;
}

}  // namespace fibremss::python
