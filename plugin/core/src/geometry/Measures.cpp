#include "fibremss/Measures.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "fibremss/Error.h"

namespace fibremss {
namespace {

constexpr double kMetresToMm = 1000.0;

/// Rest-frame bounds of a bone mesh: a point outside them cannot be inside the bone, which
/// spares the signed-distance query for most points.
struct Bounds {
  btVector3 lower;
  btVector3 upper;
  bool contains(const btVector3& p) const {
    return p.x() >= lower.x() && p.y() >= lower.y() && p.z() >= lower.z() && p.x() <= upper.x() &&
           p.y() <= upper.y() && p.z() <= upper.z();
  }
};

/// a · (b × c) in double precision.
double tripleProduct(const btVector3& a, const btVector3& b, const btVector3& c) {
  const double bx = b.x(), by = b.y(), bz = b.z(), cx = c.x(), cy = c.y(), cz = c.z();
  return a.x() * (by * cz - bz * cy) - a.y() * (bx * cz - bz * cx) + a.z() * (bx * cy - by * cx);
}

}  // namespace

Penetration measurePenetration(std::span<const btVector3> points,
                               std::span<const MeshDistance* const> bones,
                               std::span<const btTransform> boneTransforms,
                               std::span<float> depthsMm) {
  if (bones.size() != boneTransforms.size() ||
      (!depthsMm.empty() && depthsMm.size() != points.size())) {
    throw InputError("measurePenetration", "",
                     std::to_string(bones.size()) + " bones, " +
                         std::to_string(boneTransforms.size()) + " transforms, " +
                         std::to_string(points.size()) + " points, " +
                         std::to_string(depthsMm.size()) + " depths");
  }
  std::vector<Bounds> bounds(bones.size());
  std::vector<btTransform> toRest(bones.size());
  for (size_t b = 0; b < bones.size(); ++b) {
    pointBounds(bones[b]->mesh().vertices, bounds[b].lower, bounds[b].upper);
    toRest[b] = boneTransforms[b].inverse();
  }
  Penetration result;
  result.points = points.size();
  double depthSum = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    double deepest = 0;
    for (size_t b = 0; b < bones.size(); ++b) {
      const btVector3 local = toRest[b] * points[i];
      if (!bounds[b].contains(local)) continue;
      deepest = std::max(deepest, -static_cast<double>(bones[b]->signedDistance(local)));
    }
    if (!depthsMm.empty()) depthsMm[i] = static_cast<float>(deepest * kMetresToMm);
    if (deepest > 0) {
      ++result.penetrating;
      depthSum += deepest * kMetresToMm;
      result.maxMm = std::max(result.maxMm, deepest * kMetresToMm);
    }
  }
  result.meanMm = result.penetrating ? depthSum / static_cast<double>(result.penetrating) : 0;
  return result;
}

Penetration combine(const Penetration& a, const Penetration& b) {
  Penetration sum;
  sum.points = a.points + b.points;
  sum.penetrating = a.penetrating + b.penetrating;
  sum.maxMm = std::max(a.maxMm, b.maxMm);
  if (sum.penetrating > 0) {
    sum.meanMm = (a.meanMm * static_cast<double>(a.penetrating) +
                  b.meanMm * static_cast<double>(b.penetrating)) /
                 static_cast<double>(sum.penetrating);
  }
  return sum;
}

double enclosedVolume(std::span<const std::array<uint32_t, 3>> triangles,
                      std::span<const btVector3> vertices) {
  // Same formula as meshVolume, summed in double: many small tetra volumes lose digits.
  double volume = 0;
  for (const auto& t : triangles)
    volume += tripleProduct(vertices[t[0]], vertices[t[1]], vertices[t[2]]) / 6.0;
  return volume;
}

double volumeChangePercent(const TriangleMesh& rest, std::span<const btVector3> deformedVertices) {
  if (deformedVertices.size() != rest.vertices.size()) {
    throw InputError("volumeChangePercent", "",
                     std::to_string(deformedVertices.size()) +
                         " deformed vertices for a surface of " +
                         std::to_string(rest.vertices.size()));
  }
  const double restVolume = meshVolume(rest);
  if (restVolume == 0) return std::numeric_limits<double>::quiet_NaN();
  const double volume = enclosedVolume(rest.triangles, deformedVertices);
  return (volume - restVolume) / std::abs(restVolume) * 100.0;
}

double springDeviationRatio(std::span<const Spring> springs, std::span<const btVector3> positions) {
  double deviation = 0;
  double rest = 0;
  for (const Spring& s : springs) {
    if (s.a >= positions.size() || s.b >= positions.size()) {
      throw InputError("springDeviationRatio", "",
                       "spring (" + std::to_string(s.a) + ", " + std::to_string(s.b) +
                           ") outside " + std::to_string(positions.size()) + " positions");
    }
    const double length = (positions[s.a] - positions[s.b]).length();
    deviation += std::abs(length - s.restLength);
    rest += s.restLength;
  }
  return rest > 0 ? deviation / rest : std::numeric_limits<double>::quiet_NaN();
}

double rmsDistanceMm(std::span<const btVector3> a, std::span<const btVector3> b) {
  if (a.size() != b.size()) {
    throw InputError("rmsDistanceMm", "",
                     std::to_string(a.size()) + " against " + std::to_string(b.size()) + " points");
  }
  if (a.empty()) return std::numeric_limits<double>::quiet_NaN();
  double sum = 0;
  for (size_t i = 0; i < a.size(); ++i) sum += static_cast<double>((a[i] - b[i]).length2());
  return std::sqrt(sum / static_cast<double>(a.size())) * kMetresToMm;
}

}  // namespace fibremss
