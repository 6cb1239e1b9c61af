// CalculiX input (.inp) for the static reference, and the quadratic tetrahedra it can use.
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <ostream>
#include <utility>

#include "fibremss/Calculix.h"

namespace fibremss {
namespace {

/// Numbers (1-based ids) 16 to a line, as Abaqus-style sets allow.
void writeIds(std::ostream& out, const std::vector<uint32_t>& indices) {
  for (size_t i = 0; i < indices.size(); ++i)
    out << indices[i] + 1 << (i + 1 == indices.size() || i % 16 == 15 ? "\n" : ", ");
}

void writeMesh(std::ostream& out, const CalculixJob& job) {
  out << "*NODE, NSET=NALL\n";
  for (size_t n = 0; n < job.nodes.size(); ++n) {
    const btVector3& x = job.nodes[n];
    out << n + 1 << ", " << x.x() << ", " << x.y() << ", " << x.z() << "\n";
  }
  const size_t perElement = job.element == CalculixElement::C3D4 ? 4 : 10;
  out << "*ELEMENT, TYPE=" << toString(job.element) << ", ELSET=EALL\n";
  for (size_t e = 0; e * perElement < job.connectivity.size(); ++e) {
    out << e + 1;
    for (size_t i = 0; i < perElement; ++i) out << ", " << job.connectivity[e * perElement + i] + 1;
    out << "\n";
  }
}

/// The obstacles' elements after the body's, their rigid material, the master and slave
/// surfaces and the penalty contact between them.
void writeContact(std::ostream& out, const CalculixJob& job) {
  const CalculixContact& contact = job.contact;
  const size_t perElement = job.element == CalculixElement::C3D4 ? 4 : 10;
  const size_t first = job.connectivity.size() / perElement + 1;  // its first element number
  out << "*ELEMENT, TYPE=C3D4, ELSET=EBONE\n";
  for (size_t e = 0; e * 4 < contact.tetrahedra.size(); ++e) {
    out << first + e;
    for (size_t i = 0; i < 4; ++i) out << ", " << contact.tetrahedra[e * 4 + i] + 1;
    out << "\n";
  }
  out << "*MATERIAL, NAME=BONE\n*ELASTIC\n"
      << job.material.youngsModulus * 1e3 << ", 0.3\n"
      << "*SOLID SECTION, ELSET=EBONE, MATERIAL=BONE\n*SURFACE, NAME=SBONE, TYPE=ELEMENT\n";
  for (const auto& [element, face] : contact.faces)
    out << first + element << ", S" << int(face) << "\n";
  out << "*NSET, NSET=NSLAVE\n";
  writeIds(out, contact.slaves);
  out << "*SURFACE, NAME=SMUSCLE, TYPE=NODE\nNSLAVE\n"
      << "*SURFACE INTERACTION, NAME=FRICTIONLESS\n"
      << "*SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=LINEAR\n"
      << contact.stiffness << ", " << contact.tension << "\n"
      << "*CONTACT PAIR, INTERACTION=FRICTIONLESS, TYPE=NODE TO SURFACE"
      << (contact.sliding == ContactSliding::Small ? ", SMALL SLIDING" : "")
      << "\nSMUSCLE, SBONE\n";
}

/// Each equation's non-zero terms, the largest first (CalculiX eliminates the first term's
/// degree of freedom, so its coefficient must not be small).
void writeEquations(std::ostream& out, const CalculixJob& job) {
  for (const CalculixEquation& equation : job.equations) {
    std::array<int, 3> axes{0, 1, 2};
    std::sort(axes.begin(), axes.end(), [&](int a, int b) {
      return std::abs(equation.direction[a]) > std::abs(equation.direction[b]);
    });
    const auto terms = std::count_if(axes.begin(), axes.end(),
                                     [&](int axis) { return equation.direction[axis] != 0; });
    out << "*EQUATION\n" << terms << "\n";
    for (long i = 0; i < terms; ++i)
      out << equation.node + 1 << ", " << axes[size_t(i)] + 1 << ", "
          << equation.direction[axes[size_t(i)]] << (i + 1 == terms ? "\n" : ", ");
  }
}

void writeStep(std::ostream& out, const CalculixJob& job, size_t step) {
  const double largest = step < job.maximumIncrements.size() ? job.maximumIncrements[step] : 1;
  out << "*STEP, NLGEOM, INC=10000\n*STATIC\n"
      << std::min(job.initialIncrement, largest) << ", 1., "
      << std::min(job.minimumIncrement, largest) << ", " << largest << "\n*BOUNDARY\n";
  const std::vector<btVector3>& u = job.steps[step];
  for (size_t i = 0; i < job.prescribed.size(); ++i) {
    const uint32_t id = job.prescribed[i] + 1;
    for (int axis = 0; axis < 3; ++axis)
      out << id << ", " << axis + 1 << ", " << axis + 1 << ", " << u[i][axis] << "\n";
  }
  out << "*NODE PRINT, NSET=NPRINT\nU\n*END STEP\n";
}

}  // namespace

const char* toString(CalculixElement element) {
  return element == CalculixElement::C3D4 ? "C3D4" : "C3D10";
}

const char* toString(ContactSliding sliding) {
  return sliding == ContactSliding::Small ? "small" : "finite";
}

void writeCalculixInput(std::ostream& out, const CalculixJob& job) {
  const auto precision = out.precision(9);
  out << "** " << job.title << "\n** written by FibreMSS; units: m, Pa\n";
  writeMesh(out, job);
  out << "*NSET, NSET=NMOVED\n";
  writeIds(out, job.prescribed);
  out << "*NSET, NSET=NPRINT\n";
  writeIds(out, job.printed);
  out << "*MATERIAL, NAME=MUSCLE\n*HYPERELASTIC, NEO HOOKE\n"
      << job.material.c10() << ", " << job.material.d1() << "\n"
      << "*SOLID SECTION, ELSET=EALL, MATERIAL=MUSCLE\n";
  writeEquations(out, job);
  if (job.contact.stiffness > 0 && !job.contact.faces.empty() && !job.contact.slaves.empty())
    writeContact(out, job);
  for (size_t step = 0; step < job.steps.size(); ++step) writeStep(out, job, step);
  out.precision(precision);
}

std::vector<std::pair<uint32_t, uint8_t>> boundaryFaces(const std::vector<uint32_t>& tetrahedra) {
  // CalculiX's C3D4 faces by local corners: 1: 1-2-3, 2: 1-4-2, 3: 2-4-3, 4: 3-4-1.
  constexpr int kFaces[4][3] = {{0, 1, 2}, {0, 3, 1}, {1, 3, 2}, {2, 3, 0}};
  std::map<std::array<uint32_t, 3>, std::pair<uint32_t, uint8_t>> once;
  std::map<std::array<uint32_t, 3>, int> count;
  for (uint32_t e = 0; e * 4 < tetrahedra.size(); ++e)
    for (uint8_t f = 0; f < 4; ++f) {
      std::array<uint32_t, 3> key{};
      for (int k = 0; k < 3; ++k) key[k] = tetrahedra[e * 4 + kFaces[f][k]];
      std::sort(key.begin(), key.end());
      once[key] = {e, static_cast<uint8_t>(f + 1)};
      ++count[key];
    }
  std::vector<std::pair<uint32_t, uint8_t>> faces;
  for (const auto& [key, face] : once)
    if (count[key] == 1) faces.push_back(face);
  std::sort(faces.begin(), faces.end());
  return faces;
}

ObstacleMesh obstacleMesh(const TriangleMesh& surface) {
  ObstacleMesh mesh;
  mesh.nodes = surface.vertices;
  const bool outward = meshVolume(surface) >= 0;
  for (const auto& t : surface.triangles) {
    // Corners ordered so that the apex lies on the positive side of face 1 (1-2-3), as a
    // C3D4 of positive volume has it: face 1's outward normal is then the surface's.
    const uint32_t a = t[0], b = outward ? t[2] : t[1], c = outward ? t[1] : t[2];
    const btVector3 &pa = surface.vertices[a], &pb = surface.vertices[b], &pc = surface.vertices[c];
    const btVector3 inward = (pb - pa).cross(pc - pa).normalized();
    const btScalar longest = std::max({(pb - pa).length(), (pc - pb).length(), (pa - pc).length()});
    const auto apex = static_cast<uint32_t>(mesh.nodes.size());
    mesh.nodes.push_back((pa + pb + pc) / btScalar(3) + inward * (longest / 2));
    mesh.faces.emplace_back(static_cast<uint32_t>(mesh.tetrahedra.size() / 4), uint8_t{1});
    mesh.tetrahedra.insert(mesh.tetrahedra.end(), {a, b, c, apex});
  }
  return mesh;
}

std::vector<uint32_t> surfaceNodes(const CalculixJob& job, size_t surfaceVertices) {
  std::vector<uint32_t> nodes(surfaceVertices);
  for (size_t v = 0; v < surfaceVertices; ++v) nodes[v] = static_cast<uint32_t>(v);
  if (job.element != CalculixElement::C3D10) return nodes;
  std::vector<uint32_t> corners;
  corners.reserve(job.connectivity.size() / 10 * 4);
  for (size_t e = 0; e * 10 < job.connectivity.size(); ++e)
    corners.insert(corners.end(), job.connectivity.begin() + long(e * 10),
                   job.connectivity.begin() + long(e * 10 + 4));
  // Per C3D4 face (boundaryFaces' numbering), the connectivity slots of its three edges' midside
  // nodes (quadraticTetrahedra's order: 1-2, 2-3, 3-1, 1-4, 2-4, 3-4 in slots 4-9).
  constexpr int kMidsides[4][3] = {{4, 5, 6}, {7, 8, 4}, {8, 9, 5}, {9, 7, 6}};
  for (const auto& [element, face] : boundaryFaces(corners))
    for (int slot : kMidsides[face - 1]) nodes.push_back(job.connectivity[element * 10 + slot]);
  std::sort(nodes.begin(), nodes.end());
  nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
  return nodes;
}

std::vector<btVector3> quadraticTetrahedra(const TetMesh& mesh,
                                           std::vector<uint32_t>& connectivity) {
  std::vector<btVector3> nodes = mesh.nodes;
  std::map<std::pair<uint32_t, uint32_t>, uint32_t> midside;
  auto midpoint = [&](uint32_t a, uint32_t b) {
    const auto key = std::minmax(a, b);
    auto [it, added] = midside.try_emplace(key, static_cast<uint32_t>(nodes.size()));
    if (added) nodes.push_back((mesh.nodes[a] + mesh.nodes[b]) * btScalar(0.5));
    return it->second;
  };
  constexpr int kEdges[6][2] = {{0, 1}, {1, 2}, {2, 0}, {0, 3}, {1, 3}, {2, 3}};
  connectivity.clear();
  connectivity.reserve(mesh.tetrahedra.size() * 10);
  for (const auto& t : mesh.tetrahedra) {
    connectivity.insert(connectivity.end(), t.begin(), t.end());
    for (const auto& edge : kEdges) connectivity.push_back(midpoint(t[edge[0]], t[edge[1]]));
  }
  return nodes;
}

}  // namespace fibremss
