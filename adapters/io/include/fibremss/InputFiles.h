#pragma once
// Reading the files a user names: only regular files of a bounded size (a FIFO, a device such as
// /dev/zero, a directory or a symbolic-link loop is refused before anything opens it), and JSON
// held to one nesting limit (scenes, summaries, landmarks, frames' metadata), so a parser that
// recurses or a value copied recursively stays bounded.
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <string_view>

namespace fibremss {

/// Objects and arrays nested deeper than this are refused (a scene needs about eight).
constexpr size_t kMaxJsonDepth = 100;

/// The largest text file (JSON, motion table) read whole: 256 MiB.
constexpr uint64_t kMaxTextFileBytes = uint64_t(256) << 20;

/// Throws InputError naming `path` unless it is a regular file of 1 to `maxBytes` bytes; the
/// message says it expected `expected` ("a mesh", "a motion table", ...).
void requireInputFile(const std::string& path, const std::string& expected,
                      uint64_t maxBytes = std::numeric_limits<uint64_t>::max());

/// The whole file, checked as requireInputFile() does; InputError when it cannot be read.
std::string readInputFile(const std::string& path, const std::string& expected,
                          uint64_t maxBytes = std::numeric_limits<uint64_t>::max());

/// Throws InputError naming `source` and the byte offset when `text` nests objects and arrays
/// deeper than kMaxJsonDepth (brackets inside strings do not count). Checks nothing else.
void requireJsonDepth(std::string_view text, const std::string& source);

/// The JSON file at `path` as text (at most kMaxTextFileBytes), its nesting checked.
std::string readJsonText(const std::string& path);

}  // namespace fibremss
