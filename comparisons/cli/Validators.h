#pragma once
// Option checks whose messages read as a user writes numbers ("expected an integer >= 0, got
// -1"), instead of CLI11's ranges printed to six decimals up to 1.797e308; choices whose help
// lists them once ("vtk|gltf"); flags that turn a setting off.
#include <CLI/CLI.hpp>
#include <cmath>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace fibremss::cli {

/// A number >= `lowest` (> when `excluded`), finite; `integer` also refuses fractions.
inline CLI::Validator atLeast(double lowest, bool excluded = false, bool integer = false) {
  const std::string noun = integer ? "an integer" : "a number";
  std::string bound = CLI::detail::to_string(lowest);
  if (integer || lowest == std::floor(lowest))
    bound = std::to_string(static_cast<long long>(lowest));
  const std::string expected = noun + (excluded ? " > " : " >= ") + bound;
  return CLI::Validator(
      [=](std::string& text) -> std::string {
        double value = 0;
        size_t used = 0;
        try {
          value = std::stod(text, &used);
        } catch (const std::exception&) {
          used = 0;
        }
        const bool ok = used == text.size() && std::isfinite(value) &&
                        (excluded ? value > lowest : value >= lowest) &&
                        (!integer || value == std::floor(value));
        return ok ? std::string() : "expected " + expected + ", got " + text;
      },
      expected.substr(noun.size() + 1));
}

inline CLI::Validator nonNegativeInteger() {
  return atLeast(0, false, true);
}
inline CLI::Validator positiveInteger() {
  return atLeast(0, true, true);
}
inline CLI::Validator nonNegativeNumber() {
  return atLeast(0);
}
inline CLI::Validator positiveNumber() {
  return atLeast(0, true);
}

/// One of `names` (case ignored), rewritten as `converted(index)` for CLI11 to read; else
/// "expected one of a, b, got c". No description: the option's type name lists the choices.
inline CLI::Validator namedChoice(std::vector<std::string> names,
                                  std::function<std::string(size_t)> converted) {
  std::string list;
  for (const std::string& name : names) list += (list.empty() ? "" : ", ") + name;
  return CLI::Validator(
      [names = std::move(names), converted = std::move(converted),
       list](std::string& text) -> std::string {
        for (size_t i = 0; i < names.size(); ++i)
          if (CLI::detail::to_lower(names[i]) == CLI::detail::to_lower(text)) {
            text = converted(i);
            return {};
          }
        return "expected one of " + list + ", got " + text;
      },
      "");
}

/// One of `names` (case ignored), passed on as written there.
inline CLI::Validator oneOf(const std::vector<std::string>& names) {
  return namedChoice(names, [names](size_t i) { return names[i]; });
}

/// A flag `name` that sets `target` to false (its help shows no "{false}", as CLI11's
/// "!--name" flags do).
inline CLI::Option* addOffFlag(CLI::App& command, const std::string& name, bool& target,
                               const std::string& description) {
  return command.add_flag_callback(
      name, [&target] { target = false; }, description);
}

}  // namespace fibremss::cli
