#pragma once
// Reading the reference cache's binary values (ReferenceCache.cpp, and the surfaces
// SurfaceDeltas stores in it).
#include <istream>
#include <string>

#include "fibremss/Error.h"

namespace fibremss {

/// Throws InputError naming `path` where the last read from `in` ran past its end.
inline void checkRead(const std::istream& in, const std::string& path) {
  if (!in) throw InputError(path, "", "truncated reference cache file");
}

/// The next sizeof(T) bytes of `in` as a T; throws InputError naming `path` where they run past
/// its end.
template <typename T>
T readValue(std::istream& in, const std::string& path) {
  T v{};
  in.read(reinterpret_cast<char*>(&v), sizeof v);
  checkRead(in, path);
  return v;
}

}  // namespace fibremss
