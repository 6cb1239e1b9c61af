#include "SceneFields.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "fibremss/Error.h"

namespace fibremss::scene {
namespace {

std::string formatNumber(double value) {
  std::ostringstream out;
  out << value;
  return out.str();
}

std::string range(double lowest, double highest, bool lowestExcluded) {
  const double inf = std::numeric_limits<double>::infinity();
  const bool hasLow = lowest > -inf, hasHigh = highest < inf;
  if (hasLow && hasHigh)
    return std::string("a number in ") + (lowestExcluded ? "(" : "[") + formatNumber(lowest) +
           ", " + formatNumber(highest) + "]";
  if (hasLow)
    return std::string("a number ") + (lowestExcluded ? "> " : ">= ") + formatNumber(lowest);
  if (hasHigh) return "a number <= " + formatNumber(highest);
  return "a number";
}

}  // namespace

std::string joinPath(const std::string& path, const std::string& key) {
  return path.empty() ? key : path + "." + key;
}

std::string describe(const Json& value) {
  std::string text = value.dump();
  if (text.size() > 60) text = text.substr(0, 57) + "...";
  return text;
}

btVector3 readVector3(const Json& value, const std::string& path, const std::string& source) {
  if (!value.is_array() || value.size() != 3 ||
      !std::all_of(value.begin(), value.end(), [](const Json& v) { return v.is_number(); }))
    throw InputError(source, path, "expected [x, y, z] (three numbers), got " + describe(value));
  btVector3 result(btScalar(value[0].get<double>()), btScalar(value[1].get<double>()),
                   btScalar(value[2].get<double>()));
  for (int i = 0; i < 3; ++i)
    if (!std::isfinite(value[i].get<double>()))
      throw InputError(source, path, "expected finite numbers, got " + describe(value));
  return result;
}

Fields::Fields(const Json& node, std::string path, std::string source)
    : node_(&node), path_(std::move(path)), source_(std::move(source)) {
  if (!node.is_object())
    throw InputError(source_, path_.empty() ? "(top level)" : path_,
                     "expected a JSON object {...}, got " + describe(node));
}

void Fields::fail(const std::string& key, const std::string& what) const {
  throw InputError(source_, pathOf(key), what);
}

const Json* Fields::raw(const std::string& key) {
  known_.push_back(key);
  const auto found = node_->find(key);
  return found == node_->end() ? nullptr : &*found;
}

void Fields::set(const std::string& key, Json value) {
  complete_[key] = std::move(value);
}

double Fields::number(const std::string& key, double fallback, double lowest, double highest,
                      bool lowestExcluded) {
  const Json* value = raw(key);
  double result = fallback;
  if (value) {
    if (!value->is_number())
      fail(key, "expected " + range(lowest, highest, lowestExcluded) + ", got " + describe(*value));
    result = value->get<double>();
  }
  const bool tooLow = lowestExcluded ? !(result > lowest) : !(result >= lowest);
  if (!std::isfinite(result) || tooLow || result > highest)
    fail(key,
         "expected " + range(lowest, highest, lowestExcluded) + ", got " + formatNumber(result));
  set(key, result);
  return result;
}

int Fields::integer(const std::string& key, int fallback, int lowest, int highest) {
  const Json* value = raw(key);
  long long result = fallback;
  if (value) {
    const bool integral = value->is_number_integer() ||
                          (value->is_number_float() && std::isfinite(value->get<double>()) &&
                           std::floor(value->get<double>()) == value->get<double>());
    if (!integral)
      fail(key, "expected an integer in [" + std::to_string(lowest) + ", " +
                    std::to_string(highest) + "], got " + describe(*value));
    // Range-check an integral float before converting it: 1e300 has no long long.
    const double number = value->is_number_float() ? value->get<double>() : 0;
    if (value->is_number_float() && (number < lowest || number > highest))
      fail(key, "expected an integer in [" + std::to_string(lowest) + ", " +
                    std::to_string(highest) + "], got " + describe(*value));
    result = value->is_number_float() ? static_cast<long long>(number) : value->get<long long>();
  }
  if (result < lowest || result > highest)
    fail(key, "expected an integer in [" + std::to_string(lowest) + ", " + std::to_string(highest) +
                  "], got " + std::to_string(result));
  set(key, int(result));
  return int(result);
}

bool Fields::boolean(const std::string& key, bool fallback) {
  const Json* value = raw(key);
  bool result = fallback;
  if (value) {
    if (!value->is_boolean()) fail(key, "expected true or false, got " + describe(*value));
    result = value->get<bool>();
  }
  set(key, result);
  return result;
}

std::string Fields::text(const std::string& key, const std::string& fallback) {
  const Json* value = raw(key);
  std::string result = fallback;
  if (value) {
    if (!value->is_string()) fail(key, "expected a string, got " + describe(*value));
    result = value->get<std::string>();
  }
  set(key, result);
  return result;
}

std::string Fields::choice(const std::string& key, const std::string& fallback,
                           const std::vector<std::string>& allowed) {
  std::string list;
  for (const auto& name : allowed) list += (list.empty() ? "" : ", ") + ("\"" + name + "\"");
  const Json* value = raw(key);
  if (!value && fallback.empty()) fail(key, "missing: expected one of " + list);
  if (value && !value->is_string())
    fail(key, "expected one of " + list + ", got " + describe(*value));
  const std::string result = value ? value->get<std::string>() : fallback;
  if (std::find(allowed.begin(), allowed.end(), result) == allowed.end())
    fail(key, "expected one of " + list + ", got \"" + result + "\"");
  set(key, result);
  return result;
}

btVector3 Fields::vector3(const std::string& key, const btVector3& fallback) {
  const Json* value = raw(key);
  const btVector3 result = value ? readVector3(*value, pathOf(key), source_) : fallback;
  set(key, Json::array({double(result.x()), double(result.y()), double(result.z())}));
  if (value) complete_[key] = *value;  // keep the user's exact numbers
  return result;
}

Fields Fields::object(const std::string& key) {
  static const Json kEmpty = Json::object();
  const Json* value = raw(key);
  if (value && !value->is_object())
    fail(key, "expected a JSON object {...}, got " + describe(*value));
  return Fields(value ? *value : kEmpty, pathOf(key), source_);
}

const Json& Fields::array(const std::string& key) {
  static const Json kEmpty = Json::array();
  const Json* value = raw(key);
  if (value && !value->is_array())
    fail(key, "expected a JSON array [...], got " + describe(*value));
  return value ? *value : kEmpty;
}

Json Fields::finish() {
  for (auto it = node_->begin(); it != node_->end(); ++it)
    if (std::find(known_.begin(), known_.end(), it.key()) == known_.end()) {
      std::vector<std::string> valid = known_;
      std::sort(valid.begin(), valid.end());
      valid.erase(std::unique(valid.begin(), valid.end()), valid.end());
      std::string list;
      for (const auto& name : valid) list += (list.empty() ? "" : ", ") + name;
      fail(it.key(),
           "unknown field" + (list.empty() ? std::string() : "; valid fields here: " + list));
    }
  return std::move(complete_);
}

}  // namespace fibremss::scene
