// Reading the files a user names: regular files of a bounded size, JSON of a bounded nesting.
#include "fibremss/InputFiles.h"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "fibremss/Error.h"

namespace fibremss {

void requireInputFile(const std::string& path, const std::string& expected, uint64_t maxBytes) {
  namespace fs = std::filesystem;
  std::error_code error;
  const auto status = fs::status(path, error);
  if (error && error != std::errc::no_such_file_or_directory)
    throw InputError(path, "", "cannot open: " + error.message() + "; expected " + expected);
  if (!fs::exists(status)) throw InputError(path, "", "cannot open: the file does not exist");
  if (!fs::is_regular_file(status))
    throw InputError(path, "", "cannot open: expected a regular file holding " + expected);
  const uint64_t size = fs::file_size(path, error);
  if (error) throw InputError(path, "", "cannot open: " + error.message());
  if (size == 0) throw InputError(path, "", "the file is empty; expected " + expected);
  if (size > maxBytes)
    throw InputError(path, "",
                     "the file has " + std::to_string(size) + " bytes; expected " + expected +
                         " of at most " + std::to_string(maxBytes) + " bytes");
}

std::string readInputFile(const std::string& path, const std::string& expected, uint64_t maxBytes) {
  requireInputFile(path, expected, maxBytes);
  std::ifstream file(path, std::ios::binary);
  if (!file) throw InputError(path, "", std::string("cannot open: ") + std::strerror(errno));
  std::string bytes((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  if (file.bad()) throw InputError(path, "", "cannot read the file");
  if (bytes.empty()) throw InputError(path, "", "the file is empty; expected " + expected);
  return bytes;
}

void requireJsonDepth(std::string_view text, const std::string& source) {
  size_t depth = 0;
  bool inString = false;
  for (size_t at = 0; at < text.size(); ++at) {
    const char c = text[at];
    if (inString) {
      if (c == '\\') ++at;  // the escaped character is text
      inString = c != '"';
    } else if (c == '"') {
      inString = true;
    } else if (c == '[' || c == '{') {
      if (++depth > kMaxJsonDepth)
        throw InputError(source, "byte " + std::to_string(at),
                         "nested deeper than " + std::to_string(kMaxJsonDepth) +
                             " levels; expected at most a handful");
    } else if ((c == ']' || c == '}') && depth > 0) {
      --depth;
    }
  }
}

std::string readJsonText(const std::string& path) {
  std::string text = readInputFile(path, "JSON", kMaxTextFileBytes);
  requireJsonDepth(text, path);
  return text;
}

}  // namespace fibremss
