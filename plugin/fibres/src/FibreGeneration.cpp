// Fibres from a muscle surface: harmonic field on a voxel grid, gradient streamlines.
#include "fibremss/FibreGeneration.h"

#include <Eigen/Dense>
#include <Eigen/IterativeLinearSolvers>
#include <Eigen/Sparse>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <unordered_map>

#include "fibremss/Error.h"
#include "fibremss/UnionFind.h"

namespace fibremss {
namespace {

using Clock = std::chrono::steady_clock;

/// Main axis (PCA) and centroid of a point set.
void principalAxis(const std::vector<btVector3>& points, btVector3& centroid, btVector3& axis) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : points) mean += Eigen::Vector3d(p.x(), p.y(), p.z());
  mean /= double(std::max<size_t>(points.size(), 1));
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (const auto& p : points) {
    const Eigen::Vector3d d = Eigen::Vector3d(p.x(), p.y(), p.z()) - mean;
    covariance += d * d.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(covariance);
  const Eigen::Vector3d a = solver.eigenvectors().col(2);
  centroid = btVector3(btScalar(mean.x()), btScalar(mean.y()), btScalar(mean.z()));
  axis = btVector3(btScalar(a.x()), btScalar(a.y()), btScalar(a.z()));
}

btVector3 centroidOf(const std::vector<btVector3>& vertices, const std::vector<uint32_t>& ids) {
  btVector3 sum(0, 0, 0);
  for (uint32_t i : ids) sum += vertices[i];
  return ids.empty() ? sum : sum / btScalar(ids.size());
}

/// Surface vertices in an area given by a bone, landmarks or indices (FarEnd is resolved by the
/// caller).
std::vector<uint32_t> areaVertices(const TriangleMesh& surface, const AttachmentArea& area,
                                   const std::string& what, std::vector<std::string>& warnings) {
  std::vector<uint32_t> ids;
  const size_t n = surface.vertices.size();
  if (area.kind == AttachmentArea::Kind::Bone) {
    if (!area.bone || area.bone->empty()) return ids;
    MeshDistance bone(*area.bone);
    std::vector<btScalar> distance(n);
    btScalar nearest = std::numeric_limits<btScalar>::infinity();
    for (size_t i = 0; i < n; ++i) {
      const auto c = bone.closest(surface.vertices[i]);
      distance[i] = c.inside ? 0 : c.distance;
      nearest = std::min(nearest, distance[i]);
    }
    btScalar limit = area.distance;
    if (nearest >= limit) {
      limit = nearest + area.distance;
      warnings.push_back(what + ": no surface vertex within " +
                         std::to_string(area.distance * 1000) + " mm of the bone (nearest " +
                         std::to_string(nearest * 1000) + " mm); using vertices within " +
                         std::to_string(limit * 1000) + " mm");
    }
    for (size_t i = 0; i < n; ++i)
      if (distance[i] < limit) ids.push_back(uint32_t(i));
  } else if (area.kind == AttachmentArea::Kind::Vertices) {
    for (uint32_t i : area.vertices)
      if (i >= n)
        throw InputError(what, "vertices",
                         "vertex " + std::to_string(i) + " is out of range (the surface has " +
                             std::to_string(n) + " vertices)");
    ids = area.vertices;
    std::sort(ids.begin(), ids.end());
    ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  } else if (area.kind == AttachmentArea::Kind::Landmarks) {
    btScalar radius = area.radius;
    for (int attempt = 0; attempt < 2 && ids.empty(); ++attempt) {
      for (size_t i = 0; i < n; ++i)
        for (const auto& p : area.landmarks)
          if (surface.vertices[i].distance(p) < radius) {
            ids.push_back(uint32_t(i));
            break;
          }
      if (ids.empty()) {
        btScalar nearest = std::numeric_limits<btScalar>::infinity();
        for (const auto& v : surface.vertices)
          for (const auto& p : area.landmarks) nearest = std::min(nearest, v.distance(p));
        radius = nearest + area.radius;
        warnings.push_back(what + ": no surface vertex within the landmark radius; using " +
                           std::to_string(radius * 1000) + " mm");
      }
    }
  }
  return ids;
}

/// A bone area may take in places where the muscle only passes over the bone (the psoas over
/// the femoral head on its way to the lesser trochanter). Of its surface-connected patches, the
/// one reaching nearest an end of the muscle's main axis is kept, with any other patch reaching
/// within 15 % of the length of that end; the others are dropped with a warning.
void keepEndPatches(const TriangleMesh& surface, std::vector<uint32_t>& ids,
                    const std::string& what, std::vector<std::string>& warnings) {
  const auto& V = surface.vertices;
  std::vector<uint32_t> parent(V.size());
  std::iota(parent.begin(), parent.end(), 0u);
  const auto root = [&](uint32_t v) { return unionFindRoot(parent, v); };
  std::vector<char> in(V.size(), 0);
  for (uint32_t i : ids) in[i] = 1;
  for (const auto& t : surface.triangles)
    for (int e = 0; e < 3; ++e)
      if (in[t[e]] && in[t[(e + 1) % 3]]) parent[root(t[e])] = root(t[(e + 1) % 3]);
  btVector3 centroid, axis;
  principalAxis(V, centroid, axis);
  btScalar lo = std::numeric_limits<btScalar>::infinity(), hi = -lo;
  for (const auto& v : V) {
    lo = std::min(lo, (v - centroid).dot(axis));
    hi = std::max(hi, (v - centroid).dot(axis));
  }
  // Per patch: how near it reaches to the low end and to the high end.
  std::unordered_map<uint32_t, std::pair<btScalar, btScalar>> reach;
  for (uint32_t i : ids) {
    const btScalar s = (V[i] - centroid).dot(axis);
    auto [it, fresh] = reach.try_emplace(root(i), s - lo, hi - s);
    it->second = {std::min(it->second.first, s - lo), std::min(it->second.second, hi - s)};
  }
  if (reach.size() < 2) return;
  bool lowEnd = true;
  btScalar nearest = std::numeric_limits<btScalar>::infinity();
  for (const auto& [patch, gaps] : reach)
    for (int end = 0; end < 2; ++end)
      if ((end ? gaps.second : gaps.first) < nearest)
        nearest = end ? gaps.second : gaps.first, lowEnd = end == 0;
  const btScalar limit = btScalar(0.15) * (hi - lo);
  std::vector<uint32_t> kept;
  for (uint32_t i : ids) {
    const auto& gaps = reach[root(i)];
    if ((lowEnd ? gaps.first : gaps.second) <= limit) kept.push_back(i);
  }
  if (kept.size() == ids.size()) return;
  warnings.push_back(what + ": " + std::to_string(ids.size() - kept.size()) + " of " +
                     std::to_string(ids.size()) +
                     " vertices near the bone lie away from the muscle's ends (where it passes "
                     "over the bone) and are left out of the area");
  ids.swap(kept);
}

/// Vertices at the end of the main axis farthest from `from` (or the low end when from is null).
std::vector<uint32_t> farEnd(const TriangleMesh& surface, const btVector3* from, bool lowEnd,
                             double fraction, btScalar depth) {
  btVector3 centroid, axis;
  principalAxis(surface.vertices, centroid, axis);
  if (from) {
    if ((*from - centroid).dot(axis) > 0) axis = -axis;
  } else if (lowEnd) {
    axis = -axis;
  }
  btScalar lo = std::numeric_limits<btScalar>::infinity(), hi = -lo;
  for (const auto& v : surface.vertices) {
    const btScalar s = (v - centroid).dot(axis);
    lo = std::min(lo, s);
    hi = std::max(hi, s);
  }
  const btScalar cut = depth > 0 ? hi - depth : hi - btScalar(fraction) * (hi - lo);
  std::vector<uint32_t> ids;
  for (size_t i = 0; i < surface.vertices.size(); ++i)
    if ((surface.vertices[i] - centroid).dot(axis) >= cut) ids.push_back(uint32_t(i));
  return ids;
}

/// Farthest-point order of a vertex subset, starting near the subset's centroid.
std::vector<uint32_t> farthestPointOrder(const std::vector<btVector3>& vertices,
                                         const std::vector<uint32_t>& ids, size_t count) {
  std::vector<uint32_t> order;
  if (ids.empty()) return order;
  const btVector3 centre = centroidOf(vertices, ids);
  size_t first = 0;
  btScalar best = std::numeric_limits<btScalar>::infinity();
  for (size_t k = 0; k < ids.size(); ++k)
    if (vertices[ids[k]].distance2(centre) < best)
      best = vertices[ids[k]].distance2(centre), first = k;
  std::vector<btScalar> distance(ids.size(), std::numeric_limits<btScalar>::infinity());
  size_t next = first;
  count = std::min(count, ids.size());
  while (order.size() < count) {
    order.push_back(ids[next]);
    const btVector3 p = vertices[ids[next]];
    btScalar far = -1;
    for (size_t k = 0; k < ids.size(); ++k) {
      distance[k] = std::min(distance[k], vertices[ids[k]].distance2(p));
      if (distance[k] > far) far = distance[k], next = k;
    }
    if (far <= 0) break;
  }
  return order;
}

/// A scalar field on a regular grid with trilinear interpolation.
struct Grid {
  int n[3] = {0, 0, 0};
  btVector3 lower{0, 0, 0};
  btScalar h = 1;
  size_t index(int i, int j, int k) const { return (size_t(k) * n[1] + j) * n[0] + i; }
  size_t size() const { return size_t(n[0]) * n[1] * n[2]; }
  btVector3 centre(int i, int j, int k) const {
    return lower + btVector3(btScalar(i), btScalar(j), btScalar(k)) * h;
  }
  /// Trilinear interpolation of `field` (3 components when `stride` is 3).
  template <int C>
  std::array<double, C> sample(const std::vector<double>& field, const btVector3& p) const {
    const btVector3 g = (p - lower) / h;
    int base[3];
    double t[3];
    for (int a = 0; a < 3; ++a) {
      const double x = std::clamp(double(g[a]), 0.0, double(n[a] - 1) - 1e-9);
      base[a] = std::min(int(std::floor(x)), n[a] - 2);
      t[a] = x - base[a];
    }
    std::array<double, C> out{};
    for (int c = 0; c < 8; ++c) {
      const int di = c & 1, dj = (c >> 1) & 1, dk = (c >> 2) & 1;
      const double w = (di ? t[0] : 1 - t[0]) * (dj ? t[1] : 1 - t[1]) * (dk ? t[2] : 1 - t[2]);
      const size_t id = index(base[0] + di, base[1] + dj, base[2] + dk);
      for (int q = 0; q < C; ++q) out[q] += w * field[id * C + q];
    }
    return out;
  }
};

/// The six face neighbours of a voxel, as index offsets.
constexpr int kOffsets[6][3] = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},
                                {0, -1, 0}, {0, 0, 1},  {0, 0, -1}};

/// Face neighbour d (of 6) of voxel `id` in `out`; false beyond the grid.
bool neighbourOf(const Grid& grid, size_t id, int d, size_t& out) {
  const int i = int(id % grid.n[0]), j = int((id / grid.n[0]) % grid.n[1]),
            k = int(id / (size_t(grid.n[0]) * grid.n[1]));
  const int a = i + kOffsets[d][0], b = j + kOffsets[d][1], c = k + kOffsets[d][2];
  if (a < 0 || b < 0 || c < 0 || a >= grid.n[0] || b >= grid.n[1] || c >= grid.n[2]) return false;
  out = grid.index(a, b, c);
  return true;
}

/// Voxel grid: every voxel's label, -1 outside, 0 free, 1 origin (u = 0), 2 insertion (u = 1):
/// an inside voxel within a voxel of the surface takes the area most of its closest triangle's
/// vertices are in.
std::vector<int8_t> labelVoxels(const TriangleMesh& surface, const MeshDistance& distance,
                                const Grid& grid, const std::vector<uint32_t>& originIds,
                                const std::vector<uint32_t>& insertionIds) {
  const auto& V = surface.vertices;
  const btScalar h = grid.h;
  std::vector<int8_t> label(grid.size(), -1);
  std::vector<char> inOrigin(V.size(), 0), inInsertion(V.size(), 0);
  for (uint32_t i : originIds) inOrigin[i] = 1;
  for (uint32_t i : insertionIds) inInsertion[i] = 1;
  for (int k = 0; k < grid.n[2]; ++k)
    for (int j = 0; j < grid.n[1]; ++j)
      for (int i = 0; i < grid.n[0]; ++i) {
        const size_t id = grid.index(i, j, k);
        const auto c = distance.closest(grid.centre(i, j, k));
        if (!c.inside) continue;
        label[id] = 0;
        if (c.distance < h && c.triangle != UINT32_MAX) {
          int o = 0, s = 0;
          for (uint32_t v : surface.triangles[c.triangle]) o += inOrigin[v], s += inInsertion[v];
          if (o > s)
            label[id] = 1;
          else if (s > o)
            label[id] = 2;
        }
      }
  return label;
}

/// Keeps the interior voxels connected to both areas (others would make the system singular).
void keepConnectedVoxels(const Grid& grid, std::vector<int8_t>& label) {
  const size_t N = grid.size();
  std::vector<int> component(N, -1);
  std::vector<size_t> stack;
  int components = 0;
  std::vector<std::array<bool, 2>> touches;
  for (size_t id = 0; id < N; ++id) {
    if (label[id] < 0 || component[id] >= 0) continue;
    touches.push_back({false, false});
    stack.push_back(id);
    component[id] = components;
    while (!stack.empty()) {
      const size_t v = stack.back();
      stack.pop_back();
      if (label[v] == 1) touches.back()[0] = true;
      if (label[v] == 2) touches.back()[1] = true;
      for (int d = 0; d < 6; ++d) {
        size_t w;
        if (neighbourOf(grid, v, d, w) && label[w] >= 0 && component[w] < 0) {
          component[w] = components;
          stack.push_back(w);
        }
      }
    }
    ++components;
  }
  for (size_t id = 0; id < N; ++id)
    if (label[id] >= 0 && !(touches[component[id]][0] && touches[component[id]][1])) label[id] = -1;
}

/// Laplace: 7-point stencil, Neumann at the surface, Dirichlet 0 / 1 at the areas; the field
/// per voxel (0 outside).
std::vector<double> solveField(const Grid& grid, const std::vector<int8_t>& label,
                               const std::string& source, std::vector<std::string>& warnings) {
  const size_t N = grid.size();
  std::vector<int> unknown(N, -1);
  int unknowns = 0;
  for (size_t id = 0; id < N; ++id)
    if (label[id] == 0) unknown[id] = unknowns++;
  std::vector<double> u(N, 0);
  for (size_t id = 0; id < N; ++id) u[id] = label[id] == 2 ? 1.0 : 0.0;
  if (unknowns == 0) return u;
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(size_t(unknowns) * 7);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(unknowns);
  for (size_t id = 0; id < N; ++id) {
    if (unknown[id] < 0) continue;
    const int row = unknown[id];
    double degree = 0;
    for (int d = 0; d < 6; ++d) {
      size_t w;
      if (!neighbourOf(grid, id, d, w) || label[w] < 0) continue;
      degree += 1;
      if (unknown[w] >= 0)
        triplets.emplace_back(row, unknown[w], -1.0);
      else if (label[w] == 2)
        rhs[row] += 1.0;
    }
    triplets.emplace_back(row, row, std::max(degree, 1.0));
  }
  Eigen::SparseMatrix<double> A(unknowns, unknowns);
  A.setFromTriplets(triplets.begin(), triplets.end());
  Eigen::ConjugateGradient<Eigen::SparseMatrix<double>, Eigen::Lower | Eigen::Upper,
                           Eigen::IncompleteCholesky<double>>
      solver;
  solver.setTolerance(1e-8);
  solver.setMaxIterations(5000);
  solver.compute(A);
  Eigen::VectorXd x = solver.solve(rhs);
  if (solver.info() != Eigen::Success && solver.error() > 1e-4)
    warnings.push_back(source + ": the Laplace solve did not converge (error " +
                       std::to_string(solver.error()) + ")");
  for (size_t id = 0; id < N; ++id)
    if (unknown[id] >= 0) u[id] = std::clamp(x[unknown[id]], 0.0, 1.0);
  return u;
}

/// Extends the field a few voxels outwards (mean of known neighbours) for interpolation.
void extendField(const Grid& grid, const std::vector<int8_t>& label, std::vector<double>& u) {
  const size_t N = grid.size();
  std::vector<char> known(N, 0);
  for (size_t id = 0; id < N; ++id) known[id] = label[id] >= 0;
  for (int pass = 0; pass < 3; ++pass) {
    std::vector<std::pair<size_t, double>> updates;
    for (size_t id = 0; id < N; ++id) {
      if (known[id]) continue;
      double sum = 0;
      int count = 0;
      for (int d = 0; d < 6; ++d) {
        size_t w;
        if (neighbourOf(grid, id, d, w) && known[w]) sum += u[w], ++count;
      }
      if (count) updates.emplace_back(id, sum / count);
    }
    for (auto& [id, value] : updates) u[id] = value, known[id] = 1;
  }
}

/// The field's gradient by central differences (one-sided at the grid's edges), 3 per voxel.
std::vector<double> fieldGradient(const Grid& grid, const std::vector<double>& u) {
  std::vector<double> gradient(grid.size() * 3, 0);
  for (int k = 0; k < grid.n[2]; ++k)
    for (int j = 0; j < grid.n[1]; ++j)
      for (int i = 0; i < grid.n[0]; ++i) {
        const int c[3] = {i, j, k};
        const size_t id = grid.index(i, j, k);
        for (int a = 0; a < 3; ++a) {
          int lo3[3] = {i, j, k}, hi3[3] = {i, j, k};
          lo3[a] = std::max(c[a] - 1, 0);
          hi3[a] = std::min(c[a] + 1, grid.n[a] - 1);
          const double span = double(hi3[a] - lo3[a]) * grid.h;
          gradient[id * 3 + a] =
              (u[grid.index(hi3[0], hi3[1], hi3[2])] - u[grid.index(lo3[0], lo3[1], lo3[2])]) /
              span;
        }
      }
  return gradient;
}

/// Arc-length resampling to `samples` points.
std::vector<btVector3> resample(const std::vector<btVector3>& line, int samples) {
  std::vector<double> s(line.size(), 0);
  for (size_t i = 1; i < line.size(); ++i) s[i] = s[i - 1] + line[i].distance(line[i - 1]);
  std::vector<btVector3> out;
  size_t seg = 1;
  for (int q = 0; q < samples; ++q) {
    const double target = s.back() * q / (samples - 1);
    while (seg + 1 < line.size() && s[seg] < target) ++seg;
    const double span = s[seg] - s[seg - 1];
    const double t = span > 0 ? std::clamp((target - s[seg - 1]) / span, 0.0, 1.0) : 0.0;
    out.push_back(line[seg - 1].lerp(line[seg], btScalar(t)));
  }
  return out;
}

double segmentDistance2(const btVector3& p1, const btVector3& q1, const btVector3& p2,
                        const btVector3& q2) {
  // Closest points of two segments (Ericson, Real-Time Collision Detection 5.1.9).
  const btVector3 d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
  const double a = d1.dot(d1), e = d2.dot(d2), f = d2.dot(r);
  double s = 0, t = 0;
  if (a <= 1e-20 && e <= 1e-20) return r.length2();
  if (a <= 1e-20) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= 1e-20) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2), denom = a * e - b * b;
      s = denom > 1e-20 ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0)
        t = 0, s = std::clamp(-c / a, 0.0, 1.0);
      else if (t > 1)
        t = 1, s = std::clamp((b - c) / a, 0.0, 1.0);
    }
  }
  const btVector3 c1 = p1 + d1 * btScalar(s), c2 = p2 + d2 * btScalar(t);
  return (c1 - c2).length2();
}

/// Takes the vertices in both areas out of both (the field would be ill-posed there); returns
/// how many there were.
size_t removeSharedVertices(size_t vertexCount, std::vector<uint32_t>& originIds,
                            std::vector<uint32_t>& insertionIds) {
  std::vector<char> inOrigin(vertexCount, 0), inInsertion(vertexCount, 0);
  for (uint32_t i : originIds) inOrigin[i] = 1;
  for (uint32_t i : insertionIds) inInsertion[i] = 1;
  const size_t before = originIds.size();
  std::erase_if(originIds, [&](uint32_t i) { return inInsertion[i] != 0; });
  std::erase_if(insertionIds, [&](uint32_t i) { return inOrigin[i] != 0; });
  return before - originIds.size();
}

/// The surface vertices of both attachment areas (result.originArea, result.insertionArea).
void resolveAreas(const TriangleMesh& surface, const AttachmentArea& origin,
                  const AttachmentArea& insertion, const std::string& source,
                  FibreGenerationResult& result) {
  const auto& V = surface.vertices;
  std::vector<uint32_t> originIds =
      areaVertices(surface, origin, source + ": origin", result.warnings);
  std::vector<uint32_t> insertionIds =
      areaVertices(surface, insertion, source + ": insertion", result.warnings);
  if (origin.kind == AttachmentArea::Kind::Bone)
    keepEndPatches(surface, originIds, source + ": origin", result.warnings);
  if (insertion.kind == AttachmentArea::Kind::Bone)
    keepEndPatches(surface, insertionIds, source + ": insertion", result.warnings);
  const bool originFar = origin.kind == AttachmentArea::Kind::FarEnd;
  const bool insertionFar = insertion.kind == AttachmentArea::Kind::FarEnd;
  if (originFar && insertionFar) {
    originIds = farEnd(surface, nullptr, true, origin.endFraction, origin.endDepth);
    insertionIds = farEnd(surface, nullptr, false, insertion.endFraction, insertion.endDepth);
  } else if (originFar) {
    const btVector3 c = centroidOf(V, insertionIds);
    originIds = farEnd(surface, &c, false, origin.endFraction, origin.endDepth);
  } else if (insertionFar) {
    const btVector3 c = centroidOf(V, originIds);
    insertionIds = farEnd(surface, &c, false, insertion.endFraction, insertion.endDepth);
  }
  const size_t shared = removeSharedVertices(V.size(), originIds, insertionIds);
  if (shared)
    result.warnings.push_back(source + ": " + std::to_string(shared) +
                              " surface vertices are in both attachment areas; left out of both");
  if (originIds.empty() || insertionIds.empty()) {
    const std::string empty = originIds.empty() ? "origin" : "insertion";
    const std::string other = originIds.empty() ? "insertion" : "origin";
    throw InputError(source, empty,
                     shared == 0 ? "the attachment area holds no surface vertex"
                                 : "the origin and insertion areas overlap: each of this area's "
                                   "surface vertices is also in the " +
                                       other + " area (" + std::to_string(shared) +
                                       " vertices in both); expected areas apart");
  }
  result.quality.originVertices = originIds.size();
  result.quality.insertionVertices = insertionIds.size();
  result.originArea = std::move(originIds);
  result.insertionArea = std::move(insertionIds);
}

using Lines = std::vector<std::vector<btVector3>>;

/// Quality: lengths, points outside, right ends (each end within 1.5 voxels `h`, the field's
/// resolution, of its area's triangles: those with a vertex in the area).
void measureFibres(const TriangleMesh& surface, const MeshDistance& distance,
                   const std::vector<uint32_t>& originIds,
                   const std::vector<uint32_t>& insertionIds, const Lines& lines,
                   btScalar insideTolerance, btScalar h, FibreQuality& q) {
  const auto& V = surface.vertices;
  std::vector<btScalar> lengths;
  int right = 0;
  auto areaSurface = [&](const std::vector<uint32_t>& ids) {
    std::vector<char> in(V.size(), 0);
    for (uint32_t i : ids) in[i] = 1;
    TriangleMesh area;
    area.vertices = V;
    for (const auto& t : surface.triangles)
      if (in[t[0]] || in[t[1]] || in[t[2]]) area.triangles.push_back(t);
    return MeshDistance(area);
  };
  const MeshDistance originSurface = areaSurface(originIds);
  const MeshDistance insertionSurface = areaSurface(insertionIds);
  for (const auto& l : lines) {
    btScalar length = 0;
    for (size_t i = 1; i < l.size(); ++i) length += l[i].distance(l[i - 1]);
    lengths.push_back(length);
    for (const auto& p : l) q.pointsOutside += distance.signedDistance(p) > insideTolerance;
    const btScalar gap = std::max(originSurface.closest(l.front()).distance,
                                  insertionSurface.closest(l.back()).distance);
    q.worstEndGap = std::max(q.worstEndGap, gap);
    right += gap <= btScalar(1.5) * h;
  }
  if (!lengths.empty()) {
    std::sort(lengths.begin(), lengths.end());
    q.minLength = lengths.front();
    q.maxLength = lengths.back();
    q.medianLength = lengths[lengths.size() / 2];
    q.rightEnds = double(right) / double(lines.size());
  }
}

/// Coverage: interior voxels within `r` (coverageDistance) of a fibre point (points dense
/// enough).
void measureCoverage(const Grid& grid, const std::vector<int8_t>& label, const Lines& lines,
                     btScalar r, FibreQuality& q) {
  const btScalar h = grid.h;
  const size_t N = grid.size();
  std::vector<char> covered(N, 0);
  const int reach = int(std::ceil(r / h));
  for (const auto& l : lines) {
    std::vector<btVector3> dense;
    for (size_t i = 1; i < l.size(); ++i) {
      const int parts = std::max(1, int(std::ceil(l[i].distance(l[i - 1]) / (r / 2))));
      for (int s = 0; s < parts; ++s) dense.push_back(l[i - 1].lerp(l[i], btScalar(s) / parts));
    }
    dense.push_back(l.back());
    for (const auto& p : dense) {
      const btVector3 g = (p - grid.lower) / h;
      const int ci = int(std::lround(g.x())), cj = int(std::lround(g.y())),
                ck = int(std::lround(g.z()));
      for (int k = std::max(0, ck - reach); k <= std::min(grid.n[2] - 1, ck + reach); ++k)
        for (int j = std::max(0, cj - reach); j <= std::min(grid.n[1] - 1, cj + reach); ++j)
          for (int i = std::max(0, ci - reach); i <= std::min(grid.n[0] - 1, ci + reach); ++i)
            if (grid.centre(i, j, k).distance2(p) <= r * r) covered[grid.index(i, j, k)] = 1;
    }
  }
  size_t hit = 0;
  for (size_t id = 0; id < N; ++id) hit += label[id] >= 0 && covered[id];
  q.coverage = double(hit) / double(q.interiorVoxels);
}

/// Crossings: fibre pairs with segments closer than the tolerance (hash grid of segments).
void countCrossings(const Grid& grid, const Lines& lines, const FibreGenerationOptions& options,
                    FibreQuality& q) {
  const btScalar tol = options.crossingTolerance;
  const btScalar cell = std::max(tol * 4, grid.h);
  struct Seg {
    uint32_t fibre, index;
  };
  std::unordered_map<uint64_t, std::vector<Seg>> buckets;
  auto key = [&](int i, int j, int k) {
    return (uint64_t(uint32_t(i + 1048576)) << 42) ^ (uint64_t(uint32_t(j + 1048576)) << 21) ^
           uint64_t(uint32_t(k + 1048576));
  };
  auto cellOf = [&](const btVector3& p, int c[3]) {
    for (int a = 0; a < 3; ++a) c[a] = int(std::floor((p[a] - grid.lower[a]) / cell));
  };
  for (uint32_t f = 0; f < lines.size(); ++f)
    for (uint32_t s = 0; s + 1 < lines[f].size(); ++s) {
      int c[3];
      cellOf((lines[f][s] + lines[f][s + 1]) / 2, c);
      buckets[key(c[0], c[1], c[2])].push_back({f, s});
    }
  std::vector<char> pair(lines.size() * lines.size(), 0);
  const btScalar segmentLength = lines.empty() ? 0 : q.maxLength / btScalar(options.samples - 1);
  const int reach = 1 + int(std::ceil(segmentLength / cell));
  for (uint32_t f = 0; f < lines.size(); ++f)
    for (uint32_t s = 0; s + 1 < lines[f].size(); ++s) {
      int c[3];
      cellOf((lines[f][s] + lines[f][s + 1]) / 2, c);
      for (int dk = -reach; dk <= reach; ++dk)
        for (int dj = -reach; dj <= reach; ++dj)
          for (int di = -reach; di <= reach; ++di) {
            auto it = buckets.find(key(c[0] + di, c[1] + dj, c[2] + dk));
            if (it == buckets.end()) continue;
            for (const Seg& other : it->second) {
              if (other.fibre <= f || pair[f * lines.size() + other.fibre]) continue;
              if (segmentDistance2(lines[f][s], lines[f][s + 1], lines[other.fibre][other.index],
                                   lines[other.fibre][other.index + 1]) < double(tol) * tol) {
                pair[f * lines.size() + other.fibre] = 1;
                ++q.crossingPairs;
              }
            }
          }
    }
}

/// The voxel grid around the muscle: `gridSize` voxels along its longest side (`extent`, the
/// bounds' size [m]) and a voxel's margin on every side; its size into `q`.
Grid voxelGrid(const std::vector<btVector3>& V, int gridSize, btVector3& extent, FibreQuality& q) {
  btVector3 lo, hi;
  pointBounds(V, lo, hi);
  extent = hi - lo;
  const btScalar longest = std::max({extent.x(), extent.y(), extent.z()});
  Grid grid;
  grid.h = longest / btScalar(gridSize - 1);
  for (int a = 0; a < 3; ++a) grid.n[a] = int(std::ceil(extent[a] / grid.h)) + 3;
  grid.lower = lo - btVector3(grid.h, grid.h, grid.h);
  for (int a = 0; a < 3; ++a) q.gridCells[a] = grid.n[a];
  q.voxelSize = grid.h;
  return grid;
}

/// The harmonic field on the voxel grid: its labels, values and gradient.
struct Field {
  std::vector<int8_t> label;     ///< per voxel: < 0 outside, else interior or an area
  std::vector<double> u;         ///< per voxel: 0 at the origin area .. 1 at the insertion
  std::vector<double> gradient;  ///< per voxel: du/dx, three components [1/m]
};

/// Labels the voxels, keeps the connected interior and solves the field; false (and no field)
/// when no interior voxel is left.
bool solveOnGrid(const TriangleMesh& surface, const MeshDistance& distance, const Grid& grid,
                 const std::string& source, FibreGenerationResult& result, Field& field) {
  FibreQuality& q = result.quality;
  field.label = labelVoxels(surface, distance, grid, result.originArea, result.insertionArea);
  keepConnectedVoxels(grid, field.label);
  for (size_t id = 0; id < grid.size(); ++id) q.interiorVoxels += field.label[id] >= 0;
  if (q.interiorVoxels == 0) return false;
  field.u = solveField(grid, field.label, source, result.warnings);
  extendField(grid, field.label, field.u);
  field.gradient = fieldGradient(grid, field.u);
  return true;
}

/// Vertex normals of a surface, area weighted and not normalised.
std::vector<btVector3> vertexNormals(const TriangleMesh& surface) {
  const auto& V = surface.vertices;
  std::vector<btVector3> normals(V.size(), btVector3(0, 0, 0));
  for (const auto& t : surface.triangles) {
    const btVector3 n = (V[t[1]] - V[t[0]]).cross(V[t[2]] - V[t[0]]);
    for (uint32_t v : t) normals[v] += n;
  }
  return normals;
}

/// Streamlines of the field's gradient inside the surface, from one seed at a time.
class Streamlines {
 public:
  Streamlines(const TriangleMesh& surface, const MeshDistance& distance, const Grid& grid,
              const Field& field, const FibreGenerationResult& result, btScalar insideTolerance,
              const btVector3& extent)
      : V_(surface.vertices),
        distance_(distance),
        grid_(grid),
        field_(field),
        originIds_(result.originArea),
        insertionIds_(result.insertionArea),
        insideTolerance_(insideTolerance),
        h_(grid.h),
        endTolerance_(btScalar(2.5) * h_),
        step_(h_ / 2),
        maxLength_(btScalar(6) * (extent.length() + h_)) {}

  /// Traces one streamline from a seed on the origin area (normal: the surface's outward
  /// normal there) or, for a seed inside (`inside`), both ways. 0 ok, 1 left the surface, 2
  /// stopped early.
  int trace(const btVector3& seed, const btVector3& normal, bool inside,
            std::vector<btVector3>& line) {
    line.clear();
    if (inside) {
      back_.assign(1, seed);
      if (const int status = traceTo(-1, back_)) return status;
      line.assign(back_.rbegin(), back_.rend());
      return traceTo(1, line);
    }
    btVector3 p = seed - normal * (h_ / 8);
    if (distance_.signedDistance(p) > 0) p = seed;
    line.push_back(p);
    // Leave the flat (Dirichlet) layer under the area inwards, so that the streamline starts
    // where the field rises rather than sliding along the surface.
    for (int k = 0; k < 8; ++k) {
      btVector3 d;
      if (directionAt(p, d) && fieldAt(p) > 1e-3) break;
      const btVector3 next = p - normal * (h_ / 2);
      if (distance_.signedDistance(next) > -h_ / 8) break;
      p = next;
      line.push_back(p);
    }
    return traceTo(1, line);
  }

 private:
  /// Distance from a point to the nearest vertex of an area (brute force over the area) [m].
  btScalar nearestIn(const std::vector<uint32_t>& ids, const btVector3& p) const {
    btScalar best = std::numeric_limits<btScalar>::infinity();
    for (uint32_t i : ids) best = std::min(best, V_[i].distance2(p));
    return std::sqrt(best);
  }
  double fieldAt(const btVector3& p) const { return grid_.sample<1>(field_.u, p)[0]; }
  /// The gradient's direction at p into `dir`; false where it vanishes.
  bool directionAt(const btVector3& p, btVector3& dir) const {
    const auto g = grid_.sample<3>(field_.gradient, p);
    const btVector3 v{btScalar(g[0]), btScalar(g[1]), btScalar(g[2])};
    if (v.length2() < btScalar(1e-12)) return false;
    dir = v.normalized();
    return true;
  }

  /// Follows the gradient (sign +1, towards the insertion) or against it (-1, towards the
  /// origin) from line.back() until the field reaches that end's area; the end is moved onto
  /// the surface, a little inside. 0 ok, 1 left the surface, 2 stopped early.
  int traceTo(double sign, std::vector<btVector3>& line) const {
    const std::vector<uint32_t>& target = sign > 0 ? insertionIds_ : originIds_;
    btVector3 p = line.back();
    btScalar travelled = 0;
    while (travelled < maxLength_) {
      const double value = fieldAt(p);
      if (sign > 0 ? value >= 0.995 : value <= 0.005) break;
      btVector3 d1, d2;
      if (!directionAt(p, d1)) return 2;
      d1 *= btScalar(sign);
      if (!directionAt(p + d1 * (step_ / 2), d2)) return 2;
      const btVector3 next = p + d2 * (step_ * btScalar(sign));
      if (distance_.signedDistance(next) > insideTolerance_) {
        // Slide along the surface: pull back inside along the closest-point direction.
        const auto c = distance_.closest(next);
        const btVector3 pulled = c.point + (c.point - next).normalized() * (h_ / 4);
        if (nearestIn(target, next) < endTolerance_) break;
        if (distance_.signedDistance(pulled) > 0) return 1;
        p = pulled;
      } else {
        p = next;
      }
      travelled += step_;
      line.push_back(p);
    }
    if (nearestIn(target, line.back()) >= endTolerance_) return 2;
    endOnSurface(line);
    return 0;
  }

  /// Ends a line on the surface: the closest surface point, a little inside.
  void endOnSurface(std::vector<btVector3>& line) const {
    const auto c = distance_.closest(line.back());
    if (c.triangle != UINT32_MAX && c.distance > h_ / 8) {
      const btVector3 last = c.point + (line.back() - c.point).normalized() * (h_ / 8);
      if (distance_.signedDistance(last) <= 0) line.push_back(last);
    }
  }

  const std::vector<btVector3>& V_;            ///< the surface's vertices [m]
  const MeshDistance& distance_;               ///< distance to the surface
  const Grid& grid_;                           ///< the field's voxel grid
  const Field& field_;                         ///< the field and its gradient
  const std::vector<uint32_t>& originIds_;     ///< the origin area's vertices
  const std::vector<uint32_t>& insertionIds_;  ///< the insertion area's vertices
  btScalar insideTolerance_;                   ///< a point this far outside the surface is out [m]
  btScalar h_;                                 ///< voxel size [m]
  btScalar endTolerance_;        ///< a line ends this close to its area's vertices [m]
  btScalar step_;                ///< streamline step [m]
  btScalar maxLength_;           ///< a line stops after this length [m]
  std::vector<btVector3> back_;  ///< scratch: a seed's line towards the origin
};

/// Seeds and their surface normals (zero inside the muscle).
struct SeedPool {
  std::vector<btVector3> points;   ///< seed positions [m]
  std::vector<btVector3> normals;  ///< outward unit normal at each seed, or zero
};

/// Points where the field crosses `level` between two interior voxels, linearly interpolated
/// (a cross-section of the muscle), into `points` when given; returns how many.
size_t levelCrossings(const Grid& grid, const Field& field, double level,
                      std::vector<btVector3>* points) {
  size_t count = 0;
  const std::vector<int8_t>& label = field.label;
  const std::vector<double>& u = field.u;
  for (size_t id = 0; id < grid.size(); ++id)
    for (int d = 0; d < 6; d += 2) {
      size_t w;
      if (label[id] < 0 || !neighbourOf(grid, id, d, w) || label[w] < 0) continue;
      const double a = u[id] - level, b = u[w] - level;
      if ((a < 0) == (b < 0)) continue;
      ++count;
      if (!points) continue;
      const int i = int(id % grid.n[0]), j = int((id / grid.n[0]) % grid.n[1]),
                k = int(id / (size_t(grid.n[0]) * grid.n[1]));
      const btVector3 edge =
          btVector3(btScalar(kOffsets[d][0]), btScalar(kOffsets[d][1]), btScalar(kOffsets[d][2])) *
          grid.h;
      points->push_back(grid.centre(i, j, k) + edge * btScalar(a / (a - b)));
    }
  return count;
}

/// Seeds on the widest of the field's levels 0.05, 0.1, ... 0.95 (most crossed voxel edges),
/// which farthest-point order then covers evenly; a narrow muscle's widest section may hold
/// too few seeds, so the next widest ones add theirs up to twice `count`.
void sectionSeeds(const Grid& grid, const Field& field, size_t count, SeedPool& pool) {
  std::vector<std::pair<size_t, double>> levels;
  for (int l = 1; l < 20; ++l)
    levels.emplace_back(levelCrossings(grid, field, l * 0.05, nullptr), l * 0.05);
  std::sort(levels.rbegin(), levels.rend());
  for (size_t l = 0; l < levels.size() && pool.points.size() < count * 2; ++l)
    levelCrossings(grid, field, levels[l].second, &pool.points);
  pool.normals.assign(pool.points.size(), btVector3(0, 0, 0));
}

/// Seeds on the origin area: its vertices, then `count` × 16 random points on its triangles
/// (a tapered end has few vertices), each with its normal.
void originSeeds(const TriangleMesh& surface, const std::vector<uint32_t>& originIds, size_t count,
                 SeedPool& pool) {
  const auto& V = surface.vertices;
  const std::vector<btVector3> normals = vertexNormals(surface);
  for (uint32_t v : originIds) {
    pool.points.push_back(V[v]);
    pool.normals.push_back(normals[v].length2() > 0 ? normals[v].normalized() : btVector3(0, 0, 0));
  }
  std::vector<char> inOrigin(V.size(), 0);
  for (uint32_t i : originIds) inOrigin[i] = 1;
  std::vector<uint32_t> areaTriangles;
  std::vector<double> cumulative;
  double total = 0;
  for (uint32_t t = 0; t < surface.triangles.size(); ++t) {
    const auto& tri = surface.triangles[t];
    if (!(inOrigin[tri[0]] && inOrigin[tri[1]] && inOrigin[tri[2]])) continue;
    total += double((V[tri[1]] - V[tri[0]]).cross(V[tri[2]] - V[tri[0]]).length());
    areaTriangles.push_back(t);
    cumulative.push_back(total);
  }
  uint64_t state = 0x9e3779b97f4a7c15ull;
  auto random = [&]() {  // splitmix64 -> [0, 1)
    uint64_t z = (state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return double((z ^ (z >> 31)) >> 11) * 0x1.0p-53;
  };
  const size_t extra = areaTriangles.empty() ? 0 : count * 16;
  for (size_t e = 0; e < extra; ++e) {
    const size_t at =
        size_t(std::lower_bound(cumulative.begin(), cumulative.end(), random() * total) -
               cumulative.begin());
    const auto& tri = surface.triangles[areaTriangles[std::min(at, areaTriangles.size() - 1)]];
    double a = random(), b = random();
    if (a + b > 1) a = 1 - a, b = 1 - b;
    pool.points.push_back(V[tri[0]] + (V[tri[1]] - V[tri[0]]) * btScalar(a) +
                          (V[tri[2]] - V[tri[0]]) * btScalar(b));
    pool.normals.push_back((V[tri[1]] - V[tri[0]]).cross(V[tri[2]] - V[tri[0]]).normalized());
  }
}

/// The points of the accepted fibres in a hash grid of cells `separation` wide, to find a new
/// fibre closer than `separation` to one of them.
class SeparationIndex {
 public:
  SeparationIndex(const btVector3& lower, btScalar separation)
      : lower_(lower), separation_(separation) {}

  /// Whether a point of `fibre` lies closer than the separation to an accepted point.
  bool tooClose(const std::vector<btVector3>& fibre) const {
    if (separation_ <= 0) return false;
    for (const auto& p : fibre)
      for (int dk = -1; dk <= 1; ++dk)
        for (int dj = -1; dj <= 1; ++dj)
          for (int di = -1; di <= 1; ++di) {
            const auto it = accepted_.find(cellKey(p, di, dj, dk));
            if (it == accepted_.end()) continue;
            for (const auto& o : it->second)
              if (o.distance2(p) < separation_ * separation_) return true;
          }
    return false;
  }
  /// Adds an accepted fibre's points.
  void accept(const std::vector<btVector3>& fibre) {
    if (separation_ <= 0) return;
    for (const auto& p : fibre) accepted_[cellKey(p, 0, 0, 0)].push_back(p);
  }

 private:
  uint64_t cellKey(const btVector3& p, int di, int dj, int dk) const {
    const btVector3 g = (p - lower_) / std::max(separation_, btScalar(1e-9));
    return (uint64_t(uint32_t(int(std::floor(g.x())) + di + 1048576)) << 42) ^
           (uint64_t(uint32_t(int(std::floor(g.y())) + dj + 1048576)) << 21) ^
           uint64_t(uint32_t(int(std::floor(g.z())) + dk + 1048576));
  }

  btVector3 lower_;      ///< the hash grid's origin [m]
  btScalar separation_;  ///< the least distance between fibres' points [m]; <= 0: none
  std::unordered_map<uint64_t, std::vector<btVector3>> accepted_;  ///< points per cell
};

/// Traces seeds in farthest-point order until options.count good fibres are made (the
/// candidates doubled while seeds remain), resampled to options.samples points. Fibres closer
/// than minSeparation to an accepted one (streamlines converging into a narrow tendon) are set
/// aside in `crowded`: near-coincident particles make springs of almost no rest length.
Lines traceSeeds(Streamlines& streamlines, const MeshDistance& distance, const SeedPool& pool,
                 bool inside, const FibreGenerationOptions& options, btScalar insideTolerance,
                 const btVector3& lower, Lines& crowded, FibreQuality& q) {
  Lines lines;
  SeparationIndex separation(lower, options.minSeparation);
  std::vector<uint32_t> poolIds(pool.points.size());
  std::iota(poolIds.begin(), poolIds.end(), 0u);
  const size_t wanted = size_t(options.count);
  const size_t maxTraced = wanted * 8;  // bounds the time when many seeds fail or crowd
  size_t candidates = std::min(pool.points.size(), wanted * 2);
  std::vector<uint32_t> order;
  size_t tried = 0;
  std::vector<btVector3> line;
  while (lines.size() < wanted) {
    order = farthestPointOrder(pool.points, poolIds, candidates);
    for (; tried < order.size() && lines.size() < wanted && size_t(q.traced) < maxTraced; ++tried) {
      ++q.traced;
      const uint32_t seed = order[tried];
      const int status = streamlines.trace(pool.points[seed], pool.normals[seed], inside, line);
      if (status == 1) ++q.droppedOutside;
      if (status == 2) ++q.droppedEarly;
      if (status != 0) continue;
      std::vector<btVector3> fibre = resample(line, options.samples);
      // Resampling cuts the corners of a streamline that slid along a concave surface.
      if (std::any_of(fibre.begin(), fibre.end(), [&](const btVector3& p) {
            return distance.signedDistance(p) > insideTolerance;
          })) {
        ++q.droppedOutside;
        continue;
      }
      if (separation.tooClose(fibre)) {
        crowded.push_back(std::move(fibre));
        continue;
      }
      separation.accept(fibre);
      lines.push_back(std::move(fibre));
    }
    if (candidates >= pool.points.size() || tried < order.size() || size_t(q.traced) >= maxTraced)
      break;
    candidates = std::min(pool.points.size(), candidates * 2);
  }
  return lines;
}

/// Voxelises the muscle at `gridSize` voxels along its longest side, solves the field and
/// traces up to options.count fibres into `result`. False when no interior voxel connects the
/// two areas at this grid.
bool traceOnGrid(const TriangleMesh& surface, const FibreGenerationOptions& options, int gridSize,
                 const std::string& source, FibreGenerationResult& result) {
  FibreQuality& q = result.quality;
  const MeshDistance distance(surface);
  btVector3 extent;
  const Grid grid = voxelGrid(surface.vertices, gridSize, extent, q);
  const btScalar insideTolerance =
      options.insideTolerance > 0 ? options.insideTolerance : grid.h / 4;
  Field field;
  if (!solveOnGrid(surface, distance, grid, source, result, field)) return false;

  // Seed pool: points on the widest cross-section (sectionSeeds), else the origin area's
  // vertices and random points on its triangles; seeds are taken in farthest-point order, the
  // first `count` good streamlines kept.
  SeedPool pool;
  if (options.sectionSeeds) sectionSeeds(grid, field, size_t(options.count), pool);
  const bool inside = !pool.points.empty();
  if (!inside) originSeeds(surface, result.originArea, size_t(options.count), pool);
  Streamlines streamlines(surface, distance, grid, field, result, insideTolerance, extent);
  Lines crowded;
  Lines lines = traceSeeds(streamlines, distance, pool, inside, options, insideTolerance,
                           grid.lower, crowded, q);
  q.crowded = int(crowded.size());
  for (size_t i = 0; i < crowded.size() && lines.size() < size_t(options.count); ++i)
    lines.push_back(std::move(crowded[i]));
  for (const auto& l : lines) result.fibres.addFibre(l);
  q.generated = int(lines.size());

  measureFibres(surface, distance, result.originArea, result.insertionArea, lines, insideTolerance,
                grid.h, q);
  measureCoverage(grid, field.label, lines, options.coverageDistance, q);
  countCrossings(grid, lines, options, q);
  return true;
}

}  // namespace

void resolveAttachmentAreas(const TriangleMesh& surface, const AttachmentArea& origin,
                            const AttachmentArea& insertion, const std::string& source,
                            std::vector<uint32_t>& originIds, std::vector<uint32_t>& insertionIds,
                            std::vector<std::string>& warnings) {
  FibreGenerationResult areas;
  resolveAreas(surface, origin, insertion, source, areas);
  originIds = std::move(areas.originArea);
  insertionIds = std::move(areas.insertionArea);
  warnings.insert(warnings.end(), areas.warnings.begin(), areas.warnings.end());
}

FibreGenerationResult generateFibres(const TriangleMesh& surface, const AttachmentArea& origin,
                                     const AttachmentArea& insertion,
                                     const FibreGenerationOptions& options,
                                     const std::string& source) {
  const auto start = Clock::now();
  if (surface.empty()) throw InputError(source, "", "the muscle surface has no triangles");
  if (options.count < 1 || options.samples < 2 || options.grid < 8 || options.maxGrid < 8 ||
      !(options.minShare >= 0 && options.minShare <= 1))
    throw InputError(source, "",
                     "fibre generation needs count >= 1, samples >= 2, grid >= 8, max grid >= 8 "
                     "and a minimum share in [0, 1]");
  FibreGenerationResult areas;
  resolveAreas(surface, origin, insertion, source, areas);
  areas.quality.requested = options.count;
  const int needed = std::max(1, int(std::ceil(options.minShare * options.count - 1e-9)));
  // Grids tried: the given one, then 1.5 times finer up to the cap, while the areas do not
  // connect or too few streamlines arrive (and the finer grid brought more).
  std::vector<int> tried;
  FibreGenerationResult best;
  bool connected = false;
  for (int gridSize = options.grid;;) {
    FibreGenerationResult attempt = areas;
    tried.push_back(gridSize);
    if (traceOnGrid(surface, options, gridSize, source, attempt)) {
      const bool better = !connected || attempt.quality.generated > best.quality.generated;
      connected = true;
      if (better) best = std::move(attempt);
      if (best.quality.generated >= needed || !better) break;
    }
    const int next = std::min(options.maxGrid, int(std::ceil(gridSize * 1.5)));
    if (next <= gridSize) break;
    gridSize = next;
  }
  std::string grids;
  for (int g : tried) grids += (grids.empty() ? "" : ", ") + std::to_string(g);
  if (!connected)
    throw InputError(source, "",
                     "no interior voxel connects the origin and insertion areas at grid " + grids +
                         " (voxels along the longest side; the cap is " +
                         std::to_string(options.maxGrid) +
                         "): the muscle is thinner than a voxel somewhere between them, or the "
                         "areas are not on its two ends; raise the grid cap or move the areas");
  const FibreQuality& q = best.quality;
  if (q.generated < needed)
    throw InputError(
        source, "",
        "made " + std::to_string(q.generated) + " of " + std::to_string(options.count) +
            " fibres, fewer than the " + std::to_string(needed) + " (" +
            std::to_string(int(std::lround(options.minShare * 100))) + " %) required (grid " +
            grids + "; " + std::to_string(q.droppedOutside) + " streamlines left the surface, " +
            std::to_string(q.droppedEarly) +
            " stopped before the insertion area); change: widen the attachment "
            "areas or put them on the muscle's two ends" +
            (q.generated > 0 ? ", ask for fewer fibres (" + std::to_string(q.generated) +
                                   "), or accept a smaller minimum share"
                             : std::string(" (no streamline joined them)")));
  if (tried.size() > 1)
    best.warnings.push_back(source + ": grid raised from " + std::to_string(options.grid) +
                            " (tried " + grids + ")");
  if (q.generated < options.count)
    best.warnings.push_back(source + ": made " + std::to_string(q.generated) + " of " +
                            std::to_string(options.count) + " fibres (" +
                            std::to_string(q.droppedOutside) + " left the surface, " +
                            std::to_string(q.droppedEarly) + " stopped early)");
  best.quality.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return best;
}

bool fitSphere(const std::vector<btVector3>& points, btVector3& centre, btScalar& radius) {
  if (points.size() < 4) return false;
  // |p|^2 = 2 c.p + (r^2 - |c|^2): linear least squares in (c, d).
  Eigen::MatrixXd A(points.size(), 4);
  Eigen::VectorXd b(points.size());
  const btVector3 shift = points.front();
  for (size_t i = 0; i < points.size(); ++i) {
    const btVector3 p = points[i] - shift;
    A.row(Eigen::Index(i)) << 2.0 * p.x(), 2.0 * p.y(), 2.0 * p.z(), 1.0;
    b[Eigen::Index(i)] = double(p.length2());
  }
  const Eigen::Vector4d x = A.colPivHouseholderQr().solve(b);
  const double r2 = x[3] + x.head<3>().squaredNorm();
  if (!(r2 > 0) || !std::isfinite(r2)) return false;
  centre = shift + btVector3(btScalar(x[0]), btScalar(x[1]), btScalar(x[2]));
  radius = btScalar(std::sqrt(r2));
  return true;
}

bool fitFemoralHead(const TriangleMesh& femur, const btVector3& up, btScalar depth,
                    btVector3& centre, btScalar& radius) {
  if (femur.vertices.empty()) return false;
  const btVector3 axis = up.normalized();
  btVector3 top = femur.vertices.front();
  for (const auto& v : femur.vertices)
    if (v.dot(axis) > top.dot(axis)) top = v;
  // First guess: vertices within `depth` of the topmost vertex (the head is the highest part).
  std::vector<btVector3> points;
  for (const auto& v : femur.vertices)
    if (v.distance(top) < depth) points.push_back(v);
  if (!fitSphere(points, centre, radius)) return false;
  // Refine: vertices near the fitted sphere and not below its centre's neck side.
  for (int pass = 0; pass < 5; ++pass) {
    points.clear();
    for (const auto& v : femur.vertices)
      if (std::abs(v.distance(centre) - radius) < btScalar(0.1) * radius) points.push_back(v);
    btVector3 c;
    btScalar r;
    if (!fitSphere(points, c, r)) break;
    centre = c;
    radius = r;
  }
  return true;
}

}  // namespace fibremss
