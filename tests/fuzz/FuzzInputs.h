#pragma once
// How the fuzz targets and the regression replay turn raw bytes into loader input, so that a
// file a fuzzer found replays through the same path in ctest.
#include <unistd.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

#include "fibremss/Geometry.h"

namespace fibremss::fuzz {

/// A triangle mesh from bytes: byte 0 is the vertex count (0..255), then three floats per
/// vertex (any bit pattern, NaN and inf included), then three bytes per triangle taken as
/// vertex indices (so indices past the vertex count occur too). Missing bytes read as zero.
inline TriangleMesh meshFromBytes(std::string_view bytes) {
  TriangleMesh mesh;
  if (bytes.empty()) return mesh;
  const size_t vertexCount = uint8_t(bytes[0]);
  size_t at = 1;
  auto nextFloat = [&] {
    float value = 0;
    if (at + sizeof value <= bytes.size()) std::memcpy(&value, bytes.data() + at, sizeof value);
    at += sizeof value;
    return value;
  };
  for (size_t i = 0; i < vertexCount; ++i) {
    const float x = nextFloat(), y = nextFloat(), z = nextFloat();
    mesh.vertices.emplace_back(btScalar(x), btScalar(y), btScalar(z));
  }
  for (; at + 3 <= bytes.size(); at += 3)
    mesh.triangles.push_back({uint8_t(bytes[at]), uint8_t(bytes[at + 1]), uint8_t(bytes[at + 2])});
  return mesh;
}

/// A scratch directory for this process with `name` inside it, holding `bytes`; the scene
/// targets link "meshes" to the scene test meshes so that relative file references resolve.
inline std::filesystem::path writeScratchFile(const std::string& name, std::string_view bytes) {
  const auto directory =
      std::filesystem::temp_directory_path() / ("fibremss_fuzz_" + std::to_string(::getpid()));
  std::filesystem::create_directories(directory);
  const auto path = directory / name;
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), bytes.size());
  return path;
}

}  // namespace fibremss::fuzz
