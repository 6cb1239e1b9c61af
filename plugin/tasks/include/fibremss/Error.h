#pragma once
// The one exception type FibreMSS throws for bad input: it names the file, where in it, and
// what was expected, so a user can fix the input without reading code.
#include <stdexcept>
#include <string>

namespace fibremss {

/// Bad input: a file, a scene field or a parameter that cannot be used.
class InputError : public std::runtime_error {
 public:
  /// `source` is a file path or a scene field; `where` an element, line or key ("" if none).
  InputError(std::string source, std::string where, std::string what)
      : std::runtime_error(compose(source, where, what)),
        source_(std::move(source)),
        where_(std::move(where)),
        what_(std::move(what)) {}

  const std::string& source() const { return source_; }  ///< file path or scene field
  const std::string& where() const { return where_; }    ///< element, line or key; may be empty
  const std::string& problem() const { return what_; }   ///< what was wrong / what was expected

 private:
  static std::string compose(const std::string& source, const std::string& where,
                             const std::string& what) {
    std::string message = source;
    if (!where.empty()) message += ": " + where;
    return message + ": " + what;
  }
  std::string source_;
  std::string where_;
  std::string what_;
};

}  // namespace fibremss
