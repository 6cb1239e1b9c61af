#include <algorithm>
#include <cmath>
#include <utility>

#include "fibremss/Procedural.h"

namespace fibremss {
namespace {

constexpr int kSamplesPerSegment = 32;

btVector3 unitOr(const btVector3& v, const btVector3& fallback) {
  const btScalar length = v.length();
  return length > btScalar(1e-12) ? v / length : fallback;
}

// Centripetal Catmull-Rom (Barry-Goldman) on one segment p1..p2, s in [0, 1]: no cusps or
// self-loops where control points are unevenly spaced.
btVector3 catmullRom(const btVector3& p0, const btVector3& p1, const btVector3& p2,
                     const btVector3& p3, double s) {
  auto knot = [](double previous, const btVector3& a, const btVector3& b) {
    return previous + std::max(std::sqrt(double((b - a).length())), 1e-9);
  };
  const double t0 = 0, t1 = knot(t0, p0, p1), t2 = knot(t1, p1, p2), t3 = knot(t2, p2, p3);
  const double t = t1 + s * (t2 - t1);
  const btVector3 a1 = lerp(p0, p1, btScalar((t - t0) / (t1 - t0)));
  const btVector3 a2 = lerp(p1, p2, btScalar((t - t1) / (t2 - t1)));
  const btVector3 a3 = lerp(p2, p3, btScalar((t - t2) / (t3 - t2)));
  const btVector3 b1 = lerp(a1, a2, btScalar((t - t0) / (t2 - t0)));
  const btVector3 b2 = lerp(a2, a3, btScalar((t - t1) / (t3 - t1)));
  return lerp(b1, b2, btScalar((t - t1) / (t2 - t1)));
}

// Uniform Catmull-Rom for scalar profiles (radii).
double catmullRom(double v0, double v1, double v2, double v3, double s) {
  return 0.5 * ((2 * v1) + (-v0 + v2) * s + (2 * v0 - 5 * v1 + 4 * v2 - v3) * s * s +
                (-v0 + 3 * v1 - 3 * v2 + v3) * s * s * s);
}

}  // namespace

std::vector<std::array<double, 2>> diskPoints(int count, DiskPattern pattern, int* columns) {
  std::vector<std::array<double, 2>> points;
  if (count <= 0) return points;
  points.reserve(count);
  if (pattern == DiskPattern::Sunflower) {
    const double golden = M_PI * (3 - std::sqrt(5.0));
    for (int i = 0; i < count; ++i) {
      const double r = count == 1 ? 0 : std::sqrt((i + 0.5) / count);
      points.push_back({r * std::cos(i * golden), r * std::sin(i * golden)});
    }
    if (columns) *columns = 0;
    return points;
  }
  // Grid: the most square rows × cols factorisation, inside the square inscribed in the disk.
  int rows = 1;
  for (int r = 1; r * r <= count; ++r)
    if (count % r == 0) rows = r;
  const int cols = count / rows;
  const double half = std::sqrt(0.5);
  auto coordinate = [half](int i, int n) { return n == 1 ? 0.0 : -half + 2 * half * i / (n - 1); };
  // Keep the grid's aspect: the longer side spans the square, the shorter is scaled to match.
  const double spacing = cols > 1 ? 2 * half / (cols - 1) : 0;
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      const double v = rows == 1 ? 0.0 : (r - 0.5 * (rows - 1)) * spacing;
      points.push_back({coordinate(c, cols), v});
    }
  if (columns) *columns = cols;
  return points;
}

Tube::Tube(TubeDefinition definition) : definition_(std::move(definition)) {
  const auto& points = definition_.points;
  const auto& radii = definition_.radii;
  const size_t n = points.size();
  // Phantom end points continue the first and last segments straight on.
  auto point = [&](long i) {
    if (i < 0) return points[0] * 2 - points[1];
    if (i >= long(n)) return points[n - 1] * 2 - points[n - 2];
    return points[i];
  };
  auto radius = [&](long i, int axis) {
    if (i < 0) return radii[0][axis];
    if (i >= long(n)) return radii[n - 1][axis];
    return radii[i][axis];
  };
  double largest = 0;
  for (const auto& r : radii) largest = std::max({largest, r[0], r[1]});
  std::vector<btVector3> positions;
  std::vector<std::array<double, 2>> profile;
  for (size_t segment = 0; segment + 1 < n; ++segment) {
    const long i = long(segment);
    const int last = segment + 2 == n ? kSamplesPerSegment : kSamplesPerSegment - 1;
    for (int k = 0; k <= last; ++k) {
      const double s = double(k) / kSamplesPerSegment;
      positions.push_back(catmullRom(point(i - 1), point(i), point(i + 1), point(i + 2), s));
      std::array<double, 2> r;
      for (int axis = 0; axis < 2; ++axis)
        r[axis] = std::max(catmullRom(radius(i - 1, axis), radius(i, axis), radius(i + 1, axis),
                                      radius(i + 2, axis), s),
                           1e-3 * largest);
      profile.push_back(r);
    }
  }
  samples_.resize(positions.size());
  cumulative_.assign(positions.size(), 0.0);
  for (size_t i = 0; i < positions.size(); ++i) {
    const btVector3 ahead = positions[std::min(i + 1, positions.size() - 1)];
    const btVector3 behind = positions[i == 0 ? 0 : i - 1];
    samples_[i].centre = positions[i];
    samples_[i].tangent = unitOr(ahead - behind, btVector3(0, 0, 1));
    samples_[i].radii = profile[i];
    if (i > 0) cumulative_[i] = cumulative_[i - 1] + (positions[i] - positions[i - 1]).length();
  }
  // Start frame from `up` (or the axis least aligned with the tangent), then parallel transport.
  const btVector3 t0 = samples_[0].tangent;
  btVector3 up = definition_.up;
  if (up.length2() < btScalar(1e-12)) {
    const btVector3 a = t0.absolute();
    up = a.x() <= a.y() && a.x() <= a.z() ? btVector3(1, 0, 0)
         : a.y() <= a.z()                 ? btVector3(0, 1, 0)
                                          : btVector3(0, 0, 1);
  }
  btVector3 normal = unitOr(up - t0 * up.dot(t0), t0.cross(btVector3(1, 0, 0)).normalized());
  for (auto& s : samples_) {
    normal = unitOr(normal - s.tangent * normal.dot(s.tangent), normal);
    s.normal = normal;
    s.side = normal.cross(s.tangent).normalized();
  }
}

Tube::Sample Tube::sample(double t) const {
  const double target = std::clamp(t, 0.0, 1.0) * length();
  const size_t upper = std::min<size_t>(
      std::lower_bound(cumulative_.begin(), cumulative_.end(), target) - cumulative_.begin(),
      cumulative_.size() - 1);
  if (upper == 0) return samples_[0];
  const size_t lower = upper - 1;
  const double span = cumulative_[upper] - cumulative_[lower];
  const double s = span > 0 ? (target - cumulative_[lower]) / span : 0;
  const Sample& a = samples_[lower];
  const Sample& b = samples_[upper];
  Sample result;
  result.centre = lerp(a.centre, b.centre, btScalar(s));
  result.tangent = unitOr(lerp(a.tangent, b.tangent, btScalar(s)), a.tangent);
  result.normal = unitOr(lerp(a.normal, b.normal, btScalar(s)), a.normal);
  result.normal =
      unitOr(result.normal - result.tangent * result.normal.dot(result.tangent), a.normal);
  result.side = result.normal.cross(result.tangent).normalized();
  result.radii = {a.radii[0] + (b.radii[0] - a.radii[0]) * s,
                  a.radii[1] + (b.radii[1] - a.radii[1]) * s};
  return result;
}

btVector3 Tube::centre(double t) const {
  return sample(t).centre;
}
btVector3 Tube::tangent(double t) const {
  return sample(t).tangent;
}
btVector3 Tube::side(double t) const {
  return sample(t).side;
}
btVector3 Tube::normal(double t) const {
  return sample(t).normal;
}
std::array<double, 2> Tube::radii(double t) const {
  return sample(t).radii;
}

btVector3 Tube::at(double t, double u, double v) const {
  const Sample s = sample(t);
  return s.centre + s.side * btScalar(u * s.radii[0]) + s.normal * btScalar(v * s.radii[1]);
}

btVector3 Tube::surfacePoint(double t, double angle) const {
  return at(t, std::cos(angle), std::sin(angle));
}

TriangleMesh Tube::mesh() const {
  const int slices = std::max(3, definition_.slices);
  const int sections = std::max(1, definition_.sections);
  const int domeRings = definition_.roundCaps ? std::max(2, slices / 4) : 0;
  TriangleMesh mesh;
  auto addRing = [&](const Sample& s, double offset, double scale) {
    for (int i = 0; i < slices; ++i) {
      const double angle = 2 * M_PI * i / slices;
      mesh.vertices.push_back(s.centre + s.tangent * btScalar(offset) +
                              s.side * btScalar(scale * s.radii[0] * std::cos(angle)) +
                              s.normal * btScalar(scale * s.radii[1] * std::sin(angle)));
    }
  };
  const Sample first = sample(0);
  const Sample last = sample(1);
  const double startDome = definition_.roundCaps ? std::min(first.radii[0], first.radii[1]) : 0;
  const double endDome = definition_.roundCaps ? std::min(last.radii[0], last.radii[1]) : 0;
  // Apex of the start cap, then rings from start to end, then the end apex.
  mesh.vertices.push_back(first.centre - first.tangent * btScalar(startDome));
  for (int k = domeRings - 1; k >= 1; --k) {
    const double phi = 0.5 * M_PI * k / domeRings;
    addRing(first, -startDome * std::sin(phi), std::cos(phi));
  }
  for (int j = 0; j <= sections; ++j) addRing(sample(double(j) / sections), 0, 1);
  for (int k = 1; k < domeRings; ++k) {
    const double phi = 0.5 * M_PI * k / domeRings;
    addRing(last, endDome * std::sin(phi), std::cos(phi));
  }
  const uint32_t endApex = uint32_t(mesh.vertices.size());
  mesh.vertices.push_back(last.centre + last.tangent * btScalar(endDome));

  const int rings = (sections + 1) + 2 * std::max(0, domeRings - 1);
  auto vertex = [slices](int ring, int i) { return uint32_t(1 + ring * slices + (i % slices)); };
  for (int i = 0; i < slices; ++i) mesh.triangles.push_back({0, vertex(0, i + 1), vertex(0, i)});
  for (int ring = 0; ring + 1 < rings; ++ring)
    for (int i = 0; i < slices; ++i) {
      const uint32_t a = vertex(ring, i), b = vertex(ring, i + 1);
      const uint32_t c = vertex(ring + 1, i + 1), d = vertex(ring + 1, i);
      mesh.triangles.push_back({a, b, c});
      mesh.triangles.push_back({a, c, d});
    }
  for (int i = 0; i < slices; ++i)
    mesh.triangles.push_back({endApex, vertex(rings - 1, i), vertex(rings - 1, i + 1)});
  return mesh;
}

FibreSet Tube::fibres(int count, DiskPattern pattern, double inset, int samples,
                      int* columns) const {
  FibreSet fibres;
  const int n = std::max(2, samples);
  std::vector<Sample> along(n);
  for (int k = 0; k < n; ++k) along[k] = sample(double(k) / (n - 1));
  std::vector<btVector3> polyline(n);
  for (const auto& [u, v] : diskPoints(count, pattern, columns)) {
    for (int k = 0; k < n; ++k) {
      const Sample& s = along[k];
      polyline[k] = s.centre + s.side * btScalar(inset * u * s.radii[0]) +
                    s.normal * btScalar(inset * v * s.radii[1]);
    }
    fibres.addFibre(polyline);
  }
  return fibres;
}

}  // namespace fibremss
