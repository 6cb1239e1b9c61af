// The bad-input catalogue (docs/bad-inputs.md): one row per class of bad input. Each
// row writes a small scene (a cube bone, a box muscle, four fibres, in millimetres) into a
// temporary directory, spoils one thing, and checks the outcome class twice: through the
// public API (loadSurface / loadFibres / loadScene + prepareScene) and through
// `fibremss check SCENE --out DIR`, which must exit with 2, name the problem on stderr and
// leave DIR empty for errors, or exit with 0 and print the warning for things a run can
// live with.
#include <gtest/gtest.h>

#include <array>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "fibremss/Error.h"
#include "fibremss/MeshIO.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "support/Process.h"

namespace fibremss {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;
using Triangle = std::array<int, 3>;

/// A box from `lower` to `upper`: 8 vertices (bit 0: x, bit 1: y, bit 2: z at the upper
/// side) and 12 triangles, counter-clockwise seen from outside.
struct Box {
  std::array<double, 3> lower, upper;
  std::vector<std::array<double, 3>> vertices() const {
    std::vector<std::array<double, 3>> result;
    for (int v = 0; v < 8; ++v)
      result.push_back(
          {v & 1 ? upper[0] : lower[0], v & 2 ? upper[1] : lower[1], v & 4 ? upper[2] : lower[2]});
    return result;
  }
  static std::vector<Triangle> triangles() {
    return {{0, 4, 6}, {0, 6, 2}, {1, 7, 5}, {1, 3, 7}, {0, 1, 5}, {0, 5, 4},
            {2, 6, 7}, {2, 7, 3}, {0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6}};
  }
};

const Box kBone{{-10, 20, -10}, {10, 40, 10}};
const Box kMuscle{{-5, -20, -5}, {5, 20, 5}};

std::string obj(const std::vector<std::array<double, 3>>& vertices,
                const std::vector<Triangle>& triangles) {
  std::ostringstream out;
  for (const auto& v : vertices) out << "v " << v[0] << " " << v[1] << " " << v[2] << "\n";
  for (const auto& t : triangles)
    out << "f " << t[0] + 1 << " " << t[1] + 1 << " " << t[2] + 1 << "\n";
  return out.str();
}

std::string boxObj(const Box& box, std::vector<Triangle> triangles = Box::triangles()) {
  return obj(box.vertices(), triangles);
}

std::string asciiVtk(const std::vector<std::string>& points,
                     const std::vector<Triangle>& triangles) {
  std::ostringstream out;
  out << "# vtk DataFile Version 3.0\nbad input\nASCII\nDATASET POLYDATA\nPOINTS " << points.size()
      << " float\n";
  for (const auto& p : points) out << p << "\n";
  if (!triangles.empty()) {
    out << "POLYGONS " << triangles.size() << " " << 4 * triangles.size() << "\n";
    for (const auto& t : triangles) out << "3 " << t[0] << " " << t[1] << " " << t[2] << "\n";
  }
  return out.str();
}

std::vector<std::string> boxPoints(const Box& box) {
  std::vector<std::string> points;
  for (const auto& v : box.vertices())
    points.push_back(std::to_string(v[0]) + " " + std::to_string(v[1]) + " " +
                     std::to_string(v[2]));
  return points;
}

/// The bone as BINARY legacy VTK; `bigEndian` false writes the (wrong) little-endian order.
std::string binaryVtk(const Box& box, bool bigEndian) {
  std::string out =
      "# vtk DataFile Version 3.0\nbad input\nBINARY\nDATASET POLYDATA\nPOINTS 8 float\n";
  auto put = [&](uint32_t bits) {
    for (int byte = 0; byte < 4; ++byte)
      out += char(bigEndian ? bits >> (24 - 8 * byte) : bits >> (8 * byte));
  };
  for (const auto& v : box.vertices())
    for (double c : v) put(std::bit_cast<uint32_t>(float(c)));
  out += "\nPOLYGONS 12 48\n";
  for (const auto& t : Box::triangles()) {
    put(3);
    for (int i : t) put(uint32_t(i));
  }
  return out + "\n";
}

/// `count` straight fibres along y inside the muscle box, on a square-ish grid.
std::string fibresObj(int count, double y0 = -19, double y1 = 19) {
  std::ostringstream out;
  const int columns = int(std::ceil(std::sqrt(double(count))));
  for (int f = 0; f < count; ++f) {
    const double x = -4 + 8.0 * (f % columns + 0.5) / columns;
    const double z = -4 + 8.0 * (f / columns + 0.5) / columns;
    out << "v " << x << " " << y0 << " " << z << "\nv " << x << " " << y1 << " " << z << "\n";
  }
  for (int f = 0; f < count; ++f) out << "l " << 2 * f + 1 << " " << 2 * f + 2 << "\n";
  return out.str();
}

/// One row's input: the files of a scene and the scene itself, before the row spoils them.
struct Input {
  std::map<std::string, std::string> files{
      {"bone.obj", boxObj(kBone)}, {"muscle.obj", boxObj(kMuscle)}, {"fibres.obj", fibresObj(4)}};
  Json scene = {{"name", "bad-input"},
                {"units", "mm"},
                {"bones", {{{"name", "cube"}, {"mesh", {{"file", "bone.obj"}}}}}},
                {"muscles",
                 {{{"name", "box"},
                   {"surface", {{"file", "muscle.obj"}}},
                   {"fibres", {{"file", "fibres.obj"}}},
                   {"fibre_count", 4},
                   {"resolution", 10},
                   {"free_end", "origin"}}}}};  // it hangs from the cube
  Json& bone() { return scene["bones"][0]; }
  Json& muscle() { return scene["muscles"][0]; }
};

enum class Outcome { Error, Warning };
/// The public call a row goes through in-process (every row also runs the CLI on the scene).
enum class Api { Surface, Fibres, Scene };

struct BadInput {
  std::string name;                   ///< test name
  Api api;                            ///< loadSurface / loadFibres of `file`, or the scene
  std::string file;                   ///< the file the loader reads (Surface, Fibres)
  std::function<void(Input&)> spoil;  ///< makes the input bad
  Outcome outcome;                    ///< InputError, or a warning and a run that goes on
  std::string source;                 ///< the message names this file or field
  std::string phrase;                 ///< ... and says this
  std::string memoryLimitMb = "";     ///< FIBREMSS_MEMORY_LIMIT_MB for the row ("" unset)
};

std::ostream& operator<<(std::ostream& out, const BadInput& row) {
  return out << row.name;
}

/// Surface files that do not read as a mesh.
std::vector<BadInput> surfaceReadRows() {
  return {
      {"EmptyFile", Api::Surface, "bone.vtk",
       [](Input& in) {
         in.files["bone.vtk"] = "";
         in.bone()["mesh"]["file"] = "bone.vtk";
       },
       Outcome::Error, "bone.vtk", "empty"},
      {"TruncatedBinaryVtk", Api::Surface, "bone.vtk",
       [](Input& in) {
         in.files["bone.vtk"] = binaryVtk(kBone, true).substr(0, 120);
         in.bone()["mesh"]["file"] = "bone.vtk";
       },
       Outcome::Error, "bone.vtk", "bytes are left"},
      {"WrongEndiannessBinaryVtk", Api::Surface, "bone.vtk",
       [](Input& in) {
         in.files["bone.vtk"] = binaryVtk(kBone, false);
         in.bone()["mesh"]["file"] = "bone.vtk";
       },
       Outcome::Error, "bone.vtk", "must be big-endian"},
      {"NanCoordinate", Api::Surface, "bone.vtk",
       [](Input& in) {
         auto points = boxPoints(kBone);
         points[3] = "10 nan 10";
         in.files["bone.vtk"] = asciiVtk(points, Box::triangles());
         in.bone()["mesh"]["file"] = "bone.vtk";
       },
       Outcome::Error, "bone.vtk", "finite"},
      {"InfiniteCoordinate", Api::Surface, "muscle.vtk",
       [](Input& in) {
         auto points = boxPoints(kMuscle);
         points[5] = "5 inf -5";
         in.files["muscle.vtk"] = asciiVtk(points, Box::triangles());
         in.muscle()["surface"]["file"] = "muscle.vtk";
       },
       Outcome::Error, "muscle.vtk", "finite"},
      {"IndexOutOfRange", Api::Surface, "bone.vtk",
       [](Input& in) {
         auto triangles = Box::triangles();
         triangles[4][1] = 8;
         in.files["bone.vtk"] = asciiVtk(boxPoints(kBone), triangles);
         in.bone()["mesh"]["file"] = "bone.vtk";
       },
       Outcome::Error, "bone.vtk", "point index"},
      {"IndexOutOfRangeObj", Api::Surface, "bone.obj",
       [](Input& in) { in.files["bone.obj"] = boxObj(kBone) + "f 1 2 99\n"; }, Outcome::Error,
       "bone.obj", "vertex index out of range"},
      {"NoTrianglesBone", Api::Surface, "bone.vtk",
       [](Input& in) {
         in.files["bone.vtk"] = asciiVtk(boxPoints(kBone), {});
         in.bone()["mesh"]["file"] = "bone.vtk";
       },
       Outcome::Error, "bone.vtk", "triangle"},
      {"NotAMesh", Api::Surface, "bone.stl",
       [](Input& in) {
         in.files["bone.stl"] = "this is not a mesh\n";
         in.bone()["mesh"]["file"] = "bone.stl";
       },
       Outcome::Error, "bone.stl", "expected a surface mesh"},
  };
}

/// Surfaces that read but are no closed solid.
std::vector<BadInput> surfaceShapeRows() {
  return {
      {"ZeroAreaTriangle", Api::Surface, "bone.obj",
       [](Input& in) {
         auto triangles = Box::triangles();
         triangles.push_back({0, 0, 1});
         in.files["bone.obj"] = boxObj(kBone, triangles);
       },
       Outcome::Warning, "bone.obj", "degenerate"},
      {"DuplicateTriangle", Api::Surface, "bone.obj",
       [](Input& in) {
         auto triangles = Box::triangles();
         triangles.push_back(triangles[0]);
         in.files["bone.obj"] = boxObj(kBone, triangles);
       },
       Outcome::Warning, "bone.obj", "repeats triangle"},
      {"OpenSurface", Api::Surface, "bone.obj",
       [](Input& in) {
         auto triangles = Box::triangles();
         triangles.pop_back();
         in.files["bone.obj"] = boxObj(kBone, triangles);
       },
       Outcome::Warning, "bone.obj", "open"},
      {"NonManifoldEdge", Api::Surface, "bone.obj",
       [](Input& in) {
         auto vertices = kBone.vertices();
         vertices.push_back({0, 30, 30});
         auto triangles = Box::triangles();
         triangles.push_back({0, 4, 8});
         in.files["bone.obj"] = obj(vertices, triangles);
       },
       Outcome::Warning, "bone.obj", "non-manifold"},
      {"InvertedNormals", Api::Surface, "muscle.obj",
       [](Input& in) {
         auto triangles = Box::triangles();
         for (auto& t : triangles) std::swap(t[1], t[2]);
         in.files["muscle.obj"] = boxObj(kMuscle, triangles);
       },
       Outcome::Warning, "muscle.obj", "inward"},
      {"FlatMuscleSurface", Api::Scene, "",
       [](Input& in) {
         Box flat = kMuscle;
         flat.upper[2] = flat.lower[2];
         in.files["muscle.obj"] = boxObj(flat);
       },
       Outcome::Error, "muscle", "no volume"},
  };
}

/// Fibre files that give no usable fibre.
std::vector<BadInput> fibreRows() {
  return {
      {"MuscleWithNoFibres", Api::Fibres, "fibres.obj",
       [](Input& in) { in.files["fibres.obj"] = "v 0 0 0\nv 0 1 0\n"; }, Outcome::Error,
       "fibres.obj", "found none"},
      {"SinglePointFibre", Api::Fibres, "fibres.obj",
       [](Input& in) { in.files["fibres.obj"] = fibresObj(4) + "v 0 0 0\nl 9\n"; }, Outcome::Error,
       "fibres.obj", "point"},
      {"ZeroLengthFibre", Api::Fibres, "fibres.obj",
       [](Input& in) { in.files["fibres.obj"] = fibresObj(4) + "v 0 0 0\nv 0 0 0\nl 9 10\n"; },
       Outcome::Error, "fibres.obj", "length"},
      {"FibreIndexOutOfRange", Api::Fibres, "fibres.obj",
       [](Input& in) { in.files["fibres.obj"] = fibresObj(4) + "l 1 42\n"; }, Outcome::Error,
       "fibres.obj", "42"},
      {"FibresOutsideMuscle", Api::Scene, "",
       [](Input& in) { in.files["fibres.obj"] = fibresObj(4, -60, 19); }, Outcome::Warning,
       "fibres.obj", "outside"},
      // Fibres from files merge near-coincident particles of different fibres, except
      // in the lattice layouts, whose grid a merge would break: fibre 3 repeated next to it.
      {"CoincidentParticles", Api::Scene, "",
       [](Input& in) {
         in.files["fibres.obj"] = fibresObj(4) + "v 2 -19 2\nv 2 19 2\nl 9 10\n";
         in.muscle()["fibre_count"] = 5;
         in.muscle()["fibre_grid_columns"] = 5;
         in.scene["model"] = {{"layout", "lattice6"}};
       },
       Outcome::Error, "particles", "coincide"},
  };
}

/// Scene fields that are missing, unknown or of the wrong kind.
std::vector<BadInput> sceneFieldRows() {
  return {
      {"MuscleTouchingNoBone", Api::Scene, "",
       [](Input& in) {
         in.bone()["transform"] = {{"translation", {0, 100, 0}}};
       },
       Outcome::Error, "box", "no particle is fixed at its insertion"},
      {"MissingFile", Api::Scene, "",
       [](Input& in) { in.muscle()["fibres"]["file"] = "nowhere.obj"; }, Outcome::Error,
       "muscles[0].fibres.file", "no such file"},
      {"InvalidJson", Api::Scene, "", [](Input& in) { in.scene = Json(); }, Outcome::Error,
       "scene.json", "not valid JSON"},
      {"UnknownKey", Api::Scene, "", [](Input& in) { in.muscle()["resolutoin"] = 20; },
       Outcome::Error, "resolutoin", "unknown field"},
      {"WrongType", Api::Scene, "", [](Input& in) { in.muscle()["resolution"] = "forty"; },
       Outcome::Error, "muscles[0].resolution", "forty"},
      {"NegativeTimeStep", Api::Scene, "",
       [](Input& in) {
         in.scene["simulation"] = {{"dt", -0.001}};
       },
       Outcome::Error, "simulation.dt", "expected a number > 0"},
      {"ZeroTimeStep", Api::Scene, "",
       [](Input& in) {
         in.scene["simulation"] = {{"dt", 0}};
       },
       Outcome::Error, "simulation.dt", "expected a number > 0"},
      {"ZeroMass", Api::Scene, "",
       [](Input& in) {
         in.scene["model"] = {{"density", 0}};
       },
       Outcome::Error, "model.density", "expected a number > 0"},
      {"NegativeStiffness", Api::Scene, "",
       [](Input& in) {
         in.scene["model"] = {{"kappa", -5}};
       },
       Outcome::Error, "model.kappa", "expected a number > 0"},
      {"ZeroResolution", Api::Scene, "", [](Input& in) { in.muscle()["resolution"] = 0; },
       Outcome::Error, "muscles[0].resolution", "expected an integer in [2,"},
      {"NeighboursAboveParticleCount", Api::Scene, "",
       [](Input& in) {
         in.scene["model"] = {{"neighbours", 500}};
       },
       Outcome::Error, "springs.neighbours", "particle count"},
  };
}

/// Scene values out of their range: sizes, transforms, names, seeds.
std::vector<BadInput> sceneValueRows() {
  return {
      {"AbsurdSize", Api::Scene, "",
       [](Input& in) {
         // 1000 fibres x 100000 particles = 10^8 particles.
         in.files["fibres.obj"] = fibresObj(1000);
         in.muscle()["fibre_count"] = 1000;
         in.muscle()["resolution"] = 100000;
       },
       Outcome::Error, "scene", "would need about", "4096"},
      {"ScaledQuaternion", Api::Scene, "",
       [](Input& in) {
         in.bone()["transform"] = {{"quaternion", {0, 0, 0, 2}}};
       },
       Outcome::Error, "bones[0].transform.quaternion", "not rigid"},
      {"ScaledKeyframe", Api::Scene, "",
       [](Input& in) {
         in.bone()["motion"] = {
             {"type", "keyframes"},
             {"keyframes", {{{"translation", {0, 0, 0}}}, {{"quaternion", {0, 0.5, 0, 0.5}}}}}};
       },
       Outcome::Error, "bones[0].motion.keyframes[1].quaternion", "not rigid"},
      {"ShearMatrixTransform", Api::Scene, "",
       [](Input& in) {
         in.bone()["transform"] = {{"matrix", {{1, 0.5, 0}, {0, 1, 0}, {0, 0, 1}}}};
       },
       Outcome::Error, "bones[0].transform.matrix", "rigidly"},
      {"DuplicateBoneName", Api::Scene, "",
       [](Input& in) { in.scene["bones"].push_back(in.bone()); }, Outcome::Error, "bones[1].name",
       "another bone"},
      {"ZeroSweepStep", Api::Scene, "",
       [](Input& in) {
         in.bone()["motion"] = {{"type", "sweep"}, {"step_deg", 0}};
       },
       Outcome::Error, "bones[0].motion.step_deg", "expected a number in (0,"},
      {"UnknownUnits", Api::Scene, "", [](Input& in) { in.scene["units"] = "inches"; },
       Outcome::Error, "units", "inches"},
      {"NegativeSeed", Api::Scene, "",
       [](Input& in) {
         in.scene["simulation"] = {{"seed", -1}};
       },
       Outcome::Error, "simulation.seed", "expected an integer in [0, 4294967295]"},
  };
}

const std::vector<BadInput>& catalogue() {
  static const std::vector<BadInput> rows = [] {
    std::vector<BadInput> all;
    for (auto part : {surfaceReadRows, surfaceShapeRows, fibreRows, sceneFieldRows, sceneValueRows})
      for (BadInput& row : part()) all.push_back(std::move(row));
    return all;
  }();
  return rows;
}

/// Sets an environment variable for one scope.
class ScopedEnvironment {
 public:
  ScopedEnvironment(const char* name, const std::string& value) : name_(name) {
    if (!value.empty()) ::setenv(name, value.c_str(), 1);
  }
  ~ScopedEnvironment() { ::unsetenv(name_); }
  ScopedEnvironment(const ScopedEnvironment&) = delete;
  ScopedEnvironment& operator=(const ScopedEnvironment&) = delete;

 private:
  const char* name_;
};

class BadInputTest : public ::testing::TestWithParam<BadInput> {};

TEST_P(BadInputTest, IsRejectedOrReported) {
  const BadInput& row = GetParam();
  testing::TemporaryDirectory directory("fibremss_bad_input_" + row.name);
  Input input;
  row.spoil(input);
  for (const auto& [name, content] : input.files)
    std::ofstream(directory.path() / name, std::ios::binary) << content;
  const fs::path scene = directory.path() / "scene.json";
  std::ofstream(scene) << (input.scene.is_null() ? std::string("{\"bones\": [")
                                                 : input.scene.dump(2));
  ScopedEnvironment limit("FIBREMSS_MEMORY_LIMIT_MB", row.memoryLimitMb);

  // In-process, through the public API.
  std::string message;
  std::vector<std::string> warnings;
  try {
    if (row.api == Api::Surface) {
      MeshReport report;
      loadSurface((directory.path() / row.file).string(), 1e-3, &report);
      warnings = report.warnings;
    } else if (row.api == Api::Fibres) {
      loadFibres((directory.path() / row.file).string(), 1e-3);
    } else {
      const LoadedScene loaded = loadScene(scene.string());
      const PreparedScene prepared =
          prepareScene(loaded.bones, loaded.muscles, loaded.simulation.seed);
      warnings = loaded.warnings;
      warnings.insert(warnings.end(), prepared.report.warnings.begin(),
                      prepared.report.warnings.end());
    }
  } catch (const InputError& e) {
    message = e.what();
  }
  std::string allWarnings;
  for (const auto& warning : warnings) allWarnings += warning + "\n";
  if (row.outcome == Outcome::Error) {
    ASSERT_FALSE(message.empty()) << "no InputError; warnings:\n" << allWarnings;
    EXPECT_NE(message.find(row.source), std::string::npos) << message;
    EXPECT_NE(message.find(row.phrase), std::string::npos) << message;
  } else {
    ASSERT_TRUE(message.empty()) << message;
    EXPECT_NE(allWarnings.find(row.source), std::string::npos) << allWarnings;
    EXPECT_NE(allWarnings.find(row.phrase), std::string::npos) << allWarnings;
  }

  // The command line: exit code, message, and nothing written on failure.
  const fs::path out = directory.path() / "out";
  const testing::ProcessResult check = testing::runProcess(
      std::string(FIBREMSS_CLI) + " check " + scene.string() + " --out " + out.string() + " 2>&1");
  if (row.outcome == Outcome::Error) {
    EXPECT_EQ(check.exitCode, 2) << check.output;
    EXPECT_NE(check.output.find("error: "), std::string::npos) << check.output;
    EXPECT_NE(check.output.find(row.phrase), std::string::npos) << check.output;
    EXPECT_TRUE(!fs::exists(out) || fs::is_empty(out)) << "files written to " << out;
  } else {
    EXPECT_EQ(check.exitCode, 0) << check.output;
    EXPECT_NE(check.output.find("warning: "), std::string::npos) << check.output;
    EXPECT_NE(check.output.find(row.phrase), std::string::npos) << check.output;
    EXPECT_TRUE(fs::exists(out / "rest.pvd")) << check.output;
  }
}

INSTANTIATE_TEST_SUITE_P(Catalogue, BadInputTest, ::testing::ValuesIn(catalogue()),
                         [](const auto& test) { return test.param.name; });

TEST(BadInputCatalogue, HasAtLeastTwentyFiveClasses) {
  EXPECT_GE(catalogue().size(), 25u);
}

TEST(ResourceEstimate, GrowsWithTheParticleCount) {
  MuscleInput muscle;
  muscle.fibres.addFibre(std::vector<btVector3>{{0, 0, 0}, {0, 1, 0}});
  muscle.parameters.resolution = 10;
  const size_t small = estimatePreparationBytes({}, {muscle});
  muscle.parameters.resolution = 1000;
  const size_t large = estimatePreparationBytes({}, {muscle});
  EXPECT_GT(small, 0u);
  // Particle memory dominates, so 100 times the particles is nearly 100 times the bytes.
  EXPECT_GT(large, 50 * small);
  EXPECT_EQ(estimatePreparationBytes({}, {muscle, muscle}), 2 * large);
}

TEST(ResourceEstimate, LimitComesFromTheEnvironmentOrAvailableMemory) {
  {
    ScopedEnvironment limit("FIBREMSS_MEMORY_LIMIT_MB", "123");
    EXPECT_EQ(preparationMemoryLimit(), size_t(123) * 1024 * 1024);
  }
  ::unsetenv("FIBREMSS_MEMORY_LIMIT_MB");
  EXPECT_GT(preparationMemoryLimit(), size_t(0));
}

TEST(ResourceEstimate, RefusesBeforeAllocating) {
  // 10^6 fibres x 10^5 particles: far beyond any machine; refused before anything is made.
  MuscleInput muscle;
  muscle.name = "huge";
  for (int f = 0; f < 1000; ++f)
    muscle.fibres.addFibre(std::vector<btVector3>{{btScalar(f), 0, 0}, {btScalar(f), 1, 0}});
  muscle.parameters.resolution = 100000000;
  ScopedEnvironment limit("FIBREMSS_MEMORY_LIMIT_MB", "1024");
  try {
    prepareScene({}, {muscle}, 1);
    FAIL() << "no InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("100000000000 particles"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("limit is 1024 MiB"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace fibremss
