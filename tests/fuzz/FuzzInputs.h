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
#include <vector>

#include "fibremss/Geometry.h"
#include "fibremss/Scene.h"

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

/// The keys sceneJsonFromBytes writes: every scene field name, as the scene reader lists them.
inline const std::vector<std::string>& sceneKeyTable() {
  static const std::vector<std::string> keys = sceneKeys();
  return keys;
}
/// The strings sceneJsonFromBytes writes: the scene's words and file names.
inline constexpr const char* kSceneWords[] = {"m",
                                              "mm",
                                              "box",
                                              "tube",
                                              "ellipsoid",
                                              "chords",
                                              "sweep",
                                              "keyframes",
                                              "none",
                                              "auto",
                                              "budget",
                                              "converged",
                                              "verlet",
                                              "xpbd",
                                              "fixed",
                                              "adaptive",
                                              "retry",
                                              "report",
                                              "stop-body",
                                              "lattice6",
                                              "delaunay",
                                              "meshes/cube.obj",
                                              "meshes/muscle.obj",
                                              "meshes/fibres.obj",
                                              "${data_dir}/x.obj",
                                              "",
                                              "round",
                                              "grid"};
/// The numbers sceneJsonFromBytes writes besides its random ones: edges of int, float, double.
inline constexpr const char* kSceneNumbers[] = {"0",
                                                "1",
                                                "2",
                                                "-1",
                                                "3",
                                                "10",
                                                "40",
                                                "0.5",
                                                "1e-3",
                                                "-0",
                                                "1e-46",
                                                "1e39",
                                                "1e-40",
                                                "1e308",
                                                "1e-320",
                                                "9223372036854775807",
                                                "-9223372036854775808",
                                                "18446744073709551616",
                                                "4294967296",
                                                "1e16",
                                                "1e12",
                                                "0.001",
                                                "100000",
                                                "2147483648"};

/// Scene JSON text from bytes, aware of its structure: every byte is a step of a writer that
/// opens objects and arrays (so a run of bytes nests thousands deep), closes them, and writes
/// scene field names as keys (sometimes twice in one object), the scene's words as strings
/// ("mm", "sweep", "budget", "meshes/cube.obj", ...), booleans, nulls and numbers from small
/// integers to 1e±400, denormals, -0 and the int64 limits. The top level is an object and every
/// container is closed at the end, so the text is JSON unless a number overflows.
inline std::string sceneJsonFromBytes(std::string_view bytes) {
  size_t at = 0;
  auto next = [&]() -> uint8_t { return at < bytes.size() ? uint8_t(bytes[at++]) : 0; };
  auto pick = [&](const auto& table) { return table[next() % std::size(table)]; };
  std::string json = "{";
  std::vector<char> open = {'}'};  // closers of the open containers
  std::vector<bool> first = {true};
  auto startValue = [&] {
    if (!first.back()) json += ',';
    first.back() = false;
    if (open.back() == '}') json += "\"" + pick(sceneKeyTable()) + "\":";
  };
  while (at < bytes.size()) {
    const uint8_t op = next() % 16;
    if (op == 5) {
      if (open.size() > 1) {
        json += open.back();
        open.pop_back();
        first.pop_back();
      }
      continue;
    }
    startValue();
    if (op <= 4) {
      json += op <= 2 ? '{' : '[';
      open.push_back(op <= 2 ? '}' : ']');
      first.push_back(true);
    } else if (op <= 8) {
      // Mantissa -128..127, exponent -512..508: past float, past double, denormal.
      json += op == 8 ? std::to_string(int8_t(next())) + "e" + std::to_string(next() * 4 - 512)
                      : std::string(pick(kSceneNumbers));
    } else if (op <= 11) {
      json += std::string("\"") + pick(kSceneWords) + "\"";
    } else if (op <= 13) {
      json += next() & 1 ? "true" : "false";
    } else {
      json += "null";
    }
  }
  for (auto closer = open.rbegin(); closer != open.rend(); ++closer) json += *closer;
  return json;
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

/// scene.json in the scratch directory holding `json`, next to a "meshes" link to the scene test
/// meshes (FIBREMSS_SCENE_MESHES) so that relative file references resolve.
inline std::filesystem::path writeScratchScene(std::string_view json, const char* meshDirectory) {
  const std::filesystem::path scene = writeScratchFile("scene.json", json);
  const auto meshes = scene.parent_path() / "meshes";
  if (!std::filesystem::exists(meshes))
    std::filesystem::create_directory_symlink(meshDirectory, meshes);
  return scene;
}

/// A scene whose one bone, a generated box, follows the OpenSim motion `motionFile`: columns
/// "q1" and "q2" turned about x and y, its jumps split into sub-poses (the motion targets).
inline std::string motionSceneJson(const std::string& motionFile) {
  return R"({"units": "mm", "bones": [{"name": "femur", "mesh": {"generator": {"type": "box",
    "centre": [0, 0, -60], "size": [10, 10, 80]}}, "motion": {"type": "opensim", "file": ")" +
         motionFile + R"(", "coordinates": [{"column": "q1", "axis": [1, 0, 0]},
    {"column": "q2", "axis": [0, 1, 0]}]}}], "simulation": {"max_step_deg": 5}})";
}

}  // namespace fibremss::fuzz
