#include "SceneFields.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <sstream>

#include "fibremss/Error.h"
#include "fibremss/Suggest.h"

namespace fibremss::scene {
namespace {

std::string formatNumber(double value) {
  std::ostringstream out;
  out << value;
  return out.str();
}

/// Why `text` is no valid UTF-8 ("" when it is), as the JSON writer finds it.
std::string utf8Problem(const std::string& text) {
  try {
    (void)Json(text).dump();
    return "";
  } catch (const Json::type_error& e) {  // "[json.exception.type_error.316] invalid UTF-8 ..."
    const std::string what = e.what();
    return what.substr(std::min(what.find("] ") + 2, what.size()));
  }
}

}  // namespace

std::string numberRange(double lowest, double highest, bool lowestExcluded) {
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

std::string joinPath(const std::string& path, const std::string& key) {
  return path.empty() ? key : path + "." + key;
}

namespace {

/// Appends `value` as compact JSON until `out` passes `limit` characters: every level adds a
/// character, so neither the depth nor the size of the value matters.
void describeInto(const Json& value, std::string& out, size_t limit) {
  if (out.size() > limit) return;
  if (!value.is_structured()) {
    out += value.dump(-1, ' ', false, Json::error_handler_t::replace)
               .substr(0, limit + 1 - out.size());
    return;
  }
  out += value.is_object() ? '{' : '[';
  bool first = true;
  for (auto it = value.begin(); it != value.end() && out.size() <= limit; ++it, first = false) {
    if (!first) out += ',';
    if (value.is_object())
      out += Json(it.key()).dump(-1, ' ', false, Json::error_handler_t::replace) + ':';
    describeInto(it.value(), out, limit);
  }
  out += value.is_object() ? '}' : ']';
}

/// Where the parser is: one frame per open object or array.
struct ParseFrame {
  bool array = false;          ///< an array (else an object)
  size_t index = 0;            ///< array: the element being read
  std::string key;             ///< object: the key being read
  std::set<std::string> keys;  ///< object: the keys seen
};

std::string pathOf(const std::vector<ParseFrame>& frames) {
  std::string path;
  for (const ParseFrame& frame : frames)
    path = frame.array ? path + "[" + std::to_string(frame.index) + "]" : joinPath(path, frame.key);
  return path;
}

}  // namespace

std::string describe(const Json& value) {
  constexpr size_t kLimit = 60;
  std::string text;
  describeInto(value, text, kLimit);
  if (text.size() > kLimit) text = text.substr(0, kLimit - 3) + "...";
  return text;
}

Json parseJson(const std::string& text, const std::string& source) {
  std::vector<ParseFrame> frames;
  auto enter = [&](bool array) {
    if (frames.size() >= kMaxJsonDepth)
      throw InputError(source, pathOf(frames),
                       "nested deeper than " + std::to_string(kMaxJsonDepth) +
                           " levels; a scene needs a handful");
    frames.push_back(ParseFrame{array, 0, {}, {}});
  };
  auto leave = [&] {
    frames.pop_back();
    if (!frames.empty() && frames.back().array) ++frames.back().index;
  };
  const Json::parser_callback_t check = [&](int, Json::parse_event_t event, Json& parsed) {
    using Event = Json::parse_event_t;
    if (event == Event::object_start || event == Event::array_start)
      enter(event == Event::array_start);
    if (event == Event::object_end || event == Event::array_end) leave();
    if (event == Event::value && !frames.empty() && frames.back().array) ++frames.back().index;
    if (event == Event::key) {
      ParseFrame& frame = frames.back();
      frame.key = parsed.get<std::string>();
      if (!frame.keys.insert(frame.key).second)
        throw InputError(source, pathOf(frames),
                         "duplicate key: the object has this key twice (JSON keeps only one)");
    }
    return true;
  };
  try {
    return Json::parse(text, check);
  } catch (const Json::exception& e) {  // parse_error, and out_of_range for numbers like 1e999
    throw InputError(source, "", std::string("not valid JSON: ") + e.what());
  }
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
      fail(key, "expected " + numberRange(lowest, highest, lowestExcluded) + ", got " +
                    describe(*value));
    result = value->get<double>();
  }
  const bool tooLow = lowestExcluded ? !(result > lowest) : !(result >= lowest);
  if (!std::isfinite(result) || tooLow || result > highest)
    fail(key, "expected " + numberRange(lowest, highest, lowestExcluded) + ", got " +
                  formatNumber(result));
  // The solver stores btScalar: 1e-46 would become 0 and 1e39 inf in float.
  constexpr double kLargest = std::numeric_limits<btScalar>::max();
  constexpr double kSmallest = std::numeric_limits<btScalar>::min();
  if (result != 0 && (std::abs(result) > kLargest || std::abs(result) < kSmallest))
    fail(key, "expected a magnitude between " + formatNumber(kSmallest) + " and " +
                  formatNumber(kLargest) + " (btScalar, " + std::to_string(sizeof(btScalar) * 8) +
                  "-bit), got " + formatNumber(result));
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

std::string Fields::text(const std::string& key, const std::string& fallback, size_t maxBytes) {
  const Json* value = raw(key);
  std::string result = fallback;
  if (value) {
    if (!value->is_string()) fail(key, "expected a string, got " + describe(*value));
    result = value->get<std::string>();
  }
  if (result.size() > maxBytes)
    fail(key, "expected text of at most " + std::to_string(maxBytes) + " bytes, got " +
                  std::to_string(result.size()));
  if (const std::string problem = utf8Problem(result); !problem.empty())
    fail(key, "expected UTF-8 text, found an " + problem);
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
    fail(key, "expected one of " + list + ", got " + describe(Json(result)));
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
      const std::string suggestion = didYouMean(it.key(), valid);
      std::string message = "unknown field" + suggestion;
      if (!list.empty())
        message += (suggestion.empty() ? "; valid fields here: " : " Valid fields here: ") + list;
      fail(it.key(), message);
    }
  return std::move(complete_);
}

}  // namespace fibremss::scene
