// The checks every loaded surface and fibre set goes through: fatal defects throw
// InputError, defects a run can live with become counted warnings naming the first case.
#include <algorithm>
#include <cmath>
#include <string>

#include "MeshIOInternal.h"
#include "fibremss/Error.h"
#include "fibremss/MeshIO.h"

namespace fibremss {
namespace {

bool finite(const btVector3& p) {
  return std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z());
}

std::string coordinates(const btVector3& p) {
  return "(" + std::to_string(p.x()) + ", " + std::to_string(p.y()) + ", " + std::to_string(p.z()) +
         ")";
}

std::string edgeName(uint64_t key, uint32_t triangle) {
  return "the edge between vertices " + std::to_string(key >> 32) + " and " +
         std::to_string(key & 0xffffffffu) + " (triangle " + std::to_string(triangle) + ")";
}

/// Zero area to float precision: the height is below 1e-6 of the longest edge.
bool zeroArea(const btVector3& a, const btVector3& b, const btVector3& c) {
  const double ab[3] = {double(b.x()) - a.x(), double(b.y()) - a.y(), double(b.z()) - a.z()};
  const double ac[3] = {double(c.x()) - a.x(), double(c.y()) - a.y(), double(c.z()) - a.z()};
  const double bc[3] = {ac[0] - ab[0], ac[1] - ab[1], ac[2] - ab[2]};
  const double cross[3] = {ab[1] * ac[2] - ab[2] * ac[1], ab[2] * ac[0] - ab[0] * ac[2],
                           ab[0] * ac[1] - ab[1] * ac[0]};
  const auto squared = [](const double* v) { return v[0] * v[0] + v[1] * v[1] + v[2] * v[2]; };
  const double longest = std::max({squared(ab), squared(ac), squared(bc)});
  // |cross| = height * longest edge, so height <= 1e-6 * longest  <=>  |cross|^2 <= 1e-12 L^4.
  return squared(cross) <= 1e-12 * longest * longest;
}

/// A counted warning into `report` when `count` > 0, naming the first case.
void warn(MeshReport& report, const std::string& source, size_t count, const std::string& what,
          const std::string& first) {
  if (count == 0) return;
  report.warnings.push_back(source + ": " + std::to_string(count) + " " + what + ", first " +
                            first);
}

/// The fatal defects: non-finite vertices, no triangle, indices beyond the vertices.
void checkFatal(const TriangleMesh& mesh, const std::string& source) {
  const size_t vertexCount = mesh.vertices.size();
  for (size_t i = 0; i < vertexCount; ++i) {
    if (!finite(mesh.vertices[i])) {
      throw InputError(source, "vertex " + std::to_string(i),
                       "expected finite coordinates, found " + coordinates(mesh.vertices[i]));
    }
  }
  if (mesh.triangles.empty()) {
    throw InputError(source, "", "expected a surface with at least one triangle, found none");
  }
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    for (const uint32_t index : mesh.triangles[t]) {
      if (index >= vertexCount) {
        throw InputError(source, "triangle " + std::to_string(t),
                         "expected vertex indices from 0 to " + std::to_string(vertexCount) +
                             "-1, found " + std::to_string(index));
      }
    }
  }
}

/// Degenerate and duplicate triangles into `report`; the vertices the triangles use into `used`.
void checkTriangles(const TriangleMesh& mesh, const std::string& source, MeshReport& report,
                    std::vector<bool>& used) {
  std::vector<std::array<uint32_t, 4>> sortedTriangles;  // sorted corners, then triangle index
  sortedTriangles.reserve(mesh.triangles.size());
  std::string firstDegenerate;
  for (uint32_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& tri = mesh.triangles[t];
    for (const uint32_t index : tri) used[index] = true;
    const bool repeated = tri[0] == tri[1] || tri[1] == tri[2] || tri[2] == tri[0];
    if (repeated || zeroArea(mesh.vertices[tri[0]], mesh.vertices[tri[1]], mesh.vertices[tri[2]])) {
      if (report.degenerateTriangles++ == 0) firstDegenerate = "triangle " + std::to_string(t);
    }
    if (repeated) continue;
    std::array<uint32_t, 4> corners = {tri[0], tri[1], tri[2], t};
    std::sort(corners.begin(), corners.begin() + 3);
    sortedTriangles.push_back(corners);
  }
  warn(report, source, report.degenerateTriangles,
       "degenerate triangles (zero area or a repeated vertex)", firstDegenerate);

  std::sort(sortedTriangles.begin(), sortedTriangles.end());
  std::string firstDuplicate;
  for (size_t i = 1; i < sortedTriangles.size(); ++i) {
    const auto& a = sortedTriangles[i - 1];
    const auto& b = sortedTriangles[i];
    if (a[0] == b[0] && a[1] == b[1] && a[2] == b[2] && report.duplicateTriangles++ == 0) {
      firstDuplicate =
          "triangle " + std::to_string(b[3]) + " repeats triangle " + std::to_string(a[3]);
    }
  }
  warn(report, source, report.duplicateTriangles, "duplicate triangles (the same three vertices)",
       firstDuplicate);
}

/// Open, non-manifold and inconsistently oriented edges into `report`.
void checkEdges(const TriangleMesh& mesh, const std::string& source, MeshReport& report) {
  const std::vector<meshio::EdgeUse> edges = meshio::sortedEdgeUses(mesh);
  std::string firstOpen, firstNonManifold, firstInconsistent;
  for (size_t begin = 0; begin < edges.size();) {
    size_t end = begin + 1;
    while (end < edges.size() && edges[end].key == edges[begin].key) ++end;
    const auto nameFirst = [&](size_t count, std::string& name) {
      if (count == 0) name = edgeName(edges[begin].key, edges[begin].triangle);
    };
    if (end - begin == 1) {
      nameFirst(report.openEdges++, firstOpen);
    } else if (end - begin > 2) {
      nameFirst(report.nonManifoldEdges++, firstNonManifold);
    } else if (edges[begin].forward == edges[begin + 1].forward) {
      nameFirst(report.inconsistentEdges++, firstInconsistent);
    }
    begin = end;
  }
  warn(report, source, report.openEdges,
       "open edges (used by one triangle: the surface is not watertight)", firstOpen);
  warn(report, source, report.nonManifoldEdges,
       "non-manifold edges (shared by more than two triangles)", firstNonManifold);
  warn(report, source, report.inconsistentEdges,
       "edges whose two triangles are oriented inconsistently (normals flip across them)",
       firstInconsistent);
}

}  // namespace

MeshReport checkSurface(const TriangleMesh& mesh, const std::string& source) {
  checkFatal(mesh, source);
  MeshReport report;
  std::vector<bool> used(mesh.vertices.size(), false);
  checkTriangles(mesh, source, report, used);
  checkEdges(mesh, source, report);

  report.unusedVertices = static_cast<size_t>(std::count(used.begin(), used.end(), false));
  if (report.unusedVertices > 0) {
    const auto first = std::find(used.begin(), used.end(), false) - used.begin();
    warn(report, source, report.unusedVertices, "vertices used by no triangle",
         "vertex " + std::to_string(first));
  }

  if (report.closed() && report.inconsistentEdges == 0) {
    const btScalar volume = meshVolume(mesh);
    if (volume < 0) {
      report.insideOut = true;
      report.warnings.push_back(source + ": the closed surface has negative volume (" +
                                std::to_string(volume) + "): its triangles face inward");
    }
  }
  return report;
}

namespace meshio {

std::vector<EdgeUse> sortedEdgeUses(const TriangleMesh& mesh) {
  std::vector<EdgeUse> edges;
  edges.reserve(3 * mesh.triangles.size());
  for (uint32_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& tri = mesh.triangles[t];
    if (tri[0] == tri[1] || tri[1] == tri[2] || tri[2] == tri[0]) continue;
    for (size_t k = 0; k < 3; ++k) {
      const uint32_t from = tri[k], to = tri[(k + 1) % 3];
      edges.push_back({(uint64_t(std::min(from, to)) << 32) | std::max(from, to), t, from < to});
    }
  }
  std::sort(edges.begin(), edges.end(), [](const EdgeUse& a, const EdgeUse& b) {
    return a.key != b.key ? a.key < b.key : a.triangle < b.triangle;
  });
  return edges;
}

void validateFibres(const FibreSet& fibres, const std::string& source) {
  if (fibres.offsets.empty() || fibres.offsets.front() != 0 ||
      fibres.offsets.back() != fibres.points.size() ||
      !std::is_sorted(fibres.offsets.begin(), fibres.offsets.end())) {
    throw InputError(source, "",
                     "expected fibre offsets rising from 0 to the point count (a broken FibreSet)");
  }
  if (fibres.fibreCount() == 0) throw InputError(source, "", "expected fibres, found none");
  for (size_t f = 0; f < fibres.fibreCount(); ++f) {
    const auto fibre = fibres.fibre(f);
    const std::string where = "fibre " + std::to_string(f);
    if (fibre.size() < 2) {
      throw InputError(source, where,
                       fibre.empty() ? "empty; expected at least two points per fibre"
                                     : "a single point; expected at least two points per fibre");
    }
    bool hasLength = false;
    for (size_t p = 0; p < fibre.size(); ++p) {
      if (!finite(fibre[p])) {
        throw InputError(source, where + ", point " + std::to_string(p),
                         "expected finite coordinates, found " + coordinates(fibre[p]));
      }
      hasLength = hasLength || fibre[p] != fibre[0];
    }
    if (!hasLength) {
      throw InputError(source, where,
                       "all " + std::to_string(fibre.size()) +
                           " points coincide; expected a fibre of non-zero length");
    }
  }
}

}  // namespace meshio

std::vector<std::string> checkFibres(const FibreSet& fibres, const TriangleMesh& surface,
                                     const std::string& source, double tolerance) {
  meshio::validateFibres(fibres, source);
  if (surface.empty()) {
    throw InputError(source, "", "expected a muscle surface to check the fibres against");
  }
  constexpr size_t kListed = 10;  // fibres named one by one before a summary
  std::vector<std::string> warnings;
  const MeshDistance distance(surface);
  size_t outsideFibres = 0, repeatedPoints = 0;
  for (size_t f = 0; f < fibres.fibreCount(); ++f) {
    const auto fibre = fibres.fibre(f);
    size_t outside = 0;
    double farthest = 0;
    for (size_t p = 0; p < fibre.size(); ++p) {
      const double signedDistance = distance.signedDistance(fibre[p]);
      if (signedDistance > tolerance) {
        ++outside;
        farthest = std::max(farthest, signedDistance);
      }
      if (p > 0 && fibre[p] == fibre[p - 1]) ++repeatedPoints;
    }
    if (outside > 0 && outsideFibres++ < kListed) {
      warnings.push_back(source + ": fibre " + std::to_string(f) + ": " + std::to_string(outside) +
                         " of " + std::to_string(fibre.size()) +
                         " points lie outside the muscle surface (up to " +
                         std::to_string(farthest) + " m)");
    }
  }
  if (outsideFibres > kListed) {
    warnings.push_back(source + ": " + std::to_string(outsideFibres) +
                       " fibres in all leave the muscle surface");
  }
  if (repeatedPoints > 0) {
    warnings.push_back(source + ": " + std::to_string(repeatedPoints) +
                       " fibre points repeat the point before them (zero-length segments)");
  }
  return warnings;
}

}  // namespace fibremss
