// The CalculiX reference's parts: tetgen meshes, the .inp writer, the .dat reader (on real ccx
// runs of a bar under tension against its closed-form answer), the cache key and store, and
// the gates.
#include "fibremss/Calculix.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <thread>

#include "fibremss/Analytic.h"
#include "fibremss/Compare.h"
#include "fibremss/Error.h"
#include "fibremss/Measures.h"
#include "fibremss/Reference.h"
#include "fibremss/ReferenceCache.h"
#include "support/PrepFixtures.h"
#include "support/Process.h"

namespace fibremss {
namespace {

using testing::TemporaryDirectory;

bool onPath(const char* program) {
  return testing::runProcess(std::string("command -v ") + program + " >/dev/null").exitCode == 0;
}

#define REQUIRE_PROGRAM(program)                                                                \
  if (!onPath(program))                                                                         \
  GTEST_SKIP() << program << " is not installed (Debian: apt-get install "                      \
               << (std::string(program) == "ccx" ? "calculix-ccx" : program) << "; ./setup.sh " \
               << "installs it)"

/// A 10 × 10 × 40 mm bar along z, its box surface split twice (vertices on every face).
TriangleMesh barSurface() {
  return subdivided(testing::boxMesh(btVector3(0, 0, 0), btVector3(0.01f, 0.01f, 0.04f)), 2);
}

TEST(Tetgen, KeepsTheSurfaceVerticesAsTheFirstNodesAndFillsTheVolume) {
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("tetgen_test");
  const TriangleMesh surface = testing::sphereMesh(btVector3(0, 0, 0), 0.02f, 2);
  const TetMesh mesh = tetgenMesh(surface, {}, dir.path().string(), "sphere");
  ASSERT_GE(mesh.nodes.size(), surface.vertices.size());
  for (size_t v = 0; v < surface.vertices.size(); ++v)
    EXPECT_EQ(mesh.nodes[v], surface.vertices[v]);
  for (const auto& t : mesh.tetrahedra)
    ASSERT_GT(
        tetrahedronVolume(mesh.nodes[t[0]], mesh.nodes[t[1]], mesh.nodes[t[2]], mesh.nodes[t[3]]),
        0);
  EXPECT_NEAR(totalVolume(mesh), meshVolume(surface), 1e-6 * meshVolume(surface));
}

TEST(Tetgen, RefinementSplitsTheSurfaceAndShrinksTheTetrahedra) {
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("tetgen_refine_test");
  const TriangleMesh surface = testing::sphereMesh(btVector3(0, 0, 0), 0.02f, 2);
  const TetMesh coarse = tetgenMesh(surface, {}, dir.path().string(), "coarse");
  const TetMesh fine = tetgenMesh(surface, {.refinement = 1}, dir.path().string(), "fine");
  EXPECT_GT(fine.tetrahedra.size(), 4 * coarse.tetrahedra.size());
  const TriangleMesh split = subdivided(surface, 1);
  EXPECT_EQ(split.triangles.size(), 4 * surface.triangles.size());
  for (size_t v = 0; v < split.vertices.size(); ++v) EXPECT_EQ(fine.nodes[v], split.vertices[v]);
  EXPECT_NEAR(totalVolume(fine), meshVolume(surface), 1e-6 * meshVolume(surface));
}

TEST(Tetgen, ReportsAnOpenSurfaceAsInputError) {
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("tetgen_bad_test");
  TriangleMesh open = testing::boxMesh(btVector3(0, 0, 0), btVector3(1, 1, 1));
  open.triangles.pop_back();
  open.triangles.push_back({0, 0, 1});  // degenerate facet
  EXPECT_THROW(tetgenMesh(open, {}, dir.path().string(), "open"), InputError);
}

TEST(CalculixInput, WritesEveryNodeElementSetAndStep) {
  CalculixJob job;
  job.title = "one tetrahedron";
  job.nodes = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  job.connectivity = {0, 1, 2, 3};
  job.material = {.youngsModulus = 1000, .poissonRatio = 0.25};
  job.prescribed = {0, 1, 2};
  job.steps = {{{0, 0, 0}, {0.1f, 0, 0}, {0, 0, 0}}, {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}}};
  job.printed = {3};
  std::ostringstream out;
  writeCalculixInput(out, job);
  const std::string text = out.str();
  std::istringstream lines(text);
  std::string line;
  int steps = 0, boundaries = 0;
  bool material = false;
  std::string previous;
  while (std::getline(lines, line)) {
    steps += line.rfind("*STEP, NLGEOM", 0) == 0;
    if (previous == "*HYPERELASTIC, NEO HOOKE") {
      double c10 = 0, d1 = 0;
      char comma = 0;
      std::istringstream(line) >> c10 >> comma >> d1;
      EXPECT_NEAR(c10, 1000 / (4 * 1.25), 1e-6);  // μ/2
      EXPECT_NEAR(d1, 6 * 0.5 / 1000, 1e-9);      // 2/K
      material = true;
    }
    boundaries += line == "2, 1, 1, 0.100000001" || line == "2, 1, 1, 0.1";
    previous = line;
  }
  EXPECT_EQ(steps, 2);
  EXPECT_TRUE(material);
  EXPECT_EQ(boundaries, 1) << text;
  EXPECT_NE(text.find("*ELEMENT, TYPE=C3D4, ELSET=EALL\n1, 1, 2, 3, 4\n"), std::string::npos);
  EXPECT_NE(text.find("*NSET, NSET=NPRINT\n4\n"), std::string::npos);
}

TEST(CalculixInput, QuadraticTetrahedraShareTheirMidsideNodes) {
  TetMesh mesh;
  mesh.nodes = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 1}};
  mesh.tetrahedra = {{0, 1, 2, 3}, {1, 2, 3, 4}};
  std::vector<uint32_t> connectivity;
  const std::vector<btVector3> nodes = quadraticTetrahedra(mesh, connectivity);
  EXPECT_EQ(nodes.size(), 5u + 9u);  // 6 + 6 edges, 3 shared (the face 1-2-3)
  ASSERT_EQ(connectivity.size(), 20u);
  EXPECT_EQ(nodes[connectivity[4]], btVector3(0.5f, 0, 0));     // edge 1-2 of the first
  EXPECT_EQ(nodes[connectivity[9]], btVector3(0, 0.5f, 0.5f));  // edge 3-4 of the first
  EXPECT_EQ(connectivity[9], connectivity[10 + 5])
      << "edge 2-3 of the first is edge 2-3 of the second";
}

TEST(CalculixInput, BoundaryFacesAreTheFacesNoOtherTetrahedronShares) {
  // Two tetrahedra sharing the face {1, 2, 3}: 8 faces, 6 on the boundary.
  const std::vector<uint32_t> tetrahedra = {0, 1, 2, 3, 4, 2, 1, 3};
  const auto faces = boundaryFaces(tetrahedra);
  ASSERT_EQ(faces.size(), 6u);
  // CalculiX's C3D4 face k by local corners: 1: 1-2-3, 2: 1-4-2, 3: 2-4-3, 4: 3-4-1.
  constexpr int kCorners[4][3] = {{0, 1, 2}, {0, 3, 1}, {1, 3, 2}, {2, 3, 0}};
  for (const auto& [element, face] : faces) {
    std::set<uint32_t> corners;
    for (int k : kCorners[face - 1]) corners.insert(tetrahedra[element * 4 + k]);
    EXPECT_NE(corners, (std::set<uint32_t>{1, 2, 3})) << "the shared face is inside";
  }
}

TEST(CalculixInput, WritesTheObstaclesAndTheirContactOnlyWithAStiffness) {
  CalculixJob job;
  job.nodes = {{0, 0, 0},  {1, 0, 0},  {0, 1, 0},  {0, 0, 1},
               {0, 0, -1}, {1, 0, -1}, {0, 1, -1}, {0, 0, -2}};
  job.connectivity = {0, 1, 2, 3};
  job.prescribed = {4, 5, 6, 7};
  job.steps = {{{0, 0, 0}, {0, 0, 0}, {0, 0, 0}, {0, 0, 0}}};
  job.contact.tetrahedra = {4, 5, 6, 7};
  job.contact.faces = boundaryFaces(job.contact.tetrahedra);
  job.contact.slaves = {0, 1, 2};
  std::ostringstream without;
  writeCalculixInput(without, job);
  EXPECT_EQ(without.str().find("*CONTACT PAIR"), std::string::npos) << "stiffness 0: none";
  job.contact.stiffness = 1e7;
  job.contact.tension = 5;
  std::ostringstream with;
  writeCalculixInput(with, job);
  const std::string text = with.str();
  EXPECT_NE(text.find("*ELEMENT, TYPE=C3D4, ELSET=EBONE\n2, 5, 6, 7, 8\n"), std::string::npos)
      << text;
  EXPECT_NE(text.find("*SURFACE, NAME=SBONE, TYPE=ELEMENT\n2, S1\n2, S2\n2, S3\n2, S4\n"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("*NSET, NSET=NSLAVE\n1, 2, 3\n"), std::string::npos) << text;
  EXPECT_NE(text.find("PRESSURE-OVERCLOSURE=LINEAR\n10000000, 5\n"), std::string::npos) << text;
  EXPECT_NE(text.find("*CONTACT PAIR, INTERACTION=FRICTIONLESS, TYPE=NODE TO SURFACE\n"
                      "SMUSCLE, SBONE\n"),
            std::string::npos)
      << text;
  EXPECT_LT(text.find("*CONTACT PAIR"), text.find("*STEP")) << "model data before the steps";
  job.contact.sliding = ContactSliding::Small;
  std::ostringstream small;
  writeCalculixInput(small, job);
  EXPECT_NE(small.str().find("*CONTACT PAIR, INTERACTION=FRICTIONLESS, TYPE=NODE TO SURFACE, "
                             "SMALL SLIDING\nSMUSCLE, SBONE\n"),
            std::string::npos)
      << small.str();
}

TEST(CalculixInput, WritesEachEquationsLargestTermFirstBeforeTheSteps) {
  CalculixJob job;
  job.nodes = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  job.connectivity = {0, 1, 2, 3};
  job.prescribed = {0};
  job.steps = {{{0, 0, 0}}};
  job.equations = {{3, btVector3(0.6f, 0, -0.8f)}, {1, btVector3(0, 1, 0)}};
  std::ostringstream out;
  writeCalculixInput(out, job);
  const std::string text = out.str();
  // CalculiX eliminates the first term's degree of freedom: never a zero or small coefficient.
  EXPECT_NE(text.find("*EQUATION\n2\n4, 3, -0.800000012, 4, 1, 0.600000024\n"), std::string::npos)
      << text;
  EXPECT_NE(text.find("*EQUATION\n1\n2, 2, 1\n"), std::string::npos) << text;
  EXPECT_LT(text.find("*EQUATION"), text.find("*STEP")) << "model data before the steps";
}

TEST(CalculixDat, ReadsTablesRowsAndTotals) {
  std::istringstream dat(
      "\n displacements (vx,vy,vz) for set NPRINT and time  0.5000000E+00\n\n"
      "         4  1.000000E-02 -2.000000E-03  0.000000E+00\n"
      "         7 -1.5E-02  0.0E+00  3.0E-03\n\n"
      " total force (fx,fy,fz) for set TOP and time  0.1000000E+01\n\n"
      "        4.068957E-14 -2.617206E-14  2.763250E+02\n"
      "\n displacements (vx,vy,vz) for set NPRINT and time  0.1000000E+01\n\n"
      "         4  2.000000E-02  0.0E+00  0.0E+00\n");
  const auto tables = readCalculixDat(dat, "test.dat");
  ASSERT_EQ(tables.size(), 3u);
  EXPECT_EQ(tables[0].quantity, "displacements");
  EXPECT_EQ(tables[0].set, "NPRINT");
  EXPECT_DOUBLE_EQ(tables[0].time, 0.5);
  EXPECT_EQ(tables[0].ids, (std::vector<int>{4, 7}));
  EXPECT_DOUBLE_EQ(tables[0].values[4], 0.0);
  EXPECT_DOUBLE_EQ(tables[0].values[3], -0.015);
  EXPECT_TRUE(tables[1].ids.empty());
  EXPECT_DOUBLE_EQ(tables[1].values[2], 276.325);
  const auto ends = stepEndTables(tables, "displacements", "NPRINT", 3);
  ASSERT_EQ(ends.size(), 1u) << "step 1 ends at time 1; steps 2 and 3 were never printed";
  EXPECT_EQ(ends[0], &tables[2]);
}

TEST(CalculixDat, NamesTheLineOfARowThatIsNotNumbers) {
  std::istringstream dat(" displacements (vx,vy,vz) for set N and time 1.\n 4 1.0 x 2.0\n");
  try {
    readCalculixDat(dat, "bad.dat");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.where(), "line 2");
  }
}

/// Writes `job` as DIR/bar.inp, runs ccx on it (expecting success) and returns the tables of
/// its .dat.
std::vector<CalculixTable> solveBar(const std::filesystem::path& dir, const CalculixJob& job) {
  {
    std::ofstream out(dir / "bar.inp");
    writeCalculixInput(out, job);
  }
  EXPECT_EQ(runProgram({"ccx", "-i", "bar"}, dir.string(), (dir / "ccx.log").string()), 0);
  std::ifstream dat(dir / "bar.dat");
  return readCalculixDat(dat, "bar.dat");
}

/// The Neo-Hookean bar's lateral stretch under an axial stretch λ with free sides (σ_lateral = 0
/// for W = C10(Ī1−3) + (J−1)²/D1), by bisection.
double lateralStretch(const NeoHookeMaterial& material, double lambda) {
  auto lateralStress = [&](double mu) {
    const double j = lambda * mu * mu;
    const double deviatoric = 2 * material.c10() / j * std::pow(j, -2.0 / 3.0) *
                              (mu * mu - (lambda * lambda + 2 * mu * mu) / 3);
    return deviatoric + 2 / material.d1() * (j - 1);
  };
  double low = 0.5, high = 1.0;
  for (int i = 0; i < 60; ++i)
    ((lateralStress(0.5 * (low + high)) > 0) ? high : low) = 0.5 * (low + high);
  return 0.5 * (low + high);
}

/// The job's nodes and elements on `mesh`: its tetrahedra as C3D4, or made quadratic (C3D10).
void setBarElements(CalculixJob& job, const TetMesh& mesh, CalculixElement element) {
  job.element = element;
  if (element == CalculixElement::C3D10) {
    job.nodes = quadraticTetrahedra(mesh, job.connectivity);
    return;
  }
  job.nodes = mesh.nodes;
  for (const auto& t : mesh.tetrahedra)
    job.connectivity.insert(job.connectivity.end(), t.begin(), t.end());
}

/// The bar stretched 10 % along z by its end faces, moved as the homogeneous closed-form
/// answer; then back to rest. Its free surface nodes must follow that answer.
void expectClosedFormBar(CalculixElement element) {
  TemporaryDirectory dir(std::string("ccx_bar_test_") + toString(element));
  const TriangleMesh surface = barSurface();
  const TetMesh mesh = tetgenMesh(surface, {}, dir.path().string(), "bar");
  CalculixJob job;
  job.title = "bar under tension";
  job.element = element;
  job.material = {.youngsModulus = 100e3, .poissonRatio = 0.3};
  setBarElements(job, mesh, element);
  const double lambda = 1.1, mu = lateralStretch(job.material, lambda);
  ASSERT_LT(mu, 0.98) << "ν = 0.3 narrows the bar";
  const auto exact = [&](const btVector3& x) {
    return btVector3(btScalar((x.x() - 0.005) * (mu - 1)), btScalar((x.y() - 0.005) * (mu - 1)),
                     btScalar(x.z() * (lambda - 1)));
  };
  job.steps.resize(2);
  for (uint32_t n = 0; n < job.nodes.size(); ++n) {
    const btScalar z = job.nodes[n].z();
    if (z < 1e-7f || z > 0.04f - 1e-7f) {
      job.prescribed.push_back(n);
      job.steps[0].push_back(exact(job.nodes[n]));
      job.steps[1].push_back(btVector3(0, 0, 0));
    } else if (n < surface.vertices.size()) {
      job.printed.push_back(n);
    }
  }
  ASSERT_GT(job.printed.size(), 20u);
  const auto tables = solveBar(dir.path(), job);
  const auto ends = stepEndTables(tables, "displacements", "NPRINT", 2);
  ASSERT_EQ(ends.size(), 2u);
  double worst = 0, back = 0;
  for (size_t row = 0; row < ends[0]->ids.size(); ++row) {
    const btVector3 expected = exact(job.nodes[static_cast<size_t>(ends[0]->ids[row] - 1)]);
    const double* u = &ends[0]->values[row * 3];
    worst =
        std::max(worst, std::hypot(u[0] - expected.x(), u[1] - expected.y(), u[2] - expected.z()));
    const double* r = &ends[1]->values[row * 3];
    back = std::max(back, std::hypot(r[0], r[1], r[2]));
  }
  // The side moves by (1 − μ) × 5 mm ≈ 0.2 mm; the closed form within 1 µm.
  EXPECT_LT(worst, 1e-6) << toString(element) << ": lateral stretch " << mu;
  EXPECT_LT(back, 1e-7) << "back at rest";
}

TEST(CalculixRun, BarUnderTensionMatchesTheClosedFormNeoHookeanAnswerC3D4) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  expectClosedFormBar(CalculixElement::C3D4);
}

TEST(CalculixRun, BarUnderTensionMatchesTheClosedFormNeoHookeanAnswerC3D10) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  expectClosedFormBar(CalculixElement::C3D10);
}

/// A plate whose top is 1 mm below the bar and a second, thicker one lower down that cuts
/// into it from the side: one surface that intersects itself, as thigh13's pelvis does.
TriangleMesh overlappingPlates() {
  TriangleMesh plates = subdivided(
      testing::boxMesh(btVector3(-0.005f, -0.005f, -0.006f), btVector3(0.015f, 0.015f, -0.001f)),
      2);
  const TriangleMesh lower =
      testing::boxMesh(btVector3(0.01f, -0.01f, -0.012f), btVector3(0.03f, 0.02f, -0.003f));
  const auto first = static_cast<uint32_t>(plates.vertices.size());
  plates.vertices.insert(plates.vertices.end(), lower.vertices.begin(), lower.vertices.end());
  for (const auto& t : lower.triangles)
    plates.triangles.push_back({first + t[0], first + t[1], first + t[2]});
  return plates;
}

TEST(CalculixInput, AnObstacleMeshFacesOutWithPositiveTetrahedraEvenWhereTetgenRefuses) {
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("obstacle_test");
  TriangleMesh plates = overlappingPlates();
  EXPECT_THROW(tetgenMesh(plates, {}, dir.path().string(), "plates"), InputError)
      << "tetgen refuses a surface that intersects itself";
  for (const bool reversed : {false, true}) {
    if (reversed)
      for (auto& t : plates.triangles) std::swap(t[1], t[2]);
    const ObstacleMesh mesh = obstacleMesh(plates);
    ASSERT_EQ(mesh.faces.size(), plates.triangles.size());
    ASSERT_EQ(mesh.tetrahedra.size(), 4 * plates.triangles.size());
    for (size_t f = 0; f < mesh.faces.size(); ++f) {
      const auto [element, face] = mesh.faces[f];
      EXPECT_EQ(face, 1) << "face 1: corners 1-2-3";
      const uint32_t* t = &mesh.tetrahedra[4 * element];
      const btVector3 &a = mesh.nodes[t[0]], &b = mesh.nodes[t[1]], &c = mesh.nodes[t[2]];
      const btVector3 inward = (b - a).cross(c - a);
      EXPECT_GT(inward.dot(mesh.nodes[t[3]] - a), 0) << "a C3D4 of positive volume";
      // The triangle's outward normal (its own winding, flipped back when reversed).
      const auto& tri = plates.triangles[f];
      const btVector3 normal = (plates.vertices[tri[1]] - plates.vertices[tri[0]])
                                   .cross(plates.vertices[tri[2]] - plates.vertices[tri[0]]);
      EXPECT_LT(inward.dot(reversed ? -normal : normal), 0) << "face 1 faces out";
    }
  }
}

/// The bar pushed 3 mm down by its top face onto a rigid plate 1 mm below it: with contact its
/// bottom face stops on the plate (within the penalty's overclosure), without it passes 2 mm in.
/// Returns the lowest of the bottom face's nodes (midside nodes of C3D10 included) [mm].
double lowestBottomNodeMm(double contactStiffness,
                          CalculixElement element = CalculixElement::C3D4) {
  TemporaryDirectory dir(std::string("ccx_contact_test_") + toString(element));
  const TriangleMesh surface = barSurface();
  const TetMesh bar = tetgenMesh(surface, {}, dir.path().string(), "bar");
  const ObstacleMesh plate = obstacleMesh(overlappingPlates());
  CalculixJob job;
  job.title = "bar pushed onto a plate";
  job.material = {.youngsModulus = 100e3, .poissonRatio = 0.3};
  setBarElements(job, bar, element);
  job.steps.resize(1);
  for (uint32_t n = 0; n < job.nodes.size(); ++n) {
    if (job.nodes[n].z() > 0.04f - 1e-7f) {
      job.prescribed.push_back(n);
      job.steps[0].push_back(btVector3(0, 0, -0.003f));
    }
  }
  for (uint32_t n : surfaceNodes(job, surface.vertices.size())) {
    if (job.nodes[n].z() > 0.04f - 1e-7f) continue;
    job.contact.slaves.push_back(n);
    if (job.nodes[n].z() < 1e-7f) job.printed.push_back(n);
  }
  const auto first = static_cast<uint32_t>(job.nodes.size());
  for (const btVector3& x : plate.nodes) {
    job.prescribed.push_back(static_cast<uint32_t>(job.nodes.size()));
    job.steps[0].push_back(btVector3(0, 0, 0));
    job.nodes.push_back(x);
  }
  for (uint32_t corner : plate.tetrahedra) job.contact.tetrahedra.push_back(first + corner);
  job.contact.faces = plate.faces;
  job.contact.stiffness = contactStiffness;
  job.contact.tension = 1e-3 * job.material.youngsModulus;
  job.initialIncrement = 0.25;
  const auto tables = solveBar(dir.path(), job);
  const auto ends = stepEndTables(tables, "displacements", "NPRINT", 1);
  if (ends.size() != 1) return NAN;
  double lowest = INFINITY;
  for (size_t row = 0; row < ends[0]->ids.size(); ++row)
    lowest = std::min(lowest, 1e3 * (job.nodes[size_t(ends[0]->ids[row] - 1)].z() +
                                     ends[0]->values[row * 3 + 2]));
  return lowest;
}

TEST(CalculixRun, ABarPushedOntoARigidPlateStopsOnItOnlyWithContact) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  EXPECT_NEAR(lowestBottomNodeMm(0), -3, 1e-3) << "no contact: it passes through";
  // K = 5e4 × E as the reference uses: ~5 kPa of contact pressure overcloses ~1 µm.
  const double lowest = lowestBottomNodeMm(5e4 * 100e3);
  EXPECT_GT(lowest, -1.01) << "stops on the plate's top at z = -1 mm";
  EXPECT_LT(lowest, -0.99) << "and touches it";
}

TEST(CalculixRun, AQuadraticBarPushedOntoARigidPlateKeepsEveryNodeOnIt) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  const double lowest = lowestBottomNodeMm(5e4 * 100e3, CalculixElement::C3D10);
  EXPECT_GT(lowest, -1.001) << "no node of the bottom face, midside nodes included, in the plate";
  EXPECT_LT(lowest, -0.999) << "and touches it";
}

TEST(ReferenceGates, PassOnlyWithinTheirBoundsAndEveryPoseSolved) {
  ReferenceGates gates;
  EXPECT_FALSE(gates.passed()) << "nothing computed";
  gates.returnMm = 0.4;
  gates.refinementMm = 0.1;
  gates.incrementsMm = 0.1;
  gates.spreadMm = 0.6;
  EXPECT_TRUE(gates.passed());
  gates.spreadMm = 0.3;  // a third is 0.1: not below it
  EXPECT_FALSE(gates.refinementPasses());
  gates.spreadMm = 0.6;
  gates.returnMm = 0.51;
  EXPECT_FALSE(gates.returnPasses());
  gates.returnMm = 0.4;
  gates.failures = "reference pose 3: no convergence";
  EXPECT_FALSE(gates.passed());
  // pinch's C3D10 solve stopped in pose 1: its 0 mm over the rest pose alone is no pass.
  gates.failures.clear();
  gates.solvedPoses = gates.incrementsPoses = 2;
  gates.refinementPoses = 1;
  gates.refinementMm = 0;
  EXPECT_FALSE(gates.refinementPasses());
  EXPECT_NE(gateLines(gates)[1].find("FAILS (over fewer poses than the reference solved)"),
            std::string::npos)
      << gateLines(gates)[1];
  gates.refinementPoses = 2;
  EXPECT_TRUE(gates.passed());
}

TEST(ReferenceGates, LinesSayWhatWasNotComputedAndOverHowManyPoses) {
  ReferenceGates gates;
  gates.spreadMm = 0.6;
  gates.poses = 7;
  std::vector<std::string> lines = gateLines(gates);
  ASSERT_GE(lines.size(), 3u);
  EXPECT_NE(lines[1].find("not computed"), std::string::npos) << lines[1];
  EXPECT_EQ(lines[1].find("FAILS"), std::string::npos) << "no verdict on what was not solved";
  EXPECT_NE(lines[2].find("increments halved (\u2014): moves it \u2014 RMS: not computed"),
            std::string::npos)
      << lines[2];
  gates.refinementMm = 0.1;
  gates.refinementPoses = 2;
  gates.attachmentLowMm = gates.attachmentHighMm = 0.2;
  gates.attachmentLowPoses = gates.attachmentHighPoses = 7;
  lines = gateLines(gates);
  EXPECT_NE(lines[1].find("over 2/7 poses"), std::string::npos) << lines[1];
  EXPECT_NE(lines[1].find("passes"), std::string::npos) << lines[1];
  EXPECT_EQ(lines[3].find("poses"), std::string::npos) << "every pose compared: " << lines[3];
}

TEST(ReferenceGates, ExcludedPosesAreNoFailureButAGateThatFailsStillBlocks) {
  ReferenceGates gates;
  gates.returnMm = 0.1;
  gates.refinementMm = gates.incrementsMm = 0.1;
  gates.spreadMm = 0.6;
  gates.poses = 7;
  gates.refinementPoses = gates.incrementsPoses = gates.attachmentLowPoses =
      gates.attachmentHighPoses = 2;
  gates.excluded = "poses 2 to 6 of 7: no continuum equilibrium: the bones close across it";
  EXPECT_TRUE(gates.passed()) << "poses without a continuum equilibrium do not block the ranking";
  const std::vector<std::string> lines = gateLines(gates);
  const auto has = [&](const std::string& text) {
    return std::any_of(lines.begin(), lines.end(), [&](const std::string& line) {
      return line.find(text) != std::string::npos;
    });
  };
  EXPECT_TRUE(has("excluded, not ccx failures")) << lines.back();
  EXPECT_TRUE(has("no continuum equilibrium"));
  EXPECT_FALSE(has("ccx did not solve"));
  EXPECT_TRUE(has("over 2/7 poses")) << "the gates say what they covered";
  gates.refinementMm = 0.25;  // above a third of the spread: a gate that applies and fails
  EXPECT_FALSE(gates.passed());
  gates.refinementMm = 0.1;
  gates.failures = "reference pose 1: muscle m: *ERROR: increment size smaller than minimum";
  EXPECT_FALSE(gates.passed()) << "a pose ccx failed still blocks it";
  gates.failures.clear();

  // A return gate that cannot apply prints — with why and does not block; one that applies
  // and was not computed still does.
  gates.returnMm = RunMetrics::kNone;
  EXPECT_FALSE(gates.passed());
  gates.returnNotApplicable = "the motion does not return to rest, and ccx did not solve it";
  EXPECT_TRUE(gates.passed());
  const std::string line = gateLines(gates).front();
  EXPECT_NE(line.find("\u2014 (does not apply, not blocking: the motion does not return"),
            std::string::npos)
      << line;
}

/// Gates of a reference that ccx stopped at pose `stop` of 19 after its retry, each computed
/// over the poses before it and passing.
ReferenceGates stoppedAt(int stop) {
  ReferenceGates gates;
  gates.returnNotApplicable = "ccx stopped the reference at pose " + std::to_string(stop);
  gates.refinementMm = gates.incrementsMm = 0.1;
  gates.spreadMm = 0.6;
  gates.poses = 19;
  gates.solvedPoses = gates.refinementPoses = gates.incrementsPoses = gates.attachmentLowPoses =
      gates.attachmentHighPoses = stop;
  gates.stopped = "muscle iliacus: *ERROR: increment size smaller than minimum";
  return gates;
}

TEST(ReferenceGates, WhereCcxStoppedTheReferenceTheyRankOverThePosesBeforeIt) {
  ReferenceGates gates = stoppedAt(6);
  EXPECT_TRUE(gates.passed()) << gates.whyNotPassed();
  EXPECT_FALSE(gates.failed());
  EXPECT_EQ(gates.rankedPoses(), 6);
  EXPECT_EQ(gates.rankedPosesText(),
            "ranked over poses 0\u20135 of 19: ccx did not solve pose 6 (muscle iliacus: *ERROR: "
            "increment size smaller than minimum) or later");
  const std::vector<std::string> lines = gateLines(gates);
  EXPECT_NE(lines.back().find("ccx stopped the reference at pose 6 of 19, after its retry"),
            std::string::npos)
      << lines.back();
  EXPECT_NE(lines.back().find("covers poses 0\u20135"), std::string::npos) << lines.back();
  EXPECT_NE(lines.front().find("does not apply, not blocking: ccx stopped"), std::string::npos)
      << lines.front();

  // A gate fails over those poses, or a gate's solve failed a pose the reference solved. The
  // verdict names each gate that fails, with its figure and bound.
  gates.refinementMm = 0.25;
  EXPECT_FALSE(gates.passed());
  EXPECT_EQ(gates.whyNotPassed(),
            "the reference fails a gate (one level finer 0.25 mm against a third of the methods' "
            "spread 0.2 mm)");
  gates.incrementsMm = 0.3;
  EXPECT_EQ(gates.whyNotPassed(),
            "the reference fails a gate (one level finer 0.25 mm against a third of the methods' "
            "spread 0.2 mm and increments halved 0.3 mm against a third of the methods' spread "
            "0.2 mm)");
  gates.incrementsMm = 0.1;
  EXPECT_EQ(gates.rankedPoses(), 0);
  EXPECT_EQ(gates.rankedPosesText(), "");
  gates.refinementMm = 0.1;
  gates.failures = "one level finer pose 4: muscle iliacus: *ERROR: too many cutbacks";
  EXPECT_FALSE(gates.passed());
  EXPECT_EQ(gates.whyNotPassed(), "ccx did not solve every pose the ranking needs");
  gates.failures.clear();
  gates.refinementPoses = 4;  // a finer solve over fewer poses than the reference solved
  EXPECT_FALSE(gates.passed());
  gates.refinementPoses = 6;

  // A stated gate's solve that ccx stopped early: its figure covers fewer poses, and it is said,
  // but the ranking does not wait on it.
  gates.statedFailures =
      "attachment distance x1.5 pose 2: muscle iliacus: *ERROR: increment "
      "size smaller than minimum";
  gates.attachmentHighPoses = 2;
  EXPECT_TRUE(gates.passed()) << gates.whyNotPassed();
  EXPECT_EQ(gates.rankedPoses(), 6);
  const std::vector<std::string> stated = gateLines(gates);
  EXPECT_TRUE(std::any_of(stated.begin(), stated.end(), [](const std::string& line) {
    return line.find("stated gates") != std::string::npos &&
           line.find("x1.5 pose 2") != std::string::npos;
  }));
  gates.statedFailures.clear();

  // Gates not computed: said so, not that ccx's stop blocks.
  gates.incrementsMm = RunMetrics::kNone;
  EXPECT_EQ(gates.whyNotPassed(), "the reference's gates were not computed");
}

TEST(ReferenceGates, AStopInTheFirstPosedPoseRanksNothing) {
  ReferenceGates gates = stoppedAt(2);
  EXPECT_TRUE(gates.passed()) << "the first pose and one after it: " << gates.whyNotPassed();
  gates = stoppedAt(1);
  EXPECT_FALSE(gates.passed());
  EXPECT_TRUE(gates.failed());
  EXPECT_EQ(gates.whyNotPassed(),
            "ccx stopped the reference at pose 1, before 2 poses to rank over");
  EXPECT_NE(gateLines(gates).back().find("too few poses to rank over, no ranking"),
            std::string::npos)
      << gateLines(gates).back();
  gates.incrementsMm = RunMetrics::kNone;
  EXPECT_EQ(gates.whyNotPassed(),
            "ccx stopped the reference at pose 1, before 2 poses to rank over; the reference's "
            "gates were not computed");
}

TEST(ReferenceGates, WhereAJudgedGatesSolveStoppedEarlierTheyRankOverThePosesItSolved) {
  ReferenceGates gates = stoppedAt(6);
  gates.refinementPoses = 2;  // one level finer: ccx did not solve pose 2
  EXPECT_FALSE(gates.passed()) << "a finer solve over the easy poses alone, not said";
  gates.gatedPoses = 2;
  gates.gateStop =
      "one level finer pose 2: muscle iliacus: *ERROR: increment size smaller than "
      "minimum";
  EXPECT_TRUE(gates.passed()) << gates.whyNotPassed();
  EXPECT_EQ(gates.rankedPoses(), 2);
  EXPECT_EQ(gates.rankedPosesText(),
            "ranked over poses 0\u20131 of 19: no judged gate covers pose 2 or later (ccx did not "
            "solve it in the one level finer pose 2: muscle iliacus: *ERROR: increment size "
            "smaller than minimum)");
  const std::vector<std::string> lines = gateLines(gates);
  EXPECT_NE(lines.back().find("covers poses 0\u20131"), std::string::npos) << lines.back();
  EXPECT_TRUE(std::none_of(lines.begin(), lines.end(), [](const std::string& line) {
    return line.find("covers poses 0\u20135") != std::string::npos;
  })) << "the reference's own stop no longer sets what the ranking covers";

  // The gate it stopped still has to pass over the poses it solved.
  gates.refinementMm = 0.25;
  EXPECT_FALSE(gates.passed());
  EXPECT_EQ(gates.whyNotPassed(),
            "the reference fails a gate (one level finer 0.25 mm against a third of the methods' "
            "spread 0.2 mm)");
  gates.refinementMm = 0.1;

  // Stopped in the first posed pose: nothing to rank over.
  gates.gatedPoses = gates.refinementPoses = 1;
  EXPECT_FALSE(gates.passed());
  EXPECT_TRUE(gates.failed());
  EXPECT_EQ(gates.whyNotPassed(),
            "ccx stopped a judged gate's solve at pose 1, before 2 poses to rank over");
}

TEST(ReferenceGates, AJudgedGatesStopOfOneMuscleLimitsThatMuscleAlone) {
  ReferenceGates gates = stoppedAt(6);
  gates.limited = {{1, "beside", 2, "increments halved",
                    "muscle beside: *ERROR: increment size smaller than minimum"}};
  EXPECT_TRUE(gates.passed()) << gates.whyNotPassed();
  EXPECT_EQ(gates.rankedPoses(), 6) << "the muscles not limited keep every gateable pose";
  EXPECT_EQ(gates.coveredPoses(0), 6);
  EXPECT_EQ(gates.coveredPoses(1), 2);
  const std::string limited =
      "beside over poses 0\u20131: ccx did not solve its pose 2 in the increments halved solve "
      "(muscle beside: *ERROR: increment size smaller than minimum)";
  EXPECT_EQ(gates.rankedPosesText(),
            "ranked over poses 0\u20135 of 19: ccx did not solve pose 6 (muscle iliacus: *ERROR: "
            "increment size smaller than minimum) or later; " +
                limited);
  const std::vector<std::string> lines = gateLines(gates);
  EXPECT_NE(lines.back().find("ranking follows): " + limited +
                              "; every other muscle over poses "
                              "0\u20135"),
            std::string::npos)
      << lines.back();

  // Over every pose of the motion, the limited muscle is still said.
  gates.poses = 6;
  EXPECT_EQ(gates.rankedPosesText(), "ranked over poses 0\u20135 of 6; " + limited);

  // Stopped in its first posed pose: left out of every figure, the others still ranked.
  gates.limited.front().poses = 1;
  EXPECT_EQ(gates.coveredPoses(1), 0);
  EXPECT_EQ(gates.rankedPoses(), 6);
  EXPECT_NE(gates.limitedText().find("beside left out of every figure (fewer than 2 poses): ccx "
                                     "did not solve its pose 1"),
            std::string::npos)
      << gates.limitedText();
}

TEST(ReferenceGates, IncrementsHalvedIsJudgedAsRefinementIsAndBlocksTheRanking) {
  // Every other gate passes: the increment gate alone decides.
  ReferenceGates gates;
  gates.returnMm = 0.01;
  gates.refinementMm = 0.05;
  gates.spreadMm = 0.9;  // a third: 0.3 mm
  gates.poses = gates.solvedPoses = gates.refinementPoses = 2;
  EXPECT_FALSE(gates.passed()) << "not computed: no ranking";
  EXPECT_NE(gateLines(gates)[2].find(": not computed"), std::string::npos) << gateLines(gates)[2];
  gates.incrementsMm = 0.277;  // pinch's pose 1, 0.25x against 0.0625x (measured)
  gates.incrementsScale = 0.125;
  gates.incrementsPoses = 2;
  EXPECT_TRUE(gates.incrementsPass());
  EXPECT_TRUE(gates.passed());
  EXPECT_EQ(gateLines(gates)[2],
            "increments halved (x0.125 of the default 2.5 deg / 1 mm): moves it 0.277 mm RMS "
            "against a third of the methods' spread 0.3 mm: passes");
  gates.incrementsMm = 0.3;  // not below a third of the spread
  EXPECT_FALSE(gates.incrementsPass());
  EXPECT_FALSE(gates.passed()) << "a failed increment gate blocks the ranking";
  EXPECT_NE(gateLines(gates)[2].find(": FAILS"), std::string::npos) << gateLines(gates)[2];
  gates.incrementsMm = 0;  // no change at all, but over the rest pose alone
  gates.incrementsPoses = 1;
  EXPECT_FALSE(gates.passed());
  EXPECT_NE(gateLines(gates)[2].find("FAILS (over fewer poses than the reference solved)"),
            std::string::npos)
      << gateLines(gates)[2];
  gates.spreadMm = RunMetrics::kNone;
  gates.incrementsPoses = 2;
  EXPECT_NE(gateLines(gates)[2].find("needs a comparison"), std::string::npos);
}

TEST(ReferenceCache, EachGatesKeyIsTheReferencesWithOneChangeAndNoReturnStep) {
  REQUIRE_PROGRAM("ccx");
  const LoadedScene scene = loadScene("fusiform", {"resolution=6", "fibre_count=8"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  const auto key = [&](const CalculixDefinition& d) {
    return referenceCacheKey(scene, prepared, d, {});
  };
  // At the default increments, and where the reference was solved only when retried finer.
  CalculixDefinition asked;
  asked.contactSliding = ContactSliding::Small;
  for (const double scale : {1.0, kFinerIncrements}) {
    SCOPED_TRACE(scale);
    CalculixDefinition reference = asked;
    reference.incrementScale = scale;
    const GateDefinitions gates = gateDefinitions(reference, asked, 0);
    // The gates solved before the increment gate existed are built as they were, so their
    // cache entries stay valid: the reference without its return step, one thing changed; the
    // finer one from the asked increments, not the retry's.
    CalculixDefinition low = reference;
    low.returnToRest = false;
    CalculixDefinition high = low, finer = low, increments = low;
    low.attachmentScale = 0.5f;
    high.attachmentScale = 1.5f;
    finer.element = CalculixElement::C3D10;
    finer.incrementScale = asked.incrementScale;
    increments.incrementScale = scale * kIncrementGateFactor;
    EXPECT_EQ(key(gates.attachmentLow), key(low));
    EXPECT_EQ(key(gates.attachmentHigh), key(high));
    EXPECT_EQ(key(gates.finer), key(finer));
    EXPECT_EQ(key(gates.increments), key(increments)) << "only its increments differ";
    const std::set<std::string> keys{key(reference), key(low), key(high), key(finer),
                                     key(increments)};
    EXPECT_EQ(keys.size(), 5u) << "five solves, five cache entries";
    // A reference ccx solved in part: each gate stops where it stopped, under a key of its own.
    const GateDefinitions limited = gateDefinitions(reference, asked, 2);
    const std::pair<const CalculixDefinition*, const CalculixDefinition*> pairs[] = {
        {&limited.attachmentLow, &gates.attachmentLow},
        {&limited.attachmentHigh, &gates.attachmentHigh},
        {&limited.increments, &gates.increments},
        {&limited.finer, &gates.finer}};
    for (const auto& [gate, unlimited] : pairs) {
      EXPECT_EQ(gate->poseLimit, 2);
      EXPECT_NE(key(*gate), key(*unlimited));
      CalculixDefinition every = *gate;
      every.poseLimit = 0;
      EXPECT_EQ(key(every), key(*unlimited)) << "only the limit differs";
    }
  }
  CalculixDefinition quadratic;
  quadratic.element = CalculixElement::C3D10;
  const GateDefinitions gates = gateDefinitions(quadratic, quadratic, 0);
  EXPECT_EQ(gates.finer.mesher.refinement, 1) << "a C3D10 reference: the next mesh level";
  EXPECT_EQ(gates.refinedBy, "mesh level 1");
  EXPECT_EQ(gates.increments.element, CalculixElement::C3D10);
  EXPECT_EQ(gates.increments.mesher.refinement, 0);
}

TEST(ReferenceCache, APoseLimitIsInTheKeyOnlyWhereItDropsAPose) {
  REQUIRE_PROGRAM("ccx");
  const LoadedScene scene = loadScene("fusiform", {"resolution=6", "fibre_count=8"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  ASSERT_EQ(scene.poseCount, 3);
  const auto key = [&](int limit, const ContinuumCut& cut) {
    CalculixDefinition definition;
    definition.poseLimit = limit;
    return referenceCacheKey(scene, prepared, definition, cut);
  };
  const ContinuumCut none, atPose2{2, 1.0, "no continuum equilibrium"};
  for (const int every : {3, 5}) EXPECT_EQ(key(every, none), key(0, none)) << every;
  EXPECT_NE(key(2, none), key(0, none));
  EXPECT_NE(key(1, none), key(2, none));
  EXPECT_EQ(key(2, atPose2), key(0, atPose2)) << "the cut drops pose 2 already";
  EXPECT_NE(key(1, atPose2), key(0, atPose2));
}

TEST(ReferenceGates, StopWhereCcxStoppedTheReferenceButNotAtItsContinuumCut) {
  const std::vector<btVector3> surface{{0, 0, 0}};
  CalculixSolution solution;
  solution.poseSurfaces.assign(4, surface);
  solution.poseFailures.assign(4, "");
  solution.returnFailure = "muscle m: *ERROR: increment size smaller than minimum";
  EXPECT_EQ(gatePoseLimit(solution), 0) << "every pose solved (the gates have no return step)";
  solution.poseSurfaces[2].clear();
  solution.poseSurfaces[3].clear();
  solution.cut = {2, 2.0, "no continuum equilibrium"};
  EXPECT_EQ(gatePoseLimit(solution), 0) << "a cut is no failure: the gates keep their keys";
  solution.cut = {};
  solution.poseFailures[2] = solution.returnFailure;
  EXPECT_EQ(gatePoseLimit(solution), 2);
  solution.poseSurfaces.assign(4, {});
  solution.poseFailures[0] = solution.returnFailure;
  EXPECT_EQ(gatePoseLimit(solution), 1) << "pose 0 alone (0 would be every pose)";
}

/// The scene's continuum cut with its attachment distances × `scale`.
ContinuumCut cutOf(const LoadedScene& scene, btScalar scale = 1) {
  std::vector<MeshDistance> bones;
  for (const BoneInput& bone : scene.bones) bones.emplace_back(bone.mesh);
  return findContinuumCut(scene, bones, sampleContinuum(scene), scale);
}

TEST(ContinuumCut, PinchsBladesCloseAcrossTheMuscleFromPose2) {
  const LoadedScene scene = loadScene("pinch");
  const ContinuumCut cut = cutOf(scene);
  // Pose 1 leaves 10.2 mm between the blades (10 mm apart, 2 mm side by side); from pose 2 on
  // they have passed each other with their facing sides 2 mm apart, twice the attachment
  // distance being 8 mm.
  EXPECT_EQ(cut.pose, 2) << cut.reason;
  EXPECT_GE(cut.gapMm, 2 - 1e-3);
  EXPECT_LT(cut.gapMm, 3.5) << "the samples lie within a grid step (2 mm) of the slot";
  EXPECT_NE(cut.reason.find("blade-a and blade-b"), std::string::npos) << cut.reason;
  EXPECT_NE(cut.reason.find("muscle pinched"), std::string::npos) << cut.reason;
  EXPECT_NE(cut.reason.find("twice its attachment distance (8.0 mm)"), std::string::npos)
      << cut.reason;
  for (const char* other : {"fusiform", "cylinder-twist", "cylinder-stretch", "sphere-planes"})
    for (const btScalar scale : {0.5f, 1.0f, 1.5f})
      EXPECT_EQ(cutOf(loadScene(other), scale).pose, -1) << other << " x" << scale;
}

TEST(ContinuumCut, MovesWithTheAttachmentScaleOfAGatesSolve) {
  // With 1.5x the attachment distance (6 mm) the bound is 12 mm: pose 1's 10.2 mm between the
  // blades already cuts (ccx stopped there, "increment size smaller than minimum", with the
  // muscle's top attached to one blade and its bottom to the other). Halved (2 mm, bound 4 mm)
  // the cut stays at pose 2, where the blades are 2.0 mm apart.
  const LoadedScene scene = loadScene("pinch");
  const ContinuumCut wider = cutOf(scene, 1.5f);
  EXPECT_EQ(wider.pose, 1) << wider.reason;
  EXPECT_NEAR(wider.gapMm, 10.2, 1.0);
  EXPECT_NE(wider.reason.find("twice 1.5x its attachment distance (12.0 mm)"), std::string::npos)
      << wider.reason;
  EXPECT_EQ(cutOf(scene, 0.5f).pose, 2);
}

TEST(ContinuumCut, IsWhereTheGapFallsBelowTwiceTheAttachmentDistanceNotWhereItStarts) {
  // sphere-planes: the plates touch the 60 mm sphere at rest and close in by 0.25 mm each per
  // pose (59.5, then 59 mm apart). The gap is measured, not guessed: with the bound (twice the
  // attachment distance) at 59.6 mm the first pose is cut, at 58.8 none; at 80 mm the plates
  // were closer than that at rest already, which is the scene's rest state, no cut.
  const auto cutAt = [](const char* attachment) {
    return cutOf(loadScene("sphere-planes", {attachment}));
  };
  const ContinuumCut cut = cutAt("attachment_distance=29.8");
  EXPECT_EQ(cut.pose, 1) << cut.reason;
  EXPECT_NEAR(cut.gapMm, 59.5, 0.01);
  EXPECT_EQ(cutAt("attachment_distance=29.4").pose, -1);
  EXPECT_EQ(cutAt("attachment_distance=40").pose, -1);
}

TEST(ReferenceGates, SpreadIsBetweenTheBestRunOfEachMethod) {
  std::vector<RunMetrics> runs(5);
  const char* names[] = {"calculix", "fibremss", "fibremss:iterations=280", "btsoftbody", "fem"};
  const double rms[] = {0, 3.0, 1.5, 4.0, 2.0};
  for (int i = 0; i < 5; ++i) {
    runs[static_cast<size_t>(i)].method = names[i];
    runs[static_cast<size_t>(i)].rmsToReferenceMm = rms[i];
  }
  EXPECT_DOUBLE_EQ(methodSpreadMm(runs), 4.0 - 1.5);
  runs.resize(3);
  EXPECT_DOUBLE_EQ(methodSpreadMm(runs), 1.5) << "one method: its best error";
  runs.resize(1);
  EXPECT_TRUE(std::isnan(methodSpreadMm(runs)));
}

TEST(ReferenceOptions, SpherePlanesIsSolvedAsC3D10WithAStifferPenaltyUnlessGiven) {
  const LoadedScene sphere = loadScene("sphere-planes", {});
  const LoadedScene fusiform = loadScene("fusiform", {});
  ReferenceOptions options;
  const CalculixDefinition chosen = sceneDefinition(sphere, options);
  EXPECT_EQ(chosen.element, CalculixElement::C3D10);
  EXPECT_EQ(chosen.contactPenalty, kSpherePlanesContactPenalty);
  const CalculixDefinition other = sceneDefinition(fusiform, options);
  EXPECT_EQ(other.element, CalculixElement::C3D4) << "other scenes keep the defaults";
  EXPECT_EQ(other.contactPenalty, CalculixDefinition().contactPenalty);
  options.elementGiven = options.contactPenaltyGiven = true;
  const CalculixDefinition given = sceneDefinition(sphere, options);
  EXPECT_EQ(given.element, CalculixElement::C3D4) << "the command line's choice stands";
  EXPECT_EQ(given.contactPenalty, CalculixDefinition().contactPenalty);
}

TEST(ReferenceOptions, ContactSlidingIsTheScenesUnlessGiven) {
  const LoadedScene pinch = loadScene("pinch", {});
  ReferenceOptions options;
  EXPECT_EQ(sceneDefinition(pinch, options).contactSliding, ContactSliding::Small);
  for (const char* name : {"fusiform", "cylinder-twist", "sphere-planes"})
    EXPECT_EQ(sceneDefinition(loadScene(name, {}), options).contactSliding, ContactSliding::Finite)
        << name << ": finite sliding, as before";
  const LoadedScene set = loadScene("fusiform", {"reference.contact_sliding=small"});
  EXPECT_EQ(sceneDefinition(set, options).contactSliding, ContactSliding::Small);
  options.contactSlidingGiven = true;
  EXPECT_EQ(sceneDefinition(pinch, options).contactSliding, ContactSliding::Finite)
      << "the command line's choice stands";
  EXPECT_THROW(loadScene("pinch", {"reference.contact_sliding=large"}), InputError);
}

/// A muscle's job as the reference writes it (its .inp): every node, and which of the muscle's
/// own (those its elements use; the bones' obstacle nodes follow them) are prescribed.
struct WrittenJob {
  std::vector<btVector3> nodes;
  size_t muscleNodes = 0;
  std::vector<bool> prescribed;
};

WrittenJob readWrittenJob(const std::filesystem::path& inp) {
  WrittenJob job;
  std::ifstream in(inp);
  std::string section;
  std::set<uint32_t> moved;
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("**", 0) == 0) continue;
    if (line[0] == '*') {
      section = line;
      continue;
    }
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream row(line);
    if (section == "*NODE, NSET=NALL") {
      long id = 0;
      float x = 0, y = 0, z = 0;
      row >> id >> x >> y >> z;
      job.nodes.emplace_back(x, y, z);
    } else if (section.rfind("*ELEMENT, TYPE=C3D4, ELSET=EALL", 0) == 0) {
      size_t id = 0, element = 0;
      for (row >> element; row >> id;) job.muscleNodes = std::max(job.muscleNodes, id);
    } else if (section == "*NSET, NSET=NMOVED") {
      for (uint32_t id = 0; row >> id;) moved.insert(id - 1);
    }
  }
  job.prescribed.assign(job.muscleNodes, false);
  for (uint32_t n : moved)
    if (n < job.muscleNodes) job.prescribed[n] = true;
  return job;
}

/// hip-pelvis declares its muscles' origin and insertion; iliacus's belly passes the femoral
/// head within the attachment distance. The reference fixes the nodes the areas' rule takes
/// (scenes/README.md, "Declared attachments"; a surface node where preparation put its vertex)
/// and those inside a bone at rest, and leaves the belly free, none of it inside a bone.
TEST(ReferenceAttachments, ADeclaredMusclesBellyIsFreeAndOutsideTheBonesAtRest) {
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("reference_declared_test");
  const LoadedScene scene = loadScene("hip-pelvis", {"resolution=6"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  const ReferenceOptions options;
  CalculixDefinition definition = sceneDefinition(scene, options);
  definition.program = "true";  // the input is written, nothing solves it
  const MuscleSolution part =
      solveCalculixMuscle(scene, prepared, definition, ContinuumCut{}, 0, dir.path().string());
  const WrittenJob job = readWrittenJob(part.inputFile);
  const MuscleInput& iliacus = scene.muscles[0];
  const std::vector<btVector3>& surface = prepared.muscles[0]->restSurface.vertices;
  const btScalar attachment = iliacus.parameters.attachmentDistance;
  std::vector<MeshDistance> bones;
  for (const BoneInput& bone : scene.bones) bones.emplace_back(bone.mesh);
  const auto nearest = [](const btVector3& p, const std::vector<btVector3>& points) {
    btScalar best = std::numeric_limits<btScalar>::infinity();
    for (const btVector3& q : points) best = std::min(best, p.distance(q));
    return best;
  };
  ASSERT_EQ(iliacus.attachments.size(), 2u);
  std::array<size_t, 2> fixedByArea{0, 0};
  size_t freeNearBone = 0;
  for (size_t n = 0; n < job.muscleNodes; ++n) {
    const btVector3& x = job.nodes[n];
    btScalar toBone = std::numeric_limits<btScalar>::infinity();
    for (const MeshDistance& bone : bones) toBone = std::min(toBone, bone.signedDistance(x));
    if (!job.prescribed[n]) {
      EXPECT_GT(toBone, -1e-5f) << "free node " << n << " inside a bone at rest";
      if (toBone < attachment) ++freeNearBone;
      continue;
    }
    const btVector3& at = n < surface.size() ? surface[n] : x;  // where the rule sees it
    const btScalar toSurface = nearest(at, surface);
    bool inArea = toBone < 0;

    for (size_t a = 0; a < 2; ++a) {
      std::vector<btVector3> area;
      for (uint32_t v : iliacus.attachments[a].surfaceVertices) area.push_back(surface[v]);
      const bool in = nearest(at, area) - toSurface <= attachment;
      fixedByArea[a] += in;
      inArea = inArea || in;
    }
    EXPECT_TRUE(inArea) << "node " << n << " fixed outside both declared areas and the bones";
  }
  EXPECT_GT(fixedByArea[0], 0u) << "the origin holds nodes";
  EXPECT_GT(fixedByArea[1], 0u) << "the insertion holds nodes";
  EXPECT_GT(freeNearBone, 0u) << "the belly passes a bone within the attachment distance";
  EXPECT_EQ(size_t(std::count(job.prescribed.begin(), job.prescribed.end(), true)),
            part.prescribedNodes);
}

TEST(ReferenceCache, StoresAndReadsBackASolution) {
  TemporaryDirectory dir("reference_cache_test");
  CalculixSolution solution;
  solution.poseSurfaces = {{{1, 2, 3}, {4, 5, 6}}, {}};
  solution.poseFailures = {"", "muscle m: *ERROR: too many cutbacks"};
  solution.returnFailure = "muscle m: *ERROR: too many cutbacks";
  solution.nodes = 11;
  solution.elements = 7;
  solution.newtonIterations = 42;
  solution.inputFiles = {"/a/muscle0.inp"};
  const std::string path = (dir.path() / "s.bin").string();
  saveSolution(path, solution);
  CalculixSolution back;
  ASSERT_TRUE(loadSolution(path, back));
  EXPECT_EQ(back.poseSurfaces, solution.poseSurfaces);
  EXPECT_EQ(back.poseFailures, solution.poseFailures);
  EXPECT_EQ(back.returnFailure, solution.returnFailure);
  EXPECT_EQ(back.nodes, 11u);
  EXPECT_EQ(back.newtonIterations, 42);
  EXPECT_EQ(back.inputFiles, solution.inputFiles);
  EXPECT_EQ(back.solvedPoses(), 1);
  EXPECT_EQ(back.cut.pose, -1);
  EXPECT_FALSE(loadSolution((dir.path() / "absent.bin").string(), back));

  solution.cut = {1, 2.0, "no continuum equilibrium: the bones close across it"};
  saveSolution(path, solution);
  ASSERT_TRUE(loadSolution(path, back));
  EXPECT_EQ(back.cut.pose, 1);
  EXPECT_EQ(back.cut.gapMm, 2.0);
  EXPECT_EQ(back.cut.reason, solution.cut.reason);
  // An entry stored before the cut existed ends after its input files: read as no cut.
  const auto size = std::filesystem::file_size(path);
  std::filesystem::resize_file(path, size - 2 * 8 - (8 + solution.cut.reason.size()));
  ASSERT_TRUE(loadSolution(path, back));
  EXPECT_EQ(back.cut.pose, -1);
  EXPECT_EQ(back.inputFiles, solution.inputFiles);
  std::filesystem::resize_file(path, 30);
  EXPECT_THROW(loadSolution(path, back), InputError);
}

/// The solver definition changed in each of the ways the cache key must tell apart.
std::vector<CalculixDefinition> changedDefinitions(const CalculixDefinition& definition) {
  std::vector<CalculixDefinition> variants;
  CalculixDefinition d = definition;
  d.material.poissonRatio = 0.45;
  variants.push_back(d);
  d = definition;
  d.material.youngsModulus *= 2;
  variants.push_back(d);
  d = definition;
  d.element = CalculixElement::C3D10;
  variants.push_back(d);
  d.contactPenalty = 0;
  variants.push_back(d);  // C3D10 without contact
  d = definition;
  d.mesher.refinement = 1;
  variants.push_back(d);
  d = definition;
  d.mesher.radiusEdgeRatio = 1.5;
  variants.push_back(d);
  d = definition;
  d.attachmentScale = 1.5;
  variants.push_back(d);
  d = definition;
  d.contactPenalty = 0;
  variants.push_back(d);
  d = definition;
  d.incrementScale = 0.25;
  variants.push_back(d);
  d.muscleIncrementScales.assign(1, 1.0);  // a retry that kept its one muscle at x1
  variants.push_back(d);
  d = definition;
  d.contactSliding = ContactSliding::Small;
  variants.push_back(d);
  d.element = CalculixElement::C3D10;
  variants.push_back(d);  // the gate's C3D10 solve with small sliding
  return variants;
}

TEST(ReferenceCache, KeyChangesWithEachInputAndOnlyThen) {
  REQUIRE_PROGRAM("ccx");
  const LoadedScene scene = loadScene("fusiform", {"resolution=6", "fibre_count=8"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  const CalculixDefinition definition;
  const ContinuumCut none;
  const std::string key = referenceCacheKey(scene, prepared, definition, none);
  EXPECT_EQ(key.size(), 16u);
  EXPECT_EQ(referenceCacheKey(scene, prepared, definition, none), key) << "stable";
  const LoadedScene again =
      loadScene("fusiform", {"resolution=6", "fibre_count=8", "iterations=500"});
  EXPECT_EQ(referenceCacheKey(again, prepared, definition, none), key)
      << "solver settings do not matter";
  CalculixDefinition limited = definition;
  limited.memoryLimitGiB = 1;
  EXPECT_EQ(referenceCacheKey(scene, prepared, limited, none), key) << "nor ccx's memory limit";

  std::set<std::string> keys{key};
  int change = 0;
  auto changed = [&](const LoadedScene& s, const PreparedScene& p, const CalculixDefinition& d,
                     const ContinuumCut& cut = {}) {
    EXPECT_TRUE(keys.insert(referenceCacheKey(s, p, d, cut)).second) << "change " << change;
    ++change;
  };
  for (const CalculixDefinition& d : changedDefinitions(definition)) changed(scene, prepared, d);
  CalculixDefinition noContact = definition;
  noContact.contactPenalty = 0;
  CalculixDefinition sliding = noContact;
  sliding.contactSliding = ContactSliding::Small;
  EXPECT_EQ(referenceCacheKey(scene, prepared, sliding, none),
            referenceCacheKey(scene, prepared, noContact, none))
      << "without contact the sliding does not matter";
  ContinuumCut cut;
  cut.pose = 1;
  changed(scene, prepared, definition, cut);
  cut.pose = 2;
  changed(scene, prepared, definition, cut);
  cut.reason = "another reason, the same pose";
  EXPECT_EQ(referenceCacheKey(scene, prepared, definition, cut),
            referenceCacheKey(scene, prepared, definition, {2, 0, ""}))
      << "only the cut's pose";
  LoadedScene moved = scene;
  moved.muscles[0].parameters.attachmentDistance *= 2;
  changed(moved, prepared, definition);
  PreparedScene reshaped = prepared;
  auto muscle = std::make_shared<MuscleSettings>(*prepared.muscles[0]);
  muscle->restSurface.vertices[0] += btVector3(1e-4f, 0, 0);
  reshaped.muscles[0] = muscle;
  changed(scene, reshaped, definition);
  LoadedScene otherMotion = scene;
  for (BoneMotion& motion : otherMotion.motions)
    for (btTransform& pose : motion.poses) pose.getOrigin() += btVector3(0, 0, 1e-4f);
  ASSERT_GT(otherMotion.poseCount, 1) << "fusiform moves a bone";
  changed(otherMotion, prepared, definition);
}

}  // namespace
}  // namespace fibremss

namespace fibremss {
namespace {

/// fusiform with a coarse surface (8 slices × 12 sections) and coarse bars (12 × 12, not
/// 48 × 32: ccx's rigid obstacles, most of its nodes otherwise): a reference of a few hundred
/// tetrahedra, solved in seconds.
std::string coarseFusiform(const std::filesystem::path& dir) {
  nlohmann::json scene = nlohmann::json::parse(exportBuiltInScene("fusiform"));
  nlohmann::json& generator = scene["muscles"][0]["surface"]["generator"];
  generator["slices"] = 8;
  generator["sections"] = 12;
  for (nlohmann::json& bone : scene["bones"]) {
    bone["mesh"]["generator"]["slices"] = 12;
    bone["mesh"]["generator"]["sections"] = 12;
  }
  const std::filesystem::path path = dir / "coarse-fusiform.json";
  std::ofstream(path) << scene.dump(2);
  return path.string();
}

std::string readText(const std::filesystem::path& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

/// sphere-planes with a coarser sphere (subdivisions 4, ~2 mm edges) whose plates close in by
/// 1 mm each in one pose.
std::string coarseSpherePlanes(const std::filesystem::path& dir) {
  nlohmann::json scene = nlohmann::json::parse(exportBuiltInScene("sphere-planes"));
  scene["muscles"][0]["surface"]["generator"]["subdivisions"] = 4;
  for (int b = 0; b < 2; ++b) {
    nlohmann::json& keys = scene["bones"][b]["motion"]["keyframes"];
    keys.erase(1);
    keys[1]["translation"] = {0, b == 0 ? -1 : 1, 0};
  }
  const std::filesystem::path path = dir / "coarse-sphere-planes.json";
  std::ofstream(path) << scene.dump(2);
  return path.string();
}

TEST(ReferenceRetry, AFailedPoseOrReturnStepIsRetriedNotAStopOrAnInterruption) {
  CalculixSolution solution;
  solution.poseSurfaces = {{{0, 0, 0}}, {}};
  solution.poseFailures = {"", ""};
  EXPECT_EQ(ccxFailureToRetry(solution), "");
  solution.returnFailure = "muscle m: *ERROR: increment size smaller than minimum";
  EXPECT_EQ(ccxFailureToRetry(solution), "return to rest: " + solution.returnFailure)
      << "a failed return step is retried as a failed pose is";
  solution.poseFailures[1] = "muscle m: ccx stopped (exit 255)";
  EXPECT_EQ(ccxFailureToRetry(solution), "pose 1: muscle m: ccx stopped (exit 255)");
  solution.interrupted = true;
  EXPECT_EQ(ccxFailureToRetry(solution), "") << "interrupted: not retried";
  solution.interrupted = false;
  solution.returnFailure = "muscle m: *ERROR in u_calloc (ccx's memory limit is 8 GiB)";
  solution.poseFailures[1] = solution.returnFailure;
  EXPECT_EQ(ccxFailureToRetry(solution), "") << "stopped on its memory limit: not retried";
}

TEST(CalculixRun, AnInterruptedSolveWithoutAReturnStepReportsNoReturnFailure) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("ccx_interrupted_test");
  const LoadedScene scene = loadScene(coarseFusiform(dir.path()), {"resolution=6"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  const std::atomic<bool> cancel{true};
  for (const bool returnToRest : {false, true}) {
    SCOPED_TRACE(returnToRest);
    CalculixDefinition definition;
    definition.returnToRest = returnToRest;  // a gate's solve has none
    const CalculixSolution solution =
        solveCalculixReference(scene, prepared, definition, {},
                               (dir.path() / std::to_string(returnToRest)).string(), {}, &cancel);
    EXPECT_TRUE(solution.interrupted);
    EXPECT_NE(solution.poseFailures[0].find("interrupted"), std::string::npos);
    EXPECT_EQ(solution.returnFailure.find("interrupted") != std::string::npos, returnToRest)
        << solution.returnFailure;
    if (!returnToRest) {
      EXPECT_EQ(solution.returnFailure, "");
    }
  }
}

/// The coarse fusiform whose lower bar moves 2 mm per pose (not 15): a few increments.
std::string shortFusiform(const std::filesystem::path& dir) {
  nlohmann::json json = nlohmann::json::parse(readText(coarseFusiform(dir)));
  for (int pose = 1; pose < 3; ++pose)
    json["bones"][1]["motion"]["keyframes"][pose]["translation"] = {0, -2 * pose, 0};
  const std::filesystem::path path = dir / "short-fusiform.json";
  std::ofstream(path) << json.dump(2);
  return path.string();
}

/// shortFusiform at resolution 6, prepared, in a directory of its own; ccx and tetgen needed.
class ShortFusiform : public ::testing::Test {
 protected:
  void SetUp() override {
    REQUIRE_PROGRAM("ccx");
    REQUIRE_PROGRAM("tetgen");
    scene = loadScene(shortFusiform(dir.path()), {"resolution=6"});
    prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
    definition.returnToRest = false;
  }
  TemporaryDirectory dir{"ccx_short_fusiform_test"};
  LoadedScene scene;
  PreparedScene prepared;
  CalculixDefinition definition;  ///< the default without the return step (a gate's has none)
};

TEST_F(ShortFusiform, AQuarterOfTheIncrementsTakesFourTimesAsManyToTheSameEquilibrium) {
  CalculixDefinition finer = definition;
  finer.incrementScale = 0.25;
  const std::filesystem::path coarseDir = dir.path() / "coarse", fineDir = dir.path() / "fine";
  const CalculixSolution coarse =
      solveCalculixReference(scene, prepared, definition, {}, coarseDir.string());
  const CalculixSolution fine =
      solveCalculixReference(scene, prepared, finer, {}, fineDir.string());
  ASSERT_EQ(scene.poseCount, 3);
  ASSERT_EQ(coarse.solvedPoses(), 3) << coarse.poseFailures[1] << coarse.poseFailures[2];
  ASSERT_EQ(fine.solvedPoses(), 3) << fine.poseFailures[1] << fine.poseFailures[2];
  // The lower bar moves 2 mm in each of poses 1 and 2 (pose 0 is rest: one increment): at
  // most 1 mm, or 0.25 mm, per increment, and ccx may cut back further.
  EXPECT_GE(coarse.increments, 1 + 2 * 2);
  EXPECT_LT(coarse.increments, 1 + 2 * 8) << "the default is not already that fine";
  EXPECT_GE(fine.increments, 1 + 2 * 8);
  // Each moving step's *STATIC line (initial, period, minimum, largest increment) starts and
  // is bounded at 0.25 mm of its 2 mm.
  std::istringstream input(readText(fineDir / "muscle0.inp"));
  std::vector<std::array<double, 4>> statics;
  for (std::string line; std::getline(input, line);) {
    if (line != "*STATIC") continue;
    std::getline(input, line);
    std::array<double, 4>& row = statics.emplace_back();
    ASSERT_EQ(std::sscanf(line.c_str(), "%lf, %lf, %lf, %lf", &row[0], &row[1], &row[2], &row[3]),
              4)
        << line;
  }
  ASSERT_EQ(statics.size(), 3u);
  for (size_t step = 1; step < 3; ++step) {
    EXPECT_NEAR(statics[step][3], 0.125, 1e-3) << step;
    EXPECT_EQ(statics[step][0], statics[step][3]) << step;
  }
  // The same hyperelastic equilibrium (frictionless contact: no path dependence) either way.
  const size_t vertices[] = {prepared.muscles[0]->restSurface.vertices.size()};
  const int covered[] = {3};
  int compared = 0;
  EXPECT_LT(rmsBetweenSolutions(coarse, fine, vertices, covered, &compared), 1e-3) << "mm";
  EXPECT_EQ(compared, 3);
}

/// Adds a second muscle, `beside`, to a fusiform scene's JSON: the first's, 40 mm beside it and
/// half its radii.
void addBeside(nlohmann::json& json) {
  nlohmann::json beside = json["muscles"][0];
  beside["name"] = "beside";
  for (nlohmann::json& point : beside["surface"]["generator"]["points"]) point[0] = 40;
  for (nlohmann::json& radius : beside["surface"]["generator"]["radii"])
    radius = radius.get<double>() / 2;
  json["muscles"].push_back(beside);
}

/// The coarse fusiform with both bars carried 20 mm sideways in its one pose, the lower one 2 mm
/// farther down as well; `twice` adds a second muscle beside the first (half its radii).
std::string carriedFusiform(const std::filesystem::path& dir, bool twice) {
  nlohmann::json json = nlohmann::json::parse(readText(coarseFusiform(dir)));
  for (int b = 0; b < 2; ++b) {
    nlohmann::json keys = nlohmann::json::array();
    for (int pose = 0; pose < 2; ++pose)
      keys.push_back({{"label", pose},
                      {"translation", {0, b == 1 ? -2 * pose : 0, 20 * pose}},
                      {"quaternion", {0, 0, 0, 1}}});
    json["bones"][b]["motion"] = {{"type", "keyframes"}, {"keyframes", keys}};
  }
  if (twice) addBeside(json);
  const std::filesystem::path path = dir / (twice ? "carried-twice.json" : "carried.json");
  std::ofstream(path) << json.dump(2);
  return path.string();
}

/// Each step's largest increment (the last value of its *STATIC line) in a .inp.
std::vector<double> largestIncrements(const std::filesystem::path& inp) {
  std::istringstream input(readText(inp));
  std::vector<double> largest;
  for (std::string line; std::getline(input, line);) {
    if (line != "*STATIC") continue;
    std::getline(input, line);
    double initial = 0, period = 0, minimum = 0, bound = 0;
    if (std::sscanf(line.c_str(), "%lf, %lf, %lf, %lf", &initial, &period, &minimum, &bound) == 4)
      largest.push_back(bound);
  }
  return largest;
}

TEST(IncrementRule, BoundsOnlyTheMoveBeyondTheFrameTheAttachmentsMoveLeastIn) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("ccx_increment_rule_test");
  const LoadedScene scene = loadScene(carriedFusiform(dir.path(), false), {"resolution=6"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  const std::atomic<bool> cancel{true};  // the input is written, ccx stopped at once
  std::map<IncrementRule, std::vector<double>> largest;
  std::set<std::string> keys;
  for (const IncrementRule rule : {IncrementRule::World, IncrementRule::BoneFrame}) {
    CalculixDefinition definition;
    definition.returnToRest = false;
    definition.incrementRule = rule;
    const std::filesystem::path work = dir.path() / toString(rule);
    solveCalculixReference(scene, prepared, definition, {}, work.string(), {}, &cancel);
    largest[rule] = largestIncrements(work / "muscle0.inp");
    keys.insert(referenceCacheKey(scene, prepared, definition, {}));
  }
  EXPECT_EQ(keys.size(), 2u) << "the rule is in the key";
  ASSERT_EQ(largest[IncrementRule::World].size(), 2u);
  ASSERT_EQ(largest[IncrementRule::BoneFrame].size(), 2u);
  // Pose 1: the lower bar's nodes move sqrt(2² + 20²) mm, 2 mm of it beyond the upper bar's
  // rigid carry (in either bar's frame the other's nodes move 2 mm).
  EXPECT_NEAR(largest[IncrementRule::World][1], 1 / std::sqrt(404.0), 1e-4);
  EXPECT_NEAR(largest[IncrementRule::BoneFrame][1], 0.5, 1e-4);
}

TEST_F(ShortFusiform, APoseLimitSolvesTheFirstPosesAsTheWholeSolveDoesAndNoMore) {
  CalculixDefinition limited = definition;
  limited.poseLimit = 2;
  const std::filesystem::path wholeDir = dir.path() / "whole", limitedDir = dir.path() / "limited";
  const CalculixSolution whole =
      solveCalculixReference(scene, prepared, definition, {}, wholeDir.string());
  const CalculixSolution first =
      solveCalculixReference(scene, prepared, limited, {}, limitedDir.string());
  ASSERT_EQ(whole.solvedPoses(), 3) << whole.poseFailures[1] << whole.poseFailures[2];
  EXPECT_EQ(largestIncrements(limitedDir / "muscle0.inp").size(), 2u) << "two steps given to ccx";
  EXPECT_EQ(first.solvedPoses(), 2) << first.poseFailures[1];
  EXPECT_EQ(first.poseFailures, std::vector<std::string>(3, "")) << "pose 2 is no failure";
  EXPECT_EQ(ccxFailureToRetry(first), "") << "nothing to retry";
  for (size_t p = 0; p < 2; ++p) EXPECT_EQ(first.poseSurfaces[p], whole.poseSurfaces[p]) << p;
}

TEST(ReferenceCells, AReferenceCcxSolvedInPartListsItsGatesUpToItsLastSolvedPose) {
  REQUIRE_PROGRAM("ccx");
  TemporaryDirectory dir("reference_cells_limit_test");
  const LoadedScene scene = loadScene(coarseFusiform(dir.path()), {"resolution=6"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  ReferenceOptions options;
  options.cacheDir = (dir.path() / "cache").string();
  const CalculixDefinition reference = sceneDefinition(scene, options);
  CalculixDefinition retry = reference;
  retry.incrementScale *= kFinerIncrements;
  // Stores a solve of `definition` that ccx failed from pose `failed` on (-1: none failed).
  const auto store = [&](const CalculixDefinition& definition, int failed) {
    CalculixSolution solution;
    for (int p = 0; p < scene.poseCount; ++p) {
      const bool solved = failed < 0 || p < failed;
      solution.poseSurfaces.push_back(solved ? prepared.muscles[0]->restSurface.vertices
                                             : std::vector<btVector3>());
      solution.poseFailures.push_back(p == failed ? "muscle m: *ERROR: too many cutbacks" : "");
    }
    const std::string entry =
        options.cacheDir + "/" + referenceCacheKey(scene, prepared, definition, {});
    std::filesystem::create_directories(entry);
    saveSolution(entry + "/surfaces.bin", solution);
  };
  // The gates' cells against those of `definitions`, in the listing's order.
  const auto expectGates = [&](const std::vector<NamedReferenceCell>& cells,
                               const GateDefinitions& definitions, int limit) {
    ASSERT_EQ(cells.size(), 5u);
    const CalculixDefinition* gates[] = {&definitions.attachmentLow, &definitions.attachmentHigh,
                                         &definitions.increments, &definitions.finer};
    for (size_t g = 0; g < 4; ++g) {
      const NamedReferenceCell& cell = cells[g + 1];
      EXPECT_EQ(cell.cell.definition.poseLimit, limit) << cell.solve;
      EXPECT_EQ(cell.key, referenceCacheKey(scene, prepared, *gates[g], cell.cell.cut))
          << cell.solve;
    }
  };
  store(reference, 1);  // retried at finer increments, not solved yet: its gates over every pose
  const std::vector<NamedReferenceCell> unknown = referenceCells(scene, prepared, options);
  EXPECT_EQ(unknown[0].cell.definition.incrementScale, retry.incrementScale);
  EXPECT_FALSE(unknown[0].stored);
  expectGates(unknown, gateDefinitions(retry, reference, 0), 0);
  EXPECT_EQ(unknown[3].cell.definition.incrementScale, retry.incrementScale * kIncrementGateFactor)
      << "increments halved from the retry's";
  EXPECT_EQ(unknown[4].cell.definition.incrementScale, reference.incrementScale)
      << "one level finer from the asked increments";
  store(retry, 2);  // the retry stops at pose 2: its gates solve poses 0-1
  const std::vector<NamedReferenceCell> limited = referenceCells(scene, prepared, options);
  EXPECT_TRUE(limited[0].stored);
  EXPECT_EQ(limited[0].key, unknown[0].key);
  expectGates(limited, gateDefinitions(retry, reference, 2), 2);
  for (size_t c = 1; c < limited.size(); ++c) EXPECT_NE(limited[c].key, unknown[c].key);
  store(retry, -1);  // the retry solves every pose: its gates too, under their keys
  const std::vector<NamedReferenceCell> whole = referenceCells(scene, prepared, options);
  for (size_t c = 0; c < whole.size(); ++c) EXPECT_EQ(whole[c].key, unknown[c].key);
}

/// Two muscles carried by their bones (carriedFusiform) at resolution 6: every solve of it is
/// two cells.
class CarriedPair : public ::testing::Test {
 protected:
  void SetUp() override {
    REQUIRE_PROGRAM("ccx");
    REQUIRE_PROGRAM("tetgen");
    scene = loadScene(carriedFusiform(dir.path(), true), {"resolution=6"});
    prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
    ASSERT_EQ(prepared.muscles.size(), 2u);
  }
  TemporaryDirectory dir{"ccx_carried_pair_test"};
  LoadedScene scene;
  PreparedScene prepared;
};

TEST_F(CarriedPair, AGateNotStoredIsNamedWithHowManyOfItsMusclesCellsAre) {
  ReferenceOptions options;
  options.cacheDir = (dir.path() / "cache").string();
  cachedCalculixReference(scene, prepared, sceneDefinition(scene, options), {}, options.cacheDir,
                          {}, {}, nullptr);
  // The second muscle's cell of the increments-halved gate, as a batch engine solves it.
  const std::vector<NamedReferenceCell> cells = referenceCells(scene, prepared, options);
  const auto halved = std::ranges::find_if(cells, [](const NamedReferenceCell& cell) {
    return cell.solve == "increments halved" && cell.cell.muscle == 1;
  });
  ASSERT_NE(halved, cells.end());
  ASSERT_TRUE(cachedCalculixMuscle(scene, prepared, halved->cell.definition, halved->cell.cut,
                                   options.cacheDir, 1, {}, {}));
  options.cachedOnly = true;
  const Reference reference = computeReference(scene, prepared, options);
  ASSERT_FALSE(reference.missing);
  const std::string expected =
      "attachment distance x0.5; attachment distance x1.5; increments halved: 1 of 2 muscles' "
      "cells stored; one level finer";
  EXPECT_EQ(reference.gates.notComputed, expected);
  EXPECT_EQ(reference.gates.whyNotPassed(),
            "the reference's gates were not computed (" + expected + ")");
  EXPECT_EQ(referenceJson(reference)["gates"]["not_computed"], expected);
  const std::vector<std::string> lines = gateLines(reference.gates);
  EXPECT_NE(lines.back().find("`--cells` lists their cells): " + expected), std::string::npos)
      << lines.back();
}

TEST_F(CarriedPair, InParallelOrAsCellsTheCacheHoldsWhatTheSerialSolveStores) {
  const CalculixDefinition definition;
  const std::string key = referenceCacheKey(scene, prepared, definition, {});
  const auto cache = [&](const char* name) { return (dir.path() / name).string(); };
  const CalculixSolution serial =
      cachedCalculixReference(scene, prepared, definition, {}, cache("serial"), {}, {}, nullptr);
  const CalculixSolution parallel = cachedCalculixReference(scene, prepared, definition, {},
                                                            cache("parallel"), {}, {}, nullptr, 2);
  // As a batch engine runs them: one cell at a time, in any order, then merged.
  for (const size_t m : {1, 0}) {
    EXPECT_FALSE(mergeCalculixParts(scene, prepared, definition, {}, cache("cells"),
                                    *std::make_unique<CalculixSolution>()))
        << "a part is missing";
    EXPECT_TRUE(cachedCalculixMuscle(scene, prepared, definition, {}, cache("cells"), m, {}, {}));
    EXPECT_TRUE(referencePartStored(cache("cells"), key, m));
  }
  CalculixSolution cells;
  ASSERT_TRUE(mergeCalculixParts(scene, prepared, definition, {}, cache("cells"), cells));
  ASSERT_EQ(serial.solvedPoses(), 2) << serial.poseFailures[1];
  EXPECT_FALSE(serial.returnSurface.empty()) << serial.returnFailure;
  const auto files = [&](const char* name) {
    std::set<std::string> names;
    for (const auto& file : std::filesystem::directory_iterator(cache(name) + "/" + key))
      names.insert(file.path().filename().string());
    return names;
  };
  for (const auto& [name, solution] : std::vector<std::pair<const char*, CalculixSolution>>{
           {"parallel", parallel}, {"cells", cells}}) {
    SCOPED_TRACE(name);
    EXPECT_EQ(solution.poseSurfaces, serial.poseSurfaces);
    EXPECT_EQ(solution.poseFailures, serial.poseFailures);
    EXPECT_EQ(solution.returnSurface, serial.returnSurface);
    EXPECT_EQ(solution.increments, serial.increments);
    EXPECT_EQ(solution.newtonIterations, serial.newtonIterations);
    EXPECT_EQ(solution.nodes, serial.nodes);
    EXPECT_EQ(solution.prescribedNodes, serial.prescribedNodes);
    EXPECT_EQ(solution.inputFiles.size(), 2u);
    EXPECT_EQ(files(name), files("serial")) << "the same entry";
    EXPECT_FALSE(std::filesystem::exists(cache(name) + "/" + key + ".parts"));
  }
}

TEST(ReferenceCache, ASolutionKeepingItsMusclesPartsIsVersion2InTheCacheAndShipped) {
  TemporaryDirectory dir("reference_parts_test");
  CalculixSolution solution;
  solution.poseSurfaces = {{{1, 2, 3}, {4, 5, 6}}, {}};
  solution.poseFailures = {"", "muscle b: *ERROR: too many cutbacks"};
  MuscleSolution a, b;
  a.stepSurfaces = {{{1, 2, 3}}, {{1, 2, 4}}};
  a.nodes = 5;
  a.increments = 3;
  a.seconds = 1.5;
  a.inputFile = "muscle0.inp";
  b.failure = "*ERROR: too many cutbacks";
  b.increments = 7;
  const auto magic = [](const std::string& bytes) { return bytes.substr(0, 8); };
  const std::string cached = (dir.path() / "s.bin").string();
  const std::string shipped = (dir.path() / "s.ref.gz").string();
  saveSolution(cached, solution);
  EXPECT_EQ(magic(readText(cached)), "FMSSREF1") << "without parts: version 1, as before";
  solution.muscles = {a, b};
  saveSolution(cached, solution);
  EXPECT_EQ(magic(readText(cached)), "FMSSREF2");
  shipSolution(shipped, solution);
  for (const bool ship : {false, true}) {
    SCOPED_TRACE(ship ? "shipped" : "cached");
    CalculixSolution back;
    ASSERT_TRUE(ship ? loadShippedSolution(shipped, back) : loadSolution(cached, back));
    EXPECT_EQ(back.poseFailures, solution.poseFailures);
    ASSERT_EQ(back.muscles.size(), 2u);
    EXPECT_EQ(back.muscles[0].stepSurfaces, a.stepSurfaces);
    EXPECT_EQ(back.muscles[0].nodes, 5u);
    EXPECT_EQ(back.muscles[0].seconds, 1.5);
    EXPECT_EQ(back.muscles[0].inputFile, "muscle0.inp");
    EXPECT_TRUE(back.muscles[0].solvedEveryStep());
    EXPECT_EQ(back.muscles[1].failure, b.failure);
    EXPECT_EQ(back.muscles[1].increments, 7);
    EXPECT_FALSE(back.muscles[1].solvedEveryStep());
  }
}

/// A ccx that fails muscle1's job wherever the largest increment of a step after the first (the
/// rest pose's, one increment) is above `bound`, as ccx fails a pose at too coarse increments,
/// and runs ccx for every other; each job it is given is a line of `dir`/runs.log.
std::string ccxFailingMuscle1Above(const std::filesystem::path& dir, double bound) {
  const std::filesystem::path path = dir / "ccx-failing-muscle1";
  std::ofstream(path) << "#!/bin/sh\n"
                      << "[ -n \"$2\" ] && echo \"$2\" >> " << (dir / "runs.log") << "\n"
                      << "if [ \"$2\" = muscle1 ] && awk -F', *' -v bound=" << bound
                      << " '{if (p && ++n > 1 && $4 > bound) coarse = 1; p = ($0 == \"*STATIC\")} "
                         "END {exit !coarse}' muscle1.inp; then\n"
                      << "  echo ' *ERROR: increments too coarse for muscle1'; exit 201\n"
                      << "fi\n"
                      << "exec ccx \"$@\"\n";
  std::filesystem::permissions(path, std::filesystem::perms::owner_exec,
                               std::filesystem::perm_options::add);
  return path.string();
}

/// Muscle `m`'s vertices of a surface of every muscle (prepared restSurface order).
std::vector<btVector3> muscleVertices(const PreparedScene& prepared,
                                      const std::vector<btVector3>& surface, size_t m) {
  size_t first = 0;
  for (size_t i = 0; i < m; ++i) first += prepared.muscles[i]->restSurface.vertices.size();
  const size_t count = prepared.muscles[m]->restSurface.vertices.size();
  if (surface.size() < first + count) return {};
  return {surface.begin() + long(first), surface.begin() + long(first + count)};
}

/// carriedFusiform with its second muscle (`beside`), loaded and prepared; options of a
/// reference without gates in a cache of its own, solved by ccxFailingMuscle1Above.
class RetryPerMuscle : public ::testing::Test {
 protected:
  RetryPerMuscle()
      : dir("retry_per_muscle_test"),
        scene(loadScene(carriedFusiform(dir.path(), true), {"resolution=6"})),
        prepared(prepareScene(scene.bones, scene.muscles, scene.simulation.seed)) {
    options.cacheDir = (dir.path() / "cache").string();
    options.gates = false;
    // The lower bar's 2 mm beyond the carry: increments of at most 0.5 of the pose at the
    // default, 0.125 at a quarter of it.
    options.definition.program = ccxFailingMuscle1Above(dir.path(), 0.25);
  }
  /// The jobs ccx was given since the last call.
  std::vector<std::string> runs() const {
    std::vector<std::string> jobs;
    std::istringstream lines(readText(dir.path() / "runs.log"));
    for (std::string line; std::getline(lines, line);) jobs.push_back(line);
    std::filesystem::remove(dir.path() / "runs.log");
    return jobs;
  }
  /// The solve of `definition` through the cache, which ccx fails in muscle1.
  CalculixSolution failedSolve(const CalculixDefinition& definition) const {
    return cachedCalculixReference(scene, prepared, definition, {}, options.cacheDir, {}, {},
                                   nullptr);
  }
  TemporaryDirectory dir;
  LoadedScene scene;
  PreparedScene prepared;
  ReferenceOptions options;
};

TEST_F(RetryPerMuscle, KeepsTheIncrementsOfTheMusclesTheFailedSolveSolvedUnderAKeyOfItsOwn) {
  REQUIRE_PROGRAM("ccx");
  ASSERT_EQ(prepared.muscles.size(), 2u);
  const CalculixDefinition definition;
  CalculixSolution failed;
  failed.poseFailures = {"", "muscle beside: *ERROR: too many cutbacks"};
  CalculixDefinition uniform = definition;
  uniform.incrementScale *= kFinerIncrements;
  const auto key = [&](const CalculixDefinition& d) {
    return referenceCacheKey(scene, prepared, d, {});
  };
  EXPECT_EQ(key(retryDefinition(definition, failed)), key(uniform))
      << "stored without its parts: every muscle solved again";
  failed.muscles.resize(2);
  failed.muscles[1].failure = "*ERROR: too many cutbacks";
  const CalculixDefinition retry = retryDefinition(definition, failed);
  EXPECT_EQ(retry.incrementScale, uniform.incrementScale);
  EXPECT_EQ(retry.muscleIncrementScales, (std::vector<double>{1, kFinerIncrements}));
  EXPECT_NE(key(retry), key(uniform)) << "a mixed retry is no uniform one";
  EXPECT_NE(key(retry), key(definition));
  EXPECT_EQ(keptPartKey(scene, prepared, retry, {}, 0), key(definition));
  EXPECT_EQ(keptPartKey(scene, prepared, retry, {}, 1), "") << "solved again";
  EXPECT_EQ(incrementsText(retry, prepared),
            "x0.25 for beside only (" + prepared.muscles[0]->name + " at x1)");
  const CalculixDefinition halved = gateDefinitions(retry, definition, 0).increments;
  EXPECT_EQ(halved.muscleIncrementScales,
            (std::vector<double>{kIncrementGateFactor, kFinerIncrements * kIncrementGateFactor}));
  ReferenceGates gates;
  gates.incrementsScale = halved.incrementScale;
  gates.incrementsPerMuscle = incrementsText(halved, prepared);
  EXPECT_NE(gateLines(gates)[2].find("increments halved (x0.125 for beside only (" +
                                     prepared.muscles[0]->name +
                                     " at x0.5) of the default 2.5 deg / 1 mm)"),
            std::string::npos)
      << gateLines(gates)[2];
  // A retry of a mixed solve (a gate's of a mixed reference): each muscle ccx failed finer
  // than it was, the solve's own increments the finest of them.
  const CalculixDefinition again = retryDefinition(retry, failed);
  EXPECT_EQ(again.muscleIncrementScales,
            (std::vector<double>{1, kFinerIncrements * kFinerIncrements}));
  EXPECT_EQ(again.incrementScale, kFinerIncrements * kFinerIncrements);
  failed.muscles[0].failure = "*ERROR: too many cutbacks";
  failed.muscles[1].failure.clear();
  EXPECT_EQ(key(retryDefinition(retry, failed)), key(uniform)) << "every muscle at x0.25";
  failed.muscles[1].failure = "*ERROR: too many cutbacks";
  EXPECT_EQ(key(retryDefinition(definition, failed)), key(uniform)) << "both failed";
}

TEST_F(RetryPerMuscle, SolvesAgainOnlyTheMuscleCcxFailedAndTakesTheOtherAsItWas) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  ASSERT_EQ(prepared.muscles.size(), 2u);
  const CalculixDefinition definition = sceneDefinition(scene, options);
  const CalculixSolution failed = failedSolve(definition);
  ASSERT_EQ(runs(), (std::vector<std::string>{"muscle0", "muscle1"}));
  ASSERT_EQ(failed.poseFailures[0], "muscle beside: *ERROR: increments too coarse for muscle1");
  ASSERT_EQ(failed.muscles.size(), 2u) << "a failed solve keeps its muscles' parts";
  ASSERT_TRUE(failed.muscles[0].solvedEveryStep()) << failed.muscles[0].failure;
  const CalculixDefinition retry = retryDefinition(definition, failed);
  const std::string retryKey = referenceCacheKey(scene, prepared, retry, {});
  const std::vector<NamedReferenceCell> cells = referenceCells(scene, prepared, options);
  ASSERT_EQ(cells.size(), 2u);
  for (const NamedReferenceCell& cell : cells) EXPECT_EQ(cell.key, retryKey);
  EXPECT_TRUE(cells[0].stored) << "kept from the failed solve: nothing to solve";
  EXPECT_FALSE(cells[1].stored) << "the muscle ccx failed: its retry is to solve";

  // As a batch engine solves the cells left to solve, then a run merges them from the cache.
  EXPECT_TRUE(cachedCalculixMuscle(scene, prepared, cells[1].cell.definition, cells[1].cell.cut,
                                   options.cacheDir, 1, {}, {}));
  EXPECT_EQ(runs(), std::vector<std::string>{"muscle1"}) << "only the muscle ccx failed";
  options.cachedOnly = true;
  const Reference reference = computeReference(scene, prepared, options);
  EXPECT_FALSE(reference.missing) << "merged with the muscle kept, without ccx";
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "runs.log"));
  for (const char* file : {"muscle0.inp", "muscle0.dat", "muscle1.inp", "muscle1.dat"})
    EXPECT_TRUE(std::filesystem::exists(options.cacheDir + "/" + retryKey + "/" + file)) << file;
  EXPECT_EQ(reference.key, retryKey);
  EXPECT_EQ(reference.increments,
            "x0.25 for beside only (" + prepared.muscles[0]->name + " at x1)");
  EXPECT_NE(reference.description.find("retried at increments x0.25 for beside only"),
            std::string::npos)
      << reference.description;
  const CalculixSolution& mixed = reference.solution;
  ASSERT_EQ(mixed.solvedPoses(), 2) << mixed.poseFailures[0] << mixed.poseFailures[1];
  ASSERT_FALSE(mixed.returnSurface.empty()) << mixed.returnFailure;
  EXPECT_TRUE(mixed.muscles.empty()) << "nothing failed: no parts kept";

  CalculixDefinition uniform = definition;
  uniform.incrementScale *= kFinerIncrements;
  const CalculixSolution whole =
      cachedCalculixReference(scene, prepared, uniform, {}, options.cacheDir, {}, {}, nullptr);
  EXPECT_EQ(runs(), (std::vector<std::string>{"muscle0", "muscle1"})) << "its own key";
  ASSERT_EQ(whole.solvedPoses(), 2);
  const std::vector<std::vector<btVector3>>& kept = failed.muscles[0].stepSurfaces;
  for (size_t p = 0; p < 2; ++p) {
    EXPECT_EQ(muscleVertices(prepared, mixed.poseSurfaces[p], 1),
              muscleVertices(prepared, whole.poseSurfaces[p], 1))
        << "the muscle solved again, as the whole retry solves it: pose " << p;
    EXPECT_EQ(muscleVertices(prepared, mixed.poseSurfaces[p], 0), kept[p])
        << "the muscle kept, as the failed solve gave it: pose " << p;
  }
  EXPECT_EQ(muscleVertices(prepared, mixed.returnSurface, 1),
            muscleVertices(prepared, whole.returnSurface, 1));
  EXPECT_EQ(muscleVertices(prepared, mixed.returnSurface, 0), kept.back());
  EXPECT_EQ(mixed.nodes, whole.nodes);
  EXPECT_LT(mixed.increments, whole.increments) << "the muscle kept took the coarser ones";
}

TEST_F(RetryPerMuscle, ASolveStoredWithoutItsMusclesPartsReadsThemFromItsCcxFiles) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  const CalculixDefinition definition = sceneDefinition(scene, options);
  const CalculixSolution failed = failedSolve(definition);
  ASSERT_EQ(failed.muscles.size(), 2u);
  const std::string stored =
      options.cacheDir + "/" + referenceCacheKey(scene, prepared, definition, {}) + "/surfaces.bin";
  const auto storedWithoutParts = [&] {  // as a solve stored before they were kept
    CalculixSolution old = failed;
    old.muscles.clear();
    saveSolution(stored, old);
    CalculixSolution back;
    EXPECT_TRUE(loadSolution(stored, back));
    return back;
  };
  CalculixSolution solution = storedWithoutParts();
  EXPECT_TRUE(retryDefinition(definition, solution).muscleIncrementScales.empty())
      << "without parts: retried whole";
  ASSERT_TRUE(recoverCalculixParts(scene, prepared, definition, {}, options.cacheDir, solution));
  ASSERT_EQ(solution.muscles.size(), 2u);
  EXPECT_EQ(solution.muscles[0].stepSurfaces, failed.muscles[0].stepSurfaces);
  EXPECT_EQ(solution.muscles[0].increments, failed.muscles[0].increments);
  EXPECT_EQ(solution.muscles[0].nodes, failed.muscles[0].nodes);
  EXPECT_FALSE(solution.muscles[1].solvedEveryStep());
  EXPECT_EQ(readText(stored).substr(0, 8), "FMSSREF2") << "its entry keeps them now";
  EXPECT_FALSE(recoverCalculixParts(scene, prepared, definition, {}, options.cacheDir, solution))
      << "kept already";
  const std::vector<NamedReferenceCell> cells = referenceCells(scene, prepared, options);
  ASSERT_EQ(cells.size(), 2u);
  EXPECT_TRUE(cells[0].stored && !cells[1].stored) << "only the muscle ccx failed to solve";
  EXPECT_EQ(runs(), (std::vector<std::string>{"muscle0", "muscle1"})) << "ccx ran only at first";
  // A retry of every muscle stored already (solved before retries kept muscles) is taken.
  const CalculixDefinition whole = retryDefinition(definition, CalculixSolution{});
  const std::string wholeKey = referenceCacheKey(scene, prepared, whole, {});
  std::filesystem::create_directories(options.cacheDir + "/" + wholeKey);
  saveSolution(options.cacheDir + "/" + wholeKey + "/surfaces.bin", failed);
  EXPECT_EQ(referenceCells(scene, prepared, options)[0].key, wholeKey);
  std::filesystem::remove_all(options.cacheDir + "/" + wholeKey);

  // A .inp that is not what the scene gives now: its files are not read as its parts.
  std::ofstream(options.cacheDir + "/" + cells[0].retryOf + "/muscle0.inp", std::ios::app)
      << "** changed\n";
  solution = storedWithoutParts();
  EXPECT_FALSE(recoverCalculixParts(scene, prepared, definition, {}, options.cacheDir, solution));
  EXPECT_TRUE(solution.muscles.empty());
}

TEST_F(RetryPerMuscle, AMuscleKeptFromAShippedFailedSolveBringsNoFilesItDoesNotHave) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  const CalculixDefinition definition = sceneDefinition(scene, options);
  const CalculixSolution failed = failedSolve(definition);
  ASSERT_EQ(runs(), (std::vector<std::string>{"muscle0", "muscle1"}));
  // Another machine: the failed solve shipped, its cache empty.
  const std::filesystem::path shipped = dir.path() / "shipped";
  std::filesystem::create_directories(shipped);
  shipSolution(
      (shipped / (referenceCacheKey(scene, prepared, definition, {}) + ".ref.gz")).string(),
      failed);
  setenv("FIBREMSS_REFERENCES", shipped.c_str(), 1);
  options.cacheDir = (dir.path() / "empty").string();
  const std::vector<NamedReferenceCell> cells = referenceCells(scene, prepared, options);
  ASSERT_EQ(cells.size(), 2u);
  EXPECT_TRUE(cells[0].stored) << "kept from the shipped failed solve";
  EXPECT_TRUE(cachedCalculixMuscle(scene, prepared, cells[1].cell.definition, cells[1].cell.cut,
                                   options.cacheDir, 1, {}, {}));
  EXPECT_EQ(runs(), std::vector<std::string>{"muscle1"});
  options.cachedOnly = true;
  const Reference reference = computeReference(scene, prepared, options);
  unsetenv("FIBREMSS_REFERENCES");
  ASSERT_FALSE(reference.missing);
  EXPECT_EQ(reference.key, cells[1].key);
  ASSERT_EQ(reference.solution.solvedPoses(), 2);
  EXPECT_EQ(reference.solution.inputFiles.size(), 1u) << "the muscle solved here";
  for (const std::string& file : reference.solution.inputFiles)
    EXPECT_TRUE(std::filesystem::exists(file)) << file << ": named, not there";
}

TEST(CalculixRun, ASphereBetweenClosingPlatesTouchesThemOverHertzsRadius) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("ccx_hertz_test");
  const LoadedScene scene = loadScene(coarseSpherePlanes(dir.path()), {"resolution=12"});
  ASSERT_EQ(scene.poseCount, 2);
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  CalculixDefinition definition;
  definition.returnToRest = false;
  // Held by its symmetry alone: no node is attached to a plate.
  const CalculixSolution solution =
      solveCalculixReference(scene, prepared, definition, {}, (dir.path() / "ccx").string());
  EXPECT_EQ(solution.prescribedNodes, 0u);
  ASSERT_EQ(solution.solvedPoses(), 2) << solution.poseFailures[1];
  const ContactPose contact =
      measureContact(scene, prepared.muscles[0]->restSurface, solution.poseSurfaces[1], 1);
  EXPECT_NEAR(contact.exactRadiusMm, std::sqrt(30.0), 1e-3);  // √(Rδ), R = 30 mm, δ = 1 mm
  // ~2 mm edges read a flat patch of this size within 16 % (a constructed one, analytic_test
  // at this level); the plates' plain cut, √(2Rδ − δ²) = 7.7 mm, is 41 % over Hertz's.
  EXPECT_NEAR(contact.radiusMm, contact.exactRadiusMm, 0.2 * contact.exactRadiusMm);
  RecordProperty("contact_radius_mm", std::to_string(contact.radiusMm));
  // The centre stays (held), and the sphere stays centred between the plates: its top and
  // bottom move in alike.
  const std::vector<btVector3>& surface = solution.poseSurfaces[1];
  btScalar top = -1, bottom = 1;
  for (const btVector3& p : surface) {
    top = std::max(top, p.y());
    bottom = std::min(bottom, p.y());
  }
  EXPECT_NEAR(top + bottom, 0, 2e-5) << "symmetric within 20 µm";
  EXPECT_LT(top, 0.03f - 0.0009f) << "pushed in by the plate (1 mm)";
}

/// The coarse fusiform's reference at resolution 8 with its gates, solved once for the suite
/// by `fibremss reference` into a cache its tests share (one process: tests/CMakeLists.txt).
class CoarseReference : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TemporaryDirectory("coarse_reference_test");
    scene_ = new std::string(coarseFusiform(dir_->path()));
  }
  static void TearDownTestSuite() {
    delete scene_;
    delete dir_;
  }
  /// `fibremss COMMAND` of the scene at resolution 8 with the suite's cache, into dir/`out`
  /// (its stderr with its output).
  static testing::ProcessResult run(const std::string& command, const std::string& out) {
    return testing::runProcess(std::string(FIBREMSS_CLI) + " " + command + " " + *scene_ +
                               " --set resolution=8 --cache " + (dir() / "cache").string() +
                               " --out " + (dir() / out).string() + " 2>&1");
  }
  /// The first `fibremss reference` into dir/out: it solved the reference and its gates.
  static const testing::ProcessResult& solved() {
    static const testing::ProcessResult first = run("reference", "out");
    return first;
  }
  /// The suite's own directory.
  static const std::filesystem::path& dir() { return dir_->path(); }
  static TemporaryDirectory* dir_;
  static std::string* scene_;
};
TemporaryDirectory* CoarseReference::dir_ = nullptr;
std::string* CoarseReference::scene_ = nullptr;

TEST_F(CoarseReference, TheReferenceCommandSolvesCachesAndGatesIt) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  const testing::ProcessResult& first = solved();
  ASSERT_EQ(first.exitCode, 0) << first.output;
  EXPECT_NE(first.output.find("poses solved: 3/3\n"), std::string::npos) << first.output;
  EXPECT_NE(first.output.find("gate: return to rest"), std::string::npos) << first.output;
  const nlohmann::json reference = nlohmann::json::parse(readText(dir() / "out/reference.json"));
  EXPECT_FALSE(reference["from_cache"].get<bool>());
  const nlohmann::json& gates = reference["gates"];
  EXPECT_LT(gates["return_mm"].get<double>(), kReturnGateMm) << "no contact: back at rest";
  EXPECT_GT(gates["refinement_mm"].get<double>(), 0) << "C3D10 differs from C3D4";
  EXPECT_EQ(gates["increments_scale"].get<double>(), kIncrementGateFactor);
  EXPECT_EQ(gates["increments_poses"].get<int>(), 3);
  // Frictionless contact with finite sliding and no contact at all leave a path-independent
  // hyperelastic equilibrium: halving the increments changes it by ccx's tolerance alone.
  EXPECT_LT(gates["increments_mm"].get<double>(), 1e-2);
  EXPECT_NE(first.output.find("gate: increments halved (x0.5 of the default"), std::string::npos)
      << first.output;
  // The coarse mesh's nodes near the bars are the same within 2, 4 and 6 mm: 0 is possible.
  EXPECT_GE(gates["attachment_low_mm"].get<double>(), 0);
  EXPECT_GE(gates["attachment_high_mm"].get<double>(), 0);
  EXPECT_TRUE(std::filesystem::exists(dir() / "out/inp/muscle0.inp"));
  EXPECT_GT(reference["prescribed_nodes"].get<int>(), 0);

  const auto second = run("reference", "out");
  ASSERT_EQ(second.exitCode, 0) << second.output;
  EXPECT_NE(second.output.find("(from the cache)"), std::string::npos) << second.output;
  const nlohmann::json again = nlohmann::json::parse(readText(dir() / "out/reference.json"));
  EXPECT_EQ(again["gates"], gates) << "the cache gives the same reference";
}

TEST_F(CoarseReference, CompareReportsItsGatesAndRmsToIt) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  ASSERT_EQ(solved().exitCode, 0) << solved().output;
  const auto result = run("compare --methods fibremss,btsoftbody --no-fronts", "compare");
  ASSERT_EQ(result.exitCode, 0) << result.output;
  EXPECT_NE(result.output.find("reference gate: return to rest"), std::string::npos)
      << result.output;
  const nlohmann::json summary = nlohmann::json::parse(readText(dir() / "compare/summary.json"));
  ASSERT_EQ(summary["runs"].size(), 3u);
  EXPECT_EQ(summary["runs"][0]["method"], "calculix");
  for (int r = 1; r < 3; ++r) {
    const nlohmann::json& run = summary["runs"][r];
    SCOPED_TRACE(run["method"].get<std::string>());
    EXPECT_GT(run["rms_to_reference_mm"].get<double>(), 0);
    EXPECT_GT(run["shape_rms_to_reference_mm"].get<double>(), 0);
    EXPECT_LE(run["shape_rms_to_reference_mm"].get<double>(),
              run["rms_to_reference_mm"].get<double>() + 1e-9)
        << "the nearest surface point is never farther than the corresponding vertex";
    EXPECT_EQ(run["worst_muscle"], "fusiform");
    EXPECT_EQ(run["rms_to_reference_per_pose_mm"].size(), 3u);
    ASSERT_EQ(run["muscles_to_reference"].size(), 1u);
    const nlohmann::json& muscle = run["muscles_to_reference"][0];
    EXPECT_EQ(muscle["muscle"], "fusiform");
    EXPECT_EQ(muscle["per_pose_mm"], run["rms_to_reference_per_pose_mm"]) << "one muscle: all";
    EXPECT_NEAR(muscle["rms_mm"].get<double>(), run["worst_muscle_rms_mm"].get<double>(), 1e-9);
  }
  EXPECT_NE(readText(dir() / "compare/report.md").find("## RMS to the reference per pose"),
            std::string::npos);
  const nlohmann::json& gates = summary["reference"]["gates"];
  EXPECT_TRUE(gates["spread_mm"].is_number());
  EXPECT_TRUE(gates["increments_mm"].is_number());
  EXPECT_NE(result.output.find("reference gate: increments halved"), std::string::npos)
      << result.output;
  const std::string report = readText(dir() / "compare/report.md");
  EXPECT_NE(report.find("## Reference"), std::string::npos);
  EXPECT_NE(report.find("- increments halved (x0.5 of the default 2.5 deg / 1 mm): moves it"),
            std::string::npos)
      << report;
  EXPECT_NE(report.find(gates["passed"].get<bool>() ? "**Ranking**" : "**No ranking**"),
            std::string::npos)
      << report;
  EXPECT_EQ(report.find("nan |"), std::string::npos) << "tables print — for what does not apply";
}

TEST(ReferenceCommand, AReferenceCcxStoppedAfterItsRetryRanksOverThePosesBeforeTheStop) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("stopped_reference_test");
  const std::string path = shortFusiform(dir.path());
  const LoadedScene scene = loadScene(path, {"resolution=6"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  ReferenceOptions options;
  options.cacheDir = (dir.path() / "cache").string();
  CalculixDefinition reference = sceneDefinition(scene, options), retry = reference;
  retry.incrementScale *= kFinerIncrements;
  // ccx stands in stopping at pose 2 of 3 at both increments: the retry's poses 0-1 as ccx
  // solves them, the default's failures alone (as thigh13's are shipped).
  CalculixDefinition limited = retry;
  limited.poseLimit = 2;
  limited.returnToRest = false;
  const ContinuumCut cut = cutOf(scene);
  CalculixSolution stopped =
      solveCalculixReference(scene, prepared, limited, cut, (dir.path() / "solve").string());
  ASSERT_EQ(stopped.solvedPoses(), 2) << stopped.poseFailures[1];
  stopped.poseFailures[2] = stopped.returnFailure =
      "muscle fusiform: *ERROR: increment size smaller than minimum";
  CalculixSolution failed = stopped;
  failed.poseSurfaces.assign(failed.poseSurfaces.size(), {});
  for (const auto& [definition, solution] : {std::pair{&reference, &failed}, {&retry, &stopped}}) {
    const std::string entry =
        options.cacheDir + "/" + referenceCacheKey(scene, prepared, *definition, cut);
    std::filesystem::create_directories(entry);
    saveSolution(entry + "/surfaces.bin", *solution);
  }
  // The gates are solved over poses 0-1; btSoftBody alone: the spread is its RMS.
  const testing::ProcessResult result =
      testing::runProcess(std::string(FIBREMSS_CLI) + " compare " + path +
                          " --set resolution=6 --methods btsoftbody --no-fronts --cache " +
                          options.cacheDir + " --out " + (dir.path() / "out").string() + " 2>&1");
  ASSERT_EQ(result.exitCode, 0) << result.output;
  const nlohmann::json summary = nlohmann::json::parse(readText(dir.path() / "out/summary.json"));
  const nlohmann::json& gates = summary["reference"]["gates"];
  EXPECT_EQ(gates["failures"], "") << "the stop is no failure";
  EXPECT_EQ(gates["stopped"], stopped.poseFailures[2]);
  EXPECT_NE(
      gates["return_not_applicable"].get<std::string>().find("stopped the reference at pose 2"),
      std::string::npos);
  for (const char* poses : {"solved_poses", "refinement_poses", "increments_poses",
                            "attachment_low_poses", "attachment_high_poses"})
    EXPECT_EQ(gates[poses], 2) << poses;
  const nlohmann::json& run = summary["runs"][1];
  ASSERT_EQ(run["method"], "btsoftbody");
  EXPECT_EQ(run["poses"], 3);
  EXPECT_EQ(run["rms_to_reference_poses"], 2);
  EXPECT_EQ(run["rms_to_reference_per_pose_mm"].size(), 2u);
  EXPECT_EQ(run["muscles_to_reference"][0]["per_pose_mm"].size(), 2u);
  // The gates decide, over poses 0-1: with one method the spread is its RMS, and the C3D10 and
  // increment gates pass below a third of it (at resolution 6, C3D10 moves it more).
  const double third = run["rms_to_reference_mm"].get<double>() / 3;
  const bool passed =
      gates["refinement_mm"].get<double>() < third && gates["increments_mm"].get<double>() < third;
  EXPECT_EQ(gates["passed"], passed);
  EXPECT_EQ(result.output.find("the reference fails a gate (") != std::string::npos, !passed)
      << "a gate, not ccx's stop, blocks it: " << result.output;
  EXPECT_EQ(gates["ranked_poses"], passed ? 2 : 0);
  const std::string report = readText(dir.path() / "out/report.md");
  const std::string ranked =
      "ranked over poses 0\u20131 of 3: ccx did not solve pose 2 (muscle fusiform: *ERROR: "
      "increment size smaller than minimum) or later";
  EXPECT_EQ(report.find(ranked) < report.find("## Reference"), passed) << report;
  EXPECT_EQ(result.output.find("the methods are " + ranked) != std::string::npos, passed)
      << result.output;
  EXPECT_EQ(report.find("ccx did not solve every pose"), std::string::npos) << report;
  EXPECT_NE(report.find("Poses solved: 2/3 (1 not solved: ccx stopped at pose 2, see below)"),
            std::string::npos)
      << report;
}

/// Both muscles' rest surfaces, the first moved `a` mm along x, the second `b` mm.
std::vector<btVector3> shiftedRest(const PreparedScene& prepared, double a, double b) {
  std::vector<btVector3> surface;
  for (size_t m = 0; m < prepared.muscles.size(); ++m)
    for (const btVector3& vertex : prepared.muscles[m]->restSurface.vertices)
      surface.push_back(vertex + btVector3(btScalar(1e-3 * (m == 0 ? a : b)), 0, 0));
  return surface;
}

TEST(ReferenceGates, AJudgedGateStoppingOneMuscleOfTwoKeepsTheOthersPosesInEveryRms) {
  REQUIRE_PROGRAM("ccx");
  TemporaryDirectory dir("limited_muscle_test");
  nlohmann::json json = nlohmann::json::parse(readText(shortFusiform(dir.path())));
  addBeside(json);
  std::ofstream(dir.path() / "twice.json") << json.dump(2);
  const LoadedScene scene = loadScene((dir.path() / "twice.json").string(), {"resolution=6"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  ASSERT_EQ(prepared.muscles.size(), 2u);
  ASSERT_EQ(scene.poseCount, 3);
  ReferenceOptions options;
  options.cacheDir = (dir.path() / "cache").string();
  options.cachedOnly = true;
  // Solutions stand in for ccx's: the reference at rest in every pose; increments halved moves
  // the first muscle 1 mm and `beside` 3 mm, and stops `beside` at pose 2 (its retry not
  // computed) while the first muscle solves every pose (its part); one level finer moves both
  // 0.5 mm.
  CalculixSolution reference, halved, finer;
  reference.poseSurfaces.assign(3, shiftedRest(prepared, 0, 0));
  reference.poseFailures.assign(3, "");
  reference.returnSurface = shiftedRest(prepared, 0, 0);
  halved.poseSurfaces = {shiftedRest(prepared, 1, 3), shiftedRest(prepared, 1, 3), {}};
  halved.poseFailures = {"", "", "muscle beside: *ERROR: increment size smaller than minimum"};
  halved.muscles.resize(2);
  halved.muscles[0].stepSurfaces.assign(3,
                                        muscleVertices(prepared, shiftedRest(prepared, 1, 3), 0));
  halved.muscles[1].failure = "*ERROR: increment size smaller than minimum";
  finer.poseSurfaces.assign(3, shiftedRest(prepared, 0.5, 0.5));
  finer.poseFailures.assign(3, "");
  const CalculixDefinition definition = sceneDefinition(scene, options);
  const GateDefinitions gates = gateDefinitions(definition, definition, gatePoseLimit(reference));
  for (const auto& [solve, solution] :
       {std::pair{&definition, &reference}, {&gates.increments, &halved}, {&gates.finer, &finer}}) {
    const std::string entry =
        options.cacheDir + "/" + referenceCacheKey(scene, prepared, *solve, cutOf(scene));
    std::filesystem::create_directories(entry);
    saveSolution(entry + "/surfaces.bin", *solution);
  }
  const Reference computed = computeReference(scene, prepared, options);
  ASSERT_FALSE(computed.missing);
  const ReferenceGates& g = computed.gates;
  EXPECT_EQ(g.gatedPoses, -1) << "the first muscle's poses are not stopped";
  ASSERT_EQ(g.limited.size(), 1u);
  EXPECT_EQ(g.limited[0].name, "beside");
  EXPECT_EQ(g.limited[0].poses, 2);
  EXPECT_EQ(g.limited[0].solve, "increments halved");
  EXPECT_NE(g.limited[0].why.find("its retry at finer increments not computed"), std::string::npos);
  EXPECT_EQ(g.failures, "");
  // The gates' RMS: the first muscle over poses 0-2, `beside` over 0-1.
  const double first = double(prepared.muscles[0]->restSurface.vertices.size()),
               second = double(prepared.muscles[1]->restSurface.vertices.size());
  EXPECT_EQ(g.incrementsPoses, 3);
  EXPECT_NEAR(g.incrementsMm, std::sqrt((3 * first + 2 * second * 9) / (3 * first + 2 * second)),
              1e-3);
  EXPECT_EQ(g.refinementPoses, 3);
  EXPECT_NEAR(g.refinementMm, 0.5, 1e-3);

  // A run's RMS to the reference leaves `beside` out from pose 2 on: there it is 10 mm off.
  std::vector<RunMetrics> runs{computed.metrics, RunMetrics{}};
  runs[1].method = "fibremss";
  runs[1].poseSurfaces = {shiftedRest(prepared, 1, 0), shiftedRest(prepared, 1, 0),
                          shiftedRest(prepared, 1, 10)};
  fillRms(runs);
  fillReferenceShapes(runs, prepared);
  const RunMetrics& run = runs[1];
  EXPECT_EQ(run.rmsToReferencePoses, 3);
  EXPECT_NEAR(run.rmsToReferenceMm, std::sqrt(3 * first / (3 * first + 2 * second)), 1e-3);
  ASSERT_EQ(run.rmsToReferencePerPoseMm.size(), 3u);
  EXPECT_NEAR(run.rmsToReferencePerPoseMm[2], 1.0, 1e-3) << "the first muscle's alone";
  ASSERT_EQ(run.musclesToReference.size(), 2u);
  EXPECT_EQ(run.musclesToReference[0].perPoseMm.size(), 3u);
  EXPECT_EQ(run.musclesToReference[1].perPoseMm.size(), 2u);
  EXPECT_NEAR(run.musclesToReference[1].rmsMm, 0.0, 1e-3);
  EXPECT_EQ(run.worstMuscle, prepared.muscles[0]->name);
}

TEST(ReferenceCommand, ListsItsCellsAndRefusesACellItDoesNotHave) {
  REQUIRE_PROGRAM("ccx");
  TemporaryDirectory dir("reference_cells_command_test");
  const std::string command = std::string(FIBREMSS_CLI) + " reference " +
                              coarseFusiform(dir.path()) + " --set resolution=8 --cache " +
                              (dir.path() / "cache").string();
  const auto list = testing::runProcess(command + " --cells 2>/dev/null");
  ASSERT_EQ(list.exitCode, 0) << list.output;
  std::istringstream lines(list.output);
  std::vector<std::string> solves;
  for (std::string line; std::getline(lines, line);) {
    EXPECT_NE(line.find("\tfusiform\t"), std::string::npos) << line;
    EXPECT_NE(line.find("\tto solve"), std::string::npos) << line;
    solves.push_back(line.substr(0, line.find("\tfusiform")));
  }
  EXPECT_EQ(solves, (std::vector<std::string>{"0\treference", "1\tattachment distance x0.5",
                                              "2\tattachment distance x1.5", "3\tincrements halved",
                                              "4\tone level finer"}));
  const auto beyond = testing::runProcess(command + " --cell 5 2>&1");
  EXPECT_EQ(beyond.exitCode, 2) << beyond.output;
  EXPECT_NE(beyond.output.find("expected a cell number below 5"), std::string::npos)
      << beyond.output;
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "cache")) << "nothing solved";
}

/// A built-in scene with a coarser tube surface (slices × sections vertices).
std::string coarseTube(const std::filesystem::path& dir, const char* name, int slices,
                       int sections) {
  nlohmann::json scene = nlohmann::json::parse(exportBuiltInScene(name));
  nlohmann::json& generator = scene["muscles"][0]["surface"]["generator"];
  generator["slices"] = slices;
  generator["sections"] = sections;
  const std::filesystem::path path = dir / (std::string("coarse-") + name + ".json");
  std::ofstream(path) << scene.dump(2);
  return path.string();
}

/// `fibremss reference SCENE --no-gates` into dir/cache and dir/out.
testing::ProcessResult referenceWithoutGates(const std::filesystem::path& dir,
                                             const std::string& scene) {
  return testing::runProcess(std::string(FIBREMSS_CLI) + " reference " + scene +
                             " --set resolution=8 --no-gates --cache " + (dir / "cache").string() +
                             " --out " + (dir / "out").string() + " 2>&1");
}

TEST(ReferenceCommand, PinchsPosesPastTheCutAreExcludedNotFailed) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("reference_cut_test");
  const auto result = referenceWithoutGates(dir.path(), coarseTube(dir.path(), "pinch", 16, 12));
  ASSERT_EQ(result.exitCode, 0) << result.output;
  EXPECT_NE(result.output.find("poses solved: 2/7"), std::string::npos) << result.output;
  EXPECT_EQ(result.output.find("gate: ccx did not solve"), std::string::npos) << result.output;
  EXPECT_NE(readText(dir.path() / "out/inp/muscle0.inp").find("NODE TO SURFACE, SMALL SLIDING"),
            std::string::npos)
      << "pinch's reference tracks its blades' contact with small sliding";
  const nlohmann::json reference =
      nlohmann::json::parse(readText(dir.path() / "out/reference.json"));
  for (int p = 0; p < 7; ++p) {
    SCOPED_TRACE(p);
    const nlohmann::json& pose = reference["poses"][p];
    EXPECT_EQ(pose["solved"].get<bool>(), p < 2);
    EXPECT_EQ(pose["failure"], "") << "no pose is a ccx failure";
    EXPECT_EQ(pose["excluded"].get<std::string>().empty(), p < 2);
  }
  const nlohmann::json& gates = reference["gates"];
  EXPECT_EQ(gates["failures"], "");
  EXPECT_NE(gates["excluded"].get<std::string>().find("poses 2 to 6 of 7: no continuum"),
            std::string::npos)
      << gates["excluded"];
  // The motion ends at pose 6, not at rest: the steps back from pose 1 are the reference's own.
  // ccx 2.20 stops on them (a NaN as the blades release the muscle): the gate does not apply
  // and blocks nothing. Solved, it must pass.
  if (reference["return_failure"] == "") {
    EXPECT_LT(gates["return_mm"].get<double>(), kReturnGateMm);
  } else {
    EXPECT_NE(gates["return_not_applicable"].get<std::string>().find("does not return to rest"),
              std::string::npos)
        << gates;
    EXPECT_NE(result.output.find("does not apply, not blocking"), std::string::npos);
  }
}

TEST(ReferenceCommand, ATwistReturnsToRestRetracingItsPoses) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("reference_twist_test");
  const auto result =
      referenceWithoutGates(dir.path(), coarseTube(dir.path(), "cylinder-twist", 12, 12));
  ASSERT_EQ(result.exitCode, 0) << result.output;
  const nlohmann::json reference =
      nlohmann::json::parse(readText(dir.path() / "out/reference.json"));
  // Straight back from 180° in one step, ccx moves the turned end's nodes through the axis.
  EXPECT_EQ(reference["return_failure"], "");
  EXPECT_LT(reference["gates"]["return_mm"].get<double>(), kReturnGateMm);
  const std::string input = readText(dir.path() / "out/inp/muscle0.inp");
  size_t steps = 0;
  for (size_t at = input.find("*STEP"); at != std::string::npos; at = input.find("*STEP", at + 1))
    ++steps;
  EXPECT_EQ(steps, 5u + 4u) << "0°, 45°, 90°, 135°, 180°, then 135°, 90°, 45° and rest";
  // Each 45° step's increments turn the end by 2.5° at most ("initial, period, min, max").
  std::istringstream lines(input);
  std::vector<double> largest;
  for (std::string line; std::getline(lines, line);) {
    if (line != "*STATIC") continue;
    std::getline(lines, line);
    largest.push_back(std::stod(line.substr(line.rfind(',') + 1)));
  }
  ASSERT_EQ(largest.size(), steps);
  EXPECT_EQ(largest[0], 1) << "pose 0 is the rest pose: nothing turns";
  for (size_t s = 1; s < steps; ++s) EXPECT_NEAR(largest[s], 2.5 / 45, 1e-6) << s;
}

TEST(ReferenceCommand, ACcxRunOverItsMemoryLimitFailsEveryPoseNamingItAndIsSolvedAgain) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("reference_memory_test");
  const std::string command =
      std::string(FIBREMSS_CLI) + " reference " + coarseFusiform(dir.path()) +
      " --set resolution=8 --no-gates --cache " + (dir.path() / "cache").string() + " --out " +
      (dir.path() / "out").string() + " 2>&1";
  // 0.1 GiB: ccx starts, and fails allocating its matrix structure.
  const auto limited = testing::runProcess(command + " --ccx-memory 0.1");
  ASSERT_EQ(limited.exitCode, 0) << limited.output;
  EXPECT_NE(limited.output.find("poses solved: 0/3\n"), std::string::npos) << limited.output;
  EXPECT_NE(limited.output.find("reference pose 0: muscle fusiform: *ERROR in u_calloc: error "
                                "allocating memory (ccx's memory limit is 0.1 GiB"),
            std::string::npos)
      << limited.output;
  const auto enough = testing::runProcess(command);
  ASSERT_EQ(enough.exitCode, 0) << enough.output;
  EXPECT_NE(enough.output.find("poses solved: 3/3\n"), std::string::npos)
      << "a failure at the limit is not kept in the cache\n"
      << enough.output;
}

TEST(ReferenceCommand, TwoProcessesSolvingOneKeyAtOnceBothGetTheWholeReference) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("reference_race_test");
  const std::string scene = coarseFusiform(dir.path());
  const std::filesystem::path cache = dir.path() / "cache";
  auto command = [&](const char* out) {
    return std::string(FIBREMSS_CLI) + " reference " + scene +
           " --set resolution=8 --no-gates --cache " + cache.string() + " --out " +
           (dir.path() / out).string() + " > " + (dir.path() / out).string() + ".log 2>&1";
  };
  // Sharing ccx's files, one process read the other's half-written results (a return step
  // reported failed that ccx had solved). While they run, no entry may be visible before it
  // is whole (surfaces.bin in it): each solves in its own directory.
  std::atomic<bool> done{false};
  testing::ProcessResult both;
  std::thread runner([&] {
    std::string script = "(";
    script += command("a") + ") & (" + command("b") + "); status=$?; wait $! && exit $status";
    both = testing::runProcess(script);
    done = true;
  });
  bool sawOwnDirectory = false, sawPartialEntry = false;
  while (!done) {
    std::error_code error;
    for (std::filesystem::directory_iterator it(cache, error), end; !error && it != end;
         it.increment(error)) {
      const std::string name = it->path().filename().string();
      if (name.find(".solving-") != std::string::npos)
        sawOwnDirectory = true;
      else if (!std::filesystem::exists(it->path() / "surfaces.bin", error))
        sawPartialEntry = true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  runner.join();
  ASSERT_EQ(both.exitCode, 0) << readText(dir.path() / "a.log") << readText(dir.path() / "b.log");
  EXPECT_TRUE(sawOwnDirectory);
  EXPECT_FALSE(sawPartialEntry) << "an entry was visible while being solved";
  for (const char* out : {"a", "b"}) {
    SCOPED_TRACE(out);
    const nlohmann::json reference =
        nlohmann::json::parse(readText(dir.path() / out / "reference.json"));
    for (const auto& pose : reference["poses"]) EXPECT_TRUE(pose["solved"].get<bool>());
    EXPECT_EQ(reference["return_failure"], "");
    EXPECT_LT(reference["gates"]["return_mm"].get<double>(), kReturnGateMm);
  }
  int entries = 0;
  for (const auto& entry : std::filesystem::directory_iterator(cache)) {
    EXPECT_EQ(entry.path().filename().string().find(".solving-"), std::string::npos)
        << "no solve's own directory is left";
    EXPECT_TRUE(std::filesystem::exists(entry.path() / "surfaces.bin"));
    ++entries;
  }
  EXPECT_EQ(entries, 1);
}

// Ctrl-C while ccx solves: exit 130, a plain message, nothing written to --out and no solve's
// own directory left in the cache (the .inp files it would have copied went with it).
/// `fibremss reference` sent `signal` while ccx solves: it stops ccx, writes nothing to --out,
/// leaves no work directory in the cache and exits 128 + signal.
void expectAnInterruptedSolveWritesNothing(int signal) {
  TemporaryDirectory dir("reference_interrupt_test");
  const std::string scene = coarseFusiform(dir.path());
  const std::filesystem::path cache = dir.path() / "cache", out = dir.path() / "out";
  const std::string log = (dir.path() / "log").string();
  const pid_t child = fork();
  ASSERT_NE(child, -1);
  if (child == 0) {
    std::freopen(log.c_str(), "w", stderr);
    std::freopen("/dev/null", "w", stdout);
    execl(FIBREMSS_CLI, FIBREMSS_CLI, "reference", scene.c_str(), "--set", "resolution=8",
          "--no-gates", "--cache", cache.c_str(), "--out", out.c_str(),
          static_cast<char*>(nullptr));
    _exit(127);
  }
  // Wait for ccx's input in the solve's own directory: the signal then arrives during the solve.
  bool solving = false;
  for (int i = 0; i < 1200 && !solving; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    std::error_code error;
    for (std::filesystem::directory_iterator it(cache, error), end; !error && it != end;
         it.increment(error))
      solving |= it->path().filename().string().find(".solving-") != std::string::npos &&
                 std::filesystem::exists(it->path() / "muscle0.inp", error);
  }
  kill(child, signal);
  int status = 0;
  waitpid(child, &status, 0);
  ASSERT_TRUE(solving) << "no solve started within a minute: " << readText(log);
  ASSERT_TRUE(WIFEXITED(status)) << readText(log);
  EXPECT_EQ(WEXITSTATUS(status), 128 + signal) << readText(log);
  EXPECT_NE(readText(log).find("interrupted: nothing written"), std::string::npos) << readText(log);
  EXPECT_FALSE(std::filesystem::exists(out / "reference.json"));
  EXPECT_FALSE(std::filesystem::exists(out / "inp"));
  for (const auto& entry : std::filesystem::directory_iterator(cache))
    EXPECT_EQ(entry.path().filename().string().find(".solving-"), std::string::npos)
        << entry.path();
}

TEST(ReferenceCommand, AnInterruptedSolveWritesNothingAndExits130) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  expectAnInterruptedSolveWritesNothing(SIGINT);
}

TEST(ReferenceCommand, ATerminatedSolveStopsCcxWritesNothingAndExits143) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  expectAnInterruptedSolveWritesNothing(SIGTERM);
}

TEST(ReferenceCommand, ASolveThatFailsLeavesNoWorkInTheCacheAndNoResult) {
  REQUIRE_PROGRAM("ccx");
  TemporaryDirectory dir("reference_failure_test");
  const std::string scene = coarseFusiform(dir.path());
  const std::filesystem::path cache = dir.path() / "cache", out = dir.path() / "out";
  // ccx on the PATH and tetgen not: the solve fails meshing, inside its own work directory.
  const std::filesystem::path bin = dir.path() / "bin";
  std::filesystem::create_directories(bin);
  std::filesystem::create_symlink(testing::runProcess("command -v ccx | tr -d '\\n'").output,
                                  bin / "ccx");
  const testing::ProcessResult result =
      testing::runProcess("PATH=" + bin.string() + " " + FIBREMSS_CLI + " reference " + scene +
                          " --set resolution=8 --no-gates --cache " + cache.string() + " --out " +
                          out.string() + " 2>&1");
  EXPECT_NE(result.exitCode, 0) << result.output;
  EXPECT_NE(result.output.find("cannot run 'tetgen'"), std::string::npos) << result.output;
  EXPECT_FALSE(std::filesystem::exists(out / "reference.json"));
  ASSERT_TRUE(std::filesystem::is_directory(cache))
      << "the failure came after the cache's work began";
  for (const auto& entry : std::filesystem::directory_iterator(cache))
    EXPECT_EQ(entry.path().filename().string().find(".solving-"), std::string::npos)
        << entry.path() << " left in the cache";
}

/// `merged`'s failures, counts and surfaces are `whole`'s, the surfaces within a float's rounding.
void expectTheSameSolutionWithinFloats(const CalculixSolution& merged,
                                       const CalculixSolution& whole) {
  EXPECT_EQ(merged.poseFailures, whole.poseFailures);
  EXPECT_EQ(merged.nodes, whole.nodes);
  EXPECT_EQ(merged.increments, whole.increments);
  ASSERT_EQ(merged.poseSurfaces.size(), whole.poseSurfaces.size());
  for (size_t p = 0; p < whole.poseSurfaces.size(); ++p) {
    ASSERT_EQ(merged.poseSurfaces[p].size(), whole.poseSurfaces[p].size());
    EXPECT_LT(rmsDistanceMm(merged.poseSurfaces[p], whole.poseSurfaces[p]), 1e-4) << p;
  }
  ASSERT_EQ(merged.returnSurface.size(), whole.returnSurface.size());
  EXPECT_LT(rmsDistanceMm(merged.returnSurface, whole.returnSurface), 1e-4);
}

TEST(ShippedReference, IsCompressedFloatsAndReadsBackWithinTheirPrecision) {
  TemporaryDirectory dir("shipped_reference_test");
  CalculixSolution solution;
  solution.poseSurfaces.resize(3);
  for (int p = 0; p < 3; ++p)
    for (int i = 0; i < 2000; ++i)  // a smooth surface, as a muscle's
      solution.poseSurfaces[size_t(p)].emplace_back(
          0.01f * std::cos(0.01f * i), 0.01f * std::sin(0.01f * i), 1e-5f * i + 0.01f * p);
  solution.poseFailures = {"", "", ""};
  solution.returnSurface = solution.poseSurfaces[0];
  solution.nodes = 11;
  solution.increments = 9;
  solution.seconds = 2.5;
  solution.inputFiles = {"/another/machine/muscle0.inp"};
  solution.cut = {2, 1.5, "no continuum equilibrium"};
  const std::string shipped = (dir.path() / "k.ref.gz").string();
  const std::string cached = (dir.path() / "k.bin").string();
  shipSolution(shipped, solution);
  saveSolution(cached, solution);
  EXPECT_LT(std::filesystem::file_size(shipped), std::filesystem::file_size(cached) / 2)
      << "floats, compressed";
  CalculixSolution back;
  ASSERT_TRUE(loadShippedSolution(shipped, back));
  ASSERT_EQ(back.poseSurfaces.size(), 3u);
  expectTheSameSolutionWithinFloats(back, solution);
  EXPECT_EQ(back.nodes, 11u);
  EXPECT_EQ(back.increments, 9);
  EXPECT_EQ(back.seconds, 2.5);
  EXPECT_EQ(back.cut.pose, 2);
  EXPECT_EQ(back.cut.reason, solution.cut.reason);
  EXPECT_TRUE(back.inputFiles.empty()) << "another machine's files are not shipped";
  EXPECT_FALSE(loadShippedSolution((dir.path() / "absent.ref.gz").string(), back));
  EXPECT_THROW(loadShippedSolution(cached, back), InputError) << "not a shipped reference";
  std::filesystem::resize_file(shipped, std::filesystem::file_size(shipped) / 2);
  EXPECT_THROW(loadShippedSolution(shipped, back), InputError) << "truncated";
}

/// A muscle-like surface of `vertices` points [m], moved by `offset` [m] along a smooth field.
std::vector<btVector3> smoothSurface(int vertices, double phase, double offset) {
  std::vector<btVector3> surface;
  for (int i = 0; i < vertices; ++i)
    surface.emplace_back(btScalar(0.02 * std::cos(0.01 * i + phase) + offset * std::sin(0.03 * i)),
                         btScalar(0.02 * std::sin(0.01 * i + phase)),
                         btScalar(0.3 + 1e-4 * i + offset * std::cos(0.02 * i)));
  return surface;
}

std::vector<btVector3> joined(const std::vector<btVector3>& a, const std::vector<btVector3>& b) {
  std::vector<btVector3> both = a;
  both.insert(both.end(), b.begin(), b.end());
  return both;
}

TEST(ShippedReference, AGateIsStoredAgainstItsReferenceWithinHalfAQuantum) {
  TemporaryDirectory dir("shipped_gate_test");
  const std::string baseKey = "00000000000000ab";
  const std::string basePath = (dir.path() / (baseKey + ".ref.gz")).string();
  CalculixSolution reference;  // two muscles of 1 000 and 400 vertices, three poses
  for (int p = 0; p < 3; ++p) {
    reference.poseSurfaces.push_back(joined(smoothSurface(1000, p, 0), smoothSurface(400, -p, 0)));
    reference.poseFailures.push_back("");
  }
  shipSolution(basePath, reference);
  ShippedBase base{baseKey, {}, {1000, 400}};
  ASSERT_TRUE(loadShippedSolution(basePath, base.solution));

  CalculixSolution gate;  // poses 0-1 moved 0.4 mm, pose 2 by less than a quantum; a failed part
  const double moves[3] = {4e-4, 4e-4, 3e-9};
  for (int p = 0; p < 3; ++p) {
    gate.poseSurfaces.push_back(
        joined(smoothSurface(1000, p, moves[p]), smoothSurface(400, -p, moves[p])));
    gate.poseFailures.push_back("");
  }
  gate.muscles.resize(2);
  for (int p = 0; p < 3; ++p) gate.muscles[0].stepSurfaces.push_back(smoothSurface(1000, p, 2e-4));
  gate.muscles[1].failure = "*ERROR";
  gate.increments = 7;
  const std::string compact = (dir.path() / "gate.ref.gz").string();
  const std::string floats = (dir.path() / "floats.ref.gz").string();
  shipSolution(compact, gate, &base);
  shipSolution(floats, gate);
  EXPECT_LT(std::filesystem::file_size(compact), std::filesystem::file_size(floats) / 2)
      << "differences from the reference, not floats";

  CalculixSolution back, old;
  ASSERT_TRUE(loadShippedSolution(compact, back));
  ASSERT_TRUE(loadShippedSolution(floats, old)) << "a gate shipped as floats is still read";
  EXPECT_EQ(back.poseFailures, gate.poseFailures);
  EXPECT_EQ(back.increments, 7);
  EXPECT_EQ(back.returnSurface.size(), 0u);
  ASSERT_EQ(back.muscles.size(), 2u);
  EXPECT_EQ(back.muscles[1].failure, "*ERROR");
  EXPECT_TRUE(back.muscles[1].stepSurfaces.empty());
  std::vector<std::pair<std::vector<btVector3>, std::vector<btVector3>>> surfaces;  // read, shipped
  for (size_t p = 0; p < 3; ++p) surfaces.push_back({back.poseSurfaces[p], gate.poseSurfaces[p]});
  for (size_t s = 0; s < 3; ++s)
    surfaces.push_back({back.muscles[0].stepSurfaces[s], gate.muscles[0].stepSurfaces[s]});
  for (const auto& [read, shipped] : surfaces) {
    ASSERT_EQ(read.size(), shipped.size());
    for (size_t v = 0; v < read.size(); ++v)
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(read[v][c], shipped[v][c], kShippedGateQuantum / 2 + 1e-7);
  }
  for (size_t v = 0; v < back.poseSurfaces[2].size(); ++v)
    for (int c = 0; c < 3; ++c)
      ASSERT_EQ(float(back.poseSurfaces[2][v][c]), float(old.poseSurfaces[2][v][c]))
          << "within a quantum of its reference: the floats exactly";

  std::filesystem::remove(basePath);
  EXPECT_THROW(loadShippedSolution(compact, back), InputError) << "its reference is not beside it";
}

TEST(ReferenceCommand, ShipsItsSolvesAndAnEmptyCacheFindsThemThere) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("reference_ship_test");
  const std::string scene = coarseFusiform(dir.path());
  const std::string shipped = (dir.path() / "shipped").string();
  const auto reference = [&](const std::string& cache, const std::string& out,
                             const std::string& extra) {
    return testing::runProcess("FIBREMSS_REFERENCES=" + shipped + " " + FIBREMSS_CLI +
                               " reference " + scene + " --set resolution=8 --no-gates --cache " +
                               (dir.path() / cache).string() + " --out " +
                               (dir.path() / out).string() + " " + extra + " 2>&1");
  };
  const auto solved = reference("cache", "solved", "--ship " + shipped);
  ASSERT_EQ(solved.exitCode, 0) << solved.output;
  const nlohmann::json manifest =
      nlohmann::json::parse(readText(dir.path() / "shipped/manifest.json"));
  ASSERT_EQ(manifest.size(), 1u);
  EXPECT_EQ(manifest[0]["set"], nlohmann::json::array({"resolution=8"}));
  ASSERT_EQ(manifest[0]["solves"].size(), 5u) << "the reference and its four gates, named";
  for (const nlohmann::json& solve : manifest[0]["solves"]) {
    const bool isReference = solve["solve"] == "reference";
    EXPECT_EQ(solve.value("shipped", true), isReference) << "gates not computed: not shipped";
    EXPECT_EQ(std::filesystem::exists(dir.path() / "shipped" /
                                      (solve["key"].get<std::string>() + ".ref.gz")),
              isReference);
  }

  const auto found = reference("empty", "found", "--reference-cached-only");
  ASSERT_EQ(found.exitCode, 0) << found.output;
  EXPECT_NE(found.output.find("reference (reference): shipped (" + shipped), std::string::npos)
      << found.output;
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "empty")) << "nothing solved or stored";
  const nlohmann::json before =
      nlohmann::json::parse(readText(dir.path() / "solved/reference.json"));
  const nlohmann::json after = nlohmann::json::parse(readText(dir.path() / "found/reference.json"));
  EXPECT_EQ(after["key"], before["key"]);
  EXPECT_NEAR(after["gates"]["return_mm"].get<double>(), before["gates"]["return_mm"].get<double>(),
              1e-4)
      << "the same return gate from the shipped floats";

  const auto again = reference("cache", "again", "--ship " + shipped);
  ASSERT_EQ(again.exitCode, 0) << again.output;
  EXPECT_EQ(nlohmann::json::parse(readText(dir.path() / "shipped/manifest.json")), manifest)
      << "shipped again: the scene's entry replaced, not added";
}

TEST(ShippedReference, ACellsPartIsStoredAgainstItsReferenceBesideItAsAGateIs) {
  TemporaryDirectory dir("shipped_part_test");
  const std::string baseKey = "00000000000000cd";
  CalculixSolution reference;  // two muscles of 1 000 and 400 vertices, two poses
  for (int p = 0; p < 2; ++p) {
    reference.poseSurfaces.push_back(joined(smoothSurface(1000, p, 0), smoothSurface(400, -p, 0)));
    reference.poseFailures.push_back("");
  }
  const std::string basePath = (dir.path() / (baseKey + ".ref.gz")).string();
  shipSolution(basePath, reference);
  ShippedBase base{baseKey, {}, {1000, 400}};
  ASSERT_TRUE(loadShippedSolution(basePath, base.solution));
  MuscleSolution part;  // the second muscle of a gate: moved 0.3 mm in each pose
  for (int p = 0; p < 2; ++p) part.stepSurfaces.push_back(smoothSurface(400, -p, 3e-4));
  part.nodes = 120;
  part.increments = 9;
  part.seconds = 4.5;
  part.inputFile = "/another/machine/muscle1.inp";
  const std::string compact = (dir.path() / shippedPartName("00000000000000ef", 1)).string();
  const std::string floats = (dir.path() / "floats.ref.gz").string();
  EXPECT_EQ(std::filesystem::path(compact).filename(), "00000000000000ef.m1.ref.gz");
  shipPart(compact, part, &base);
  shipPart(floats, part);
  EXPECT_LT(std::filesystem::file_size(compact), std::filesystem::file_size(floats) / 2)
      << "differences from the reference, not floats";
  for (const std::string& path : {compact, floats}) {
    SCOPED_TRACE(path);
    MuscleSolution back;
    ASSERT_TRUE(loadShippedPart(path, back));
    EXPECT_EQ(back.nodes, 120u);
    EXPECT_EQ(back.increments, 9);
    EXPECT_EQ(back.seconds, 4.5);
    EXPECT_EQ(back.inputFile, "") << "its files stay on the machine that solved it";
    EXPECT_TRUE(back.solvedEveryStep());
    ASSERT_EQ(back.stepSurfaces.size(), 2u);
    for (size_t s = 0; s < 2; ++s) {
      ASSERT_EQ(back.stepSurfaces[s].size(), 400u);
      for (size_t v = 0; v < 400; ++v)
        for (int c = 0; c < 3; ++c)
          ASSERT_NEAR(back.stepSurfaces[s][v][c], part.stepSurfaces[s][v][c],
                      kShippedGateQuantum / 2 + 1e-7);
    }
  }
  CalculixSolution solution;
  MuscleSolution notAPart;
  EXPECT_THROW(loadShippedSolution(compact, solution), InputError) << "a part, not a solve";
  EXPECT_THROW(loadShippedPart(basePath, notAPart), InputError) << "a solve, not a part";
  EXPECT_FALSE(loadShippedPart((dir.path() / "absent.ref.gz").string(), notAPart));
  std::filesystem::remove(basePath);
  EXPECT_THROW(loadShippedPart(compact, notAPart), InputError) << "its reference is not beside it";
}

/// Each cell's "stored" or "to solve" in the output of `fibremss reference --cells` (its lines
/// of tab-separated columns; the log's are not).
std::vector<std::string> cellStates(const std::string& output) {
  std::vector<std::string> states;
  std::istringstream lines(output);
  for (std::string line; std::getline(lines, line);)
    if (line.find('\t') != std::string::npos) states.push_back(line.substr(line.rfind('\t') + 1));
  return states;
}

TEST(ReferenceCommand, ShipsTheCellsOfASolveNotStoredWholeAndTheNextMachineSolvesTheRest) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("reference_ship_cells_test");
  const std::string scene = carriedFusiform(dir.path(), true);  // two muscles
  const std::filesystem::path shipped = dir.path() / "shipped";
  const auto reference = [&](const std::string& cache, const std::string& extra) {
    return testing::runProcess("FIBREMSS_REFERENCES=" + shipped.string() + " " + FIBREMSS_CLI +
                               " reference " + scene + " --set resolution=6 --no-gates --cache " +
                               (dir.path() / cache).string() + " --out " +
                               (dir.path() / ("out-" + cache)).string() + " " + extra + " 2>&1");
  };
  const auto manifest = [&] {
    return nlohmann::json::parse(readText(shipped / "manifest.json"))[0]["solves"][0];
  };
  // One machine solves the second muscle's cell of the reference and ships it.
  ASSERT_EQ(reference("first", "--cell 1").exitCode, 0);
  const auto partly = reference("first", "--reference-cached-only --ship " + shipped.string());
  ASSERT_EQ(partly.exitCode, 0) << partly.output;
  const nlohmann::json entry = manifest();
  const std::string key = entry["key"];
  EXPECT_EQ(entry["solve"], "reference");
  EXPECT_EQ(entry["shipped"], false);
  EXPECT_EQ(entry["parts"], nlohmann::json::array({1}));
  EXPECT_TRUE(std::filesystem::exists(shipped / (key + ".m1.ref.gz")));
  EXPECT_FALSE(std::filesystem::exists(shipped / (key + ".m0.ref.gz")));
  EXPECT_FALSE(std::filesystem::exists(shipped / (key + ".ref.gz")));

  // The next one, its cache empty, finds that cell shipped and solves the other.
  const auto cells = reference("second", "--cells");
  ASSERT_EQ(cells.exitCode, 0) << cells.output;
  EXPECT_EQ(cellStates(cells.output), (std::vector<std::string>{"to solve", "stored"}));
  const auto found = reference("second", "--cell 1");
  ASSERT_EQ(found.exitCode, 0) << found.output;
  EXPECT_NE(found.output.find("was stored"), std::string::npos) << found.output;
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "second")) << "nothing solved";
  ASSERT_EQ(reference("second", "--cell 0").exitCode, 0);
  const auto merged = reference("second", "--reference-cached-only");
  ASSERT_EQ(merged.exitCode, 0) << merged.output;
  EXPECT_EQ(merged.output.find("not in the cache"), std::string::npos) << merged.output;
  // A run that solves what is missing takes the shipped cell too.
  const auto solved = reference("third", "");
  ASSERT_EQ(solved.exitCode, 0) << solved.output;
  for (const char* cache : {"second", "third"}) {
    SCOPED_TRACE(cache);
    const std::filesystem::path entryDir = dir.path() / cache / key;
    EXPECT_TRUE(std::filesystem::exists(entryDir / "muscle0.inp"));
    EXPECT_FALSE(std::filesystem::exists(entryDir / "muscle1.inp")) << "shipped: not solved here";
  }

  // The same solve merged from the first machine's cache alone.
  ASSERT_EQ(reference("first", "--cell 0").exitCode, 0);
  ASSERT_EQ(reference("first", "--reference-cached-only").exitCode, 0);
  const auto stored = [&](const char* cache) {
    CalculixSolution solution;
    EXPECT_TRUE(loadSolution((dir.path() / cache / key / "surfaces.bin").string(), solution));
    return solution;
  };
  const CalculixSolution whole = stored("first");
  ASSERT_EQ(whole.solvedPoses(), 2) << whole.poseFailures[1];
  ASSERT_FALSE(whole.returnSurface.empty()) << whole.returnFailure;
  for (const char* cache : {"second", "third"}) {
    SCOPED_TRACE(cache);
    const CalculixSolution withShipped = stored(cache);
    expectTheSameSolutionWithinFloats(withShipped, whole);
    EXPECT_EQ(withShipped.inputFiles.size(), 1u) << "the shipped cell's files are not here";
  }

  // Shipped whole, the solve's cells are no longer shipped on their own.
  const auto again = reference("second", "--reference-cached-only --ship " + shipped.string());
  ASSERT_EQ(again.exitCode, 0) << again.output;
  EXPECT_EQ(manifest(), (nlohmann::json{{"solve", "reference"}, {"key", key}}));
  EXPECT_TRUE(std::filesystem::exists(shipped / (key + ".ref.gz")));
  EXPECT_FALSE(std::filesystem::exists(shipped / (key + ".m1.ref.gz"))) << "stale: removed";
}

TEST(ReferenceCommand, TheMethodsAReferenceRanksGoWithoutTheMuscleContactItLacks) {
  REQUIRE_PROGRAM("ccx");
  REQUIRE_PROGRAM("tetgen");
  TemporaryDirectory dir("compare_contact_test");
  const std::string scene = carriedFusiform(dir.path(), true);  // two muscles that collide
  const auto compare = [&](const std::string& out, const std::string& extra) {
    const auto result = testing::runProcess(
        std::string(FIBREMSS_CLI) + " compare " + scene +
        " --set resolution=6 --methods fibremss --no-fronts --no-gates --cache " +
        (dir.path() / "cache").string() + " --out " + (dir.path() / out).string() + " " + extra +
        " 2>&1");
    EXPECT_EQ(result.exitCode, 0) << result.output;
    return nlohmann::json::parse(readText(dir.path() / out / "summary.json"));
  };
  const auto withoutContact = [](const nlohmann::json& run) {
    const nlohmann::json& overrides = run["scene_overrides"];
    return std::find(overrides.begin(), overrides.end(), kNoMuscleContact) != overrides.end();
  };
  const nlohmann::json ranked = compare("ranked", "");
  ASSERT_EQ(ranked["runs"].size(), 2u);
  for (const nlohmann::json& run : ranked["runs"]) EXPECT_TRUE(withoutContact(run)) << run;
  EXPECT_EQ(ranked["reference"]["methods_without_muscle_contact"], true);
  EXPECT_NE(readText(dir.path() / "ranked/report.md").find("**One problem for all:**"),
            std::string::npos);

  const nlohmann::json alone = compare("alone", "--no-reference");
  ASSERT_EQ(alone["runs"].size(), 1u);
  for (const nlohmann::json& run : alone["runs"])
    EXPECT_FALSE(withoutContact(run)) << "no reference: the scene's own contact";
  EXPECT_EQ(readText(dir.path() / "alone/report.md").find("One problem for all"),
            std::string::npos);
}

TEST(ShippedReference, EveryShippedSolveStillHasTheKeyItsSceneGivesToday) {
  REQUIRE_PROGRAM("ccx");
#ifdef BT_USE_DOUBLE_PRECISION
  GTEST_SKIP() << "the shipped keys hash the float build's prepared surfaces (the main job's)";
#endif
  const std::filesystem::path dir =
      std::filesystem::path(FIBREMSS_SOURCE_DIR) / "scenes/references";
  const nlohmann::json manifest = nlohmann::json::parse(readText(dir / "manifest.json"));
  std::set<std::string> listed;
  for (const nlohmann::json& entry : manifest) {
    const std::string name = entry["scene"].get<std::string>();
    SCOPED_TRACE(name);
    const LoadedScene scene = loadScene(name, entry["set"].get<std::vector<std::string>>());
    const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
    ReferenceOptions options;
    options.cacheDir = "/nonexistent";
    std::vector<std::string> keys;
    for (const NamedReferenceCell& cell : referenceCells(scene, prepared, options))
      if (cell.cell.muscle == 0) keys.push_back(cell.key);
    std::vector<std::string> named, shipped, failed;
    std::vector<std::pair<std::string, size_t>> parts;  // a solve's key, a muscle
    for (const nlohmann::json& solve : entry["solves"]) {
      named.push_back(solve["key"]);
      if (solve.value("shipped", true)) shipped.push_back(solve["key"]);
      if (solve.contains("retry_of")) failed.push_back(solve["retry_of"]);
      for (const nlohmann::json& m : solve.value("parts", nlohmann::json::array()))
        parts.emplace_back(solve["key"], m.get<size_t>());
    }
    EXPECT_EQ(keys, named) << "the scene or the reference changed: recompute it as "
                              "scenes/references/README.md says";
    for (const std::string& key : shipped) {
      listed.insert(key + ".ref.gz");
      CalculixSolution solution;
      ASSERT_TRUE(loadShippedSolution((dir / (key + ".ref.gz")).string(), solution)) << key;
      EXPECT_EQ(solution.poseSurfaces.size(), size_t(std::max(scene.poseCount, 1))) << key;
    }
    for (const std::string& key : failed) {
      listed.insert(key + ".ref.gz");
      CalculixSolution solution;
      ASSERT_TRUE(loadShippedSolution((dir / (key + ".ref.gz")).string(), solution)) << key;
      EXPECT_FALSE(ccxFailureToRetry(solution).empty())
          << key << ": a retried solve keeps the failure through which a run finds its retry";
    }
    for (const auto& [key, m] : parts) {  // a cell of a solve not shipped whole, under its key
      const std::string file = shippedPartName(key, m);
      listed.insert(file);
      ASSERT_LT(m, prepared.muscles.size()) << file;
      MuscleSolution part;
      ASSERT_TRUE(loadShippedPart((dir / file).string(), part)) << file;
      size_t solved = 0;  // a failed cell's steps past its failure are empty
      for (const std::vector<btVector3>& surface : part.stepSurfaces)
        if (!surface.empty() && ++solved) {
          EXPECT_EQ(surface.size(), prepared.muscles[m]->restSurface.vertices.size()) << file;
        }
      EXPECT_GT(solved, 0u) << file;
      EXPECT_EQ(solved < part.stepSurfaces.size(), !part.failure.empty()) << file;
    }
  }
  for (const auto& file : std::filesystem::directory_iterator(dir))
    if (file.path().extension() == ".gz") {
      EXPECT_TRUE(listed.count(file.path().filename().string())) << file.path() << " is unlisted";
    }
}

}  // namespace
}  // namespace fibremss
