// Replays every file under tests/data/regressions/<fuzz target>/ (inputs the fuzzers found,
// minimised, plus small seeds) through the public API the target exercises: each must load
// or fail with fibremss::InputError, never crash, hang or throw anything else.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "fibremss/Error.h"
#include "fibremss/MeshIO.h"
#include "fibremss/Scene.h"
#include "fibremss/VtkFiles.h"
#include "fuzz/FuzzInputs.h"
#include "support/Process.h"

namespace fibremss {
namespace {

namespace fs = std::filesystem;

const fs::path kRegressions = fs::path(FIBREMSS_SOURCE_DIR) / "tests/data/regressions";

std::vector<fs::path> filesOf(const std::string& target) {
  std::vector<fs::path> files;
  if (fs::is_directory(kRegressions / target))
    for (const auto& entry : fs::directory_iterator(kRegressions / target))
      if (entry.is_regular_file()) files.push_back(entry.path());
  std::sort(files.begin(), files.end());
  return files;
}

std::string bytesOf(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}

/// Runs `load` on every file of `target` in a scratch directory; counts InputErrors.
template <typename Load>
void replay(const std::string& target, Load load) {
  const auto files = filesOf(target);
  if (files.empty()) GTEST_SKIP() << "no files under " << (kRegressions / target);
  testing::TemporaryDirectory scratch("fibremss_regression_" + target);
  size_t rejected = 0;
  for (const auto& file : files) {
    SCOPED_TRACE(file.string());
    try {
      load(scratch.path(), bytesOf(file));
    } catch (const InputError& e) {
      ++rejected;
      EXPECT_FALSE(e.problem().empty());
    }
  }
  std::cout << target << ": " << files.size() << " files, " << rejected << " rejected\n";
}

void write(const fs::path& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

TEST(FuzzRegression, Vtk) {
  replay("fuzz_vtk", [](const fs::path& scratch, const std::string& bytes) {
    const fs::path file = scratch / "input.vtk";
    write(file, bytes);
    // The same bytes as a surface and as fibres: either may fail, independently.
    try {
      loadSurface(file.string());
    } catch (const InputError&) {
    }
    loadFibres(file.string());
  });
}

TEST(FuzzRegression, Vtp) {
  replay("fuzz_vtp", [](const fs::path& scratch, const std::string& bytes) {
    const fs::path file = scratch / "input.vtp";
    write(file, bytes);
    try {
      loadSurface(file.string());
    } catch (const InputError&) {
    }
    loadFibres(file.string());
  });
}

TEST(FuzzRegression, ObjFibres) {
  replay("fuzz_obj_fibres", [](const fs::path& scratch, const std::string& bytes) {
    const fs::path file = scratch / "input.obj";
    write(file, bytes);
    loadFibres(file.string());
  });
}

TEST(FuzzRegression, MeshCheck) {
  replay("fuzz_mesh_check", [](const fs::path&, const std::string& bytes) {
    const TriangleMesh mesh = fuzz::meshFromBytes(bytes);
    checkSurface(mesh, "regression");
    FibreSet fibres;
    if (mesh.vertices.size() >= 2) fibres.addFibre({mesh.vertices.data(), 2});
    checkFibres(fibres, mesh, "regression", 1e-3);
  });
}

/// scratch/scene.json holding `json`, with scratch/meshes linked to the scene test meshes so
/// that relative mesh references resolve as they did for the fuzzer.
fs::path writeScene(const fs::path& scratch, const std::string& json) {
  const fs::path meshes = scratch / "meshes";
  if (!fs::exists(meshes))
    fs::create_directory_symlink(fs::path(FIBREMSS_SOURCE_DIR) / "tests/data/scenes/meshes",
                                 meshes);
  write(scratch / "scene.json", json);
  return scratch / "scene.json";
}

TEST(FuzzRegression, SceneJson) {
  replay("fuzz_scene_json", [](const fs::path& scratch, const std::string& bytes) {
    loadScene(writeScene(scratch, bytes).string());
  });
}

TEST(FuzzRegression, SceneStructured) {
  replay("fuzz_scene_structured", [](const fs::path& scratch, const std::string& bytes) {
    const std::string json = fuzz::sceneJsonFromBytes(bytes);
    try {
      loadScene(writeScene(scratch, json).string());
    } catch (const InputError&) {
    }
    loadScene("fusiform", {"model=" + json, "muscles.0=" + json});
  });
}

TEST(FuzzRegression, Motion) {
  replay("fuzz_motion", [](const fs::path& scratch, const std::string& bytes) {
    write(scratch / "motion.mot", bytes);
    write(scratch / "motion-scene.json", fuzz::motionSceneJson((scratch / "motion.mot").string()));
    loadScene((scratch / "motion-scene.json").string());
  });
}

TEST(FuzzRegression, Pvd) {
  replay("fuzz_pvd", [](const fs::path& scratch, const std::string& bytes) {
    write(scratch / "run.pvd", bytes);
    for (const PvdDataSet& set : readPvd((scratch / "run.pvd").string()))
      EXPECT_FALSE(set.file.empty());
  });
}

}  // namespace
}  // namespace fibremss
