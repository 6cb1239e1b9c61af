#pragma once
// Files a hostile user brings, written by tests: a small scene in millimetres (a cube bone
// touching a box muscle with four straight fibres), the CLI run on them, and what it left.
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "Process.h"

namespace fibremss::testing {

namespace fs = std::filesystem;

/// Runs the CLI with `arguments`; stdout and stderr together in `output`.
inline ProcessResult cli(const std::string& arguments) {
  return runProcess(std::string("\"") + FIBREMSS_CLI + "\" " + arguments + " 2>&1");
}

inline void writeFile(const fs::path& path, const std::string& content) {
  std::ofstream(path, std::ios::binary) << content;
}

/// The cube a bone or muscle surface is made of, as OBJ, `size` mm wide, at `x` mm.
inline std::string cubeObj(double size, double x = 0) {
  std::string obj;
  for (int i = 0; i < 8; ++i)
    obj += "v " + std::to_string(x + (i & 1 ? size : 0)) + " " + std::to_string(i & 2 ? size : 0) +
           " " + std::to_string(i & 4 ? size : 0) + "\n";
  obj +=
      "f 1 3 2\nf 2 3 4\nf 5 6 7\nf 6 8 7\nf 1 2 5\nf 2 6 5\nf 3 7 4\nf 4 7 8\nf 1 5 3\nf 3 5 "
      "7\nf 2 4 6\nf 4 8 6\n";
  return obj;
}

/// A scene in mm in `dir`: a cube bone at x < 0 (in `boneFile`; bone.obj is written) touching a
/// 20 mm box muscle with four straight fibres (hanging from the cube: its insertion is free),
/// every coordinate multiplied by `scale`, `extra` top-level fields after them. Returns the scene
/// path.
inline fs::path writeScene(const fs::path& dir, double scale = 1, const std::string& extra = "",
                           const std::string& boneFile = "bone.obj") {
  writeFile(dir / "bone.obj", cubeObj(10 * scale, -10 * scale));
  writeFile(dir / "muscle.obj", cubeObj(20 * scale));
  std::string fibres;
  for (int f = 0; f < 4; ++f) {
    const double y = (5 + 10 * (f & 1)) * scale, z = (5 + 10 * (f >> 1)) * scale;
    fibres += "v " + std::to_string(0.5 * scale) + " " + std::to_string(y) + " " +
              std::to_string(z) + "\nv " + std::to_string(19.5 * scale) + " " + std::to_string(y) +
              " " + std::to_string(z) + "\n";
  }
  fibres += "l 1 2\nl 3 4\nl 5 6\nl 7 8\n";
  writeFile(dir / "fibres.obj", fibres);
  const fs::path scene = dir / "scene.json";
  writeFile(scene, R"({"units": "mm", "bones": [{"name": "cube", "mesh": {"file": ")" + boneFile +
                       R"("}}],
    "muscles": [{"name": "box", "surface": {"file": "muscle.obj"},
                 "fibres": {"file": "fibres.obj"}, "resolution": 5, "fibre_count": 4,
                 "free_end": "insertion"}])" +
                       extra + "}");
  return scene;
}

/// The directory's files, recursively, relative to it.
inline std::vector<std::string> filesIn(const fs::path& dir) {
  std::vector<std::string> files;
  if (!fs::exists(dir)) return files;
  for (const auto& entry : fs::recursive_directory_iterator(dir))
    if (entry.is_regular_file()) files.push_back(fs::relative(entry.path(), dir).string());
  std::sort(files.begin(), files.end());
  return files;
}

}  // namespace fibremss::testing
