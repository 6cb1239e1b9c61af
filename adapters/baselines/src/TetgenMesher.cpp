// Conforming tetrahedral meshes of closed surfaces by Debian's tetgen, run as a process: the
// surface written as OFF, `tetgen -pYqQ` (keep the surface), its .node/.ele read back.
#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>
#include <utility>

#include "fibremss/Calculix.h"
#include "fibremss/Error.h"

namespace fibremss {
namespace {

void writeOff(const std::string& path, const TriangleMesh& surface) {
  std::ofstream out(path);
  out.precision(9);
  out << "OFF\n" << surface.vertices.size() << " " << surface.triangles.size() << " 0\n";
  for (const btVector3& v : surface.vertices) out << v.x() << " " << v.y() << " " << v.z() << "\n";
  for (const auto& t : surface.triangles) out << "3 " << t[0] << " " << t[1] << " " << t[2] << "\n";
  if (!out) throw InputError(path, "", "cannot write the surface for tetgen");
}

/// The first non-comment line's numbers of a tetgen file, then the rest of the stream.
std::istringstream header(std::ifstream& in) {
  std::string line;
  while (std::getline(in, line))
    if (line.find_first_not_of(" \t") != std::string::npos &&
        line[line.find_first_not_of(" \t")] != '#')
      break;
  return std::istringstream(line);
}

std::vector<btVector3> readNodes(const std::string& path) {
  std::ifstream in(path);
  size_t count = 0;
  if (!in || !(header(in) >> count)) throw InputError(path, "", "tetgen wrote no readable nodes");
  std::vector<btVector3> nodes(count);
  for (size_t i = 0; i < count; ++i) {
    size_t index = 0;
    double x = 0, y = 0, z = 0;
    if (!(in >> index >> x >> y >> z) || index >= count)
      throw InputError(path, "node " + std::to_string(i), "expected 'index x y z'");
    in.ignore(1 << 12, '\n');  // attributes and markers
    nodes[index].setValue(static_cast<btScalar>(x), static_cast<btScalar>(y),
                          static_cast<btScalar>(z));
  }
  return nodes;
}

std::vector<std::array<uint32_t, 4>> readTetrahedra(const std::string& path, size_t nodes) {
  std::ifstream in(path);
  size_t count = 0, corners = 0;
  if (!in || !(header(in) >> count >> corners) || corners != 4)
    throw InputError(path, "", "tetgen wrote no readable linear tetrahedra");
  std::vector<std::array<uint32_t, 4>> tetrahedra(count);
  for (size_t i = 0; i < count; ++i) {
    size_t index = 0;
    auto& t = tetrahedra[i];
    if (!(in >> index >> t[0] >> t[1] >> t[2] >> t[3]) ||
        *std::max_element(t.begin(), t.end()) >= nodes)
      throw InputError(path, "tetrahedron " + std::to_string(i), "expected 'index a b c d'");
  }
  return tetrahedra;
}

std::string tetgenFailure(const std::string& logPath) {
  std::ifstream in(logPath);
  std::string line, message;
  while (std::getline(in, line))
    if (!line.empty() && line.find("Opening") == std::string::npos)
      message += (message.empty() ? "" : " ") + line;
  return message.empty() ? "no message" : message;
}

/// Runs tetgen once on `<stem>.off` in workDir with a volume bound (0: none).
TetMesh runTetgen(const TriangleMesh& surface, const TetgenDefinition& definition,
                  const std::string& workDir, const std::string& stem, double maxVolume) {
  const std::string off = workDir + "/" + stem + ".off";
  writeOff(off, surface);
  std::ostringstream switches;
  switches << "-pYQq" << definition.radiusEdgeRatio;
  if (maxVolume > 0) switches << "a" << maxVolume;
  const std::string log = workDir + "/" + stem + ".tetgen.log";
  const int status = runProgram({definition.program, switches.str(), stem + ".off"}, workDir, log);
  if (status != 0) {
    throw InputError(off, "",
                     "tetgen " + switches.str() + " failed (exit " + std::to_string(status) +
                         "): " + tetgenFailure(log));
  }
  TetMesh mesh;
  mesh.nodes = readNodes(workDir + "/" + stem + ".1.node");
  mesh.tetrahedra = readTetrahedra(workDir + "/" + stem + ".1.ele", mesh.nodes.size());
  for (size_t v = 0; v < surface.vertices.size(); ++v) {
    if (v >= mesh.nodes.size() || mesh.nodes[v].distance(surface.vertices[v]) > btScalar(1e-7)) {
      throw InputError(off, "vertex " + std::to_string(v),
                       "tetgen did not keep the surface vertex as node " + std::to_string(v) +
                           " (duplicate vertices?)");
    }
    mesh.nodes[v] = surface.vertices[v];  // bit for bit the surface's
  }
  for (auto& t : mesh.tetrahedra) {
    const auto& x = mesh.nodes;
    if (tetrahedronVolume(x[t[0]], x[t[1]], x[t[2]], x[t[3]]) < 0) std::swap(t[2], t[3]);
  }
  return mesh;
}

}  // namespace

TriangleMesh subdivided(const TriangleMesh& surface, int levels) {
  TriangleMesh mesh = surface;
  for (int level = 0; level < levels; ++level) {
    TriangleMesh finer;
    finer.vertices = mesh.vertices;
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> midpoints;
    auto midpoint = [&](uint32_t a, uint32_t b) {
      auto [it, added] =
          midpoints.try_emplace(std::minmax(a, b), static_cast<uint32_t>(finer.vertices.size()));
      if (added) finer.vertices.push_back((mesh.vertices[a] + mesh.vertices[b]) * btScalar(0.5));
      return it->second;
    };
    for (const auto& t : mesh.triangles) {
      const uint32_t ab = midpoint(t[0], t[1]), bc = midpoint(t[1], t[2]),
                     ca = midpoint(t[2], t[0]);
      finer.triangles.push_back({t[0], ab, ca});
      finer.triangles.push_back({ab, t[1], bc});
      finer.triangles.push_back({ca, bc, t[2]});
      finer.triangles.push_back({ab, bc, ca});
    }
    mesh = std::move(finer);
  }
  return mesh;
}

TetMesh tetgenMesh(const TriangleMesh& surface, const TetgenDefinition& definition,
                   const std::string& workDir, const std::string& stem) {
  if (surface.empty()) throw InputError(stem, "", "an empty surface cannot be tetrahedralized");
  TetMesh mesh = runTetgen(surface, definition, workDir, stem, 0);
  if (definition.refinement <= 0) return mesh;
  const double meanVolume = totalVolume(mesh) / static_cast<double>(mesh.tetrahedra.size());
  const double bound = meanVolume / std::pow(8.0, definition.refinement);
  return runTetgen(subdivided(surface, definition.refinement), definition, workDir, stem, bound);
}

}  // namespace fibremss
