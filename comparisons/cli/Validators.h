#pragma once
// Option checks whose messages read as a user writes numbers ("expected an integer >= 0, got
// -1"), instead of CLI11's ranges printed to six decimals up to 1.797e308.
#include <CLI/CLI.hpp>
#include <cmath>
#include <string>

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

}  // namespace fibremss::cli
