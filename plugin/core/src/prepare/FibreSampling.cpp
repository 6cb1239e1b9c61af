// Fibre sampling (method.md §2): equal arc-length steps ΔL = length / (resolution − 1); the
// first particle at the fibre start, the second at a random offset δ in (0, ΔL), the rest at
// ΔL steps after it. The last particle therefore lies ΔL − δ before the fibre end (the
// thesis' rule, kept literally: every fibre has exactly `resolution` particles and the
// jitter shifts the whole fibre but its first particle).
#include <cmath>

#include "PreparationInternal.h"
#include "fibremss/Error.h"

namespace fibremss::detail {

std::string muscleSource(const MuscleInput& muscle) {
  return "muscle '" + muscle.name + "'";
}

std::mt19937 bodyRandom(uint32_t seed, uint32_t kind, size_t bodyIndex) {
  std::seed_seq sequence{seed, kind, static_cast<uint32_t>(bodyIndex),
                         static_cast<uint32_t>(uint64_t(bodyIndex) >> 32)};
  return std::mt19937(sequence);
}

void sampleFibres(const MuscleInput& muscle, std::mt19937& random, MuscleSettings& out) {
  const int resolution = muscle.parameters.resolution;
  if (resolution < 2)
    throw InputError(muscleSource(muscle), "resolution",
                     "needs at least 2 particles per fibre, got " + std::to_string(resolution));
  const size_t fibreCount = muscle.fibres.fibreCount();
  if (fibreCount == 0) throw InputError(muscleSource(muscle), "fibres", "the muscle has no fibres");

  out.restPositions.clear();
  out.restPositions.reserve(fibreCount * resolution);
  out.fibreParticles.clear();
  out.fibreOffsets.assign(1, 0);
  // Draw from (0, 1) open on both ends: δ = 0 would put two particles on top of each other.
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<double> arc;
  for (size_t f = 0; f < fibreCount; ++f) {
    const auto points = muscle.fibres.fibre(f);
    if (points.size() < 2)
      throw InputError(muscleSource(muscle), "fibre " + std::to_string(f),
                       "needs at least 2 points, has " + std::to_string(points.size()));
    arc.assign(1, 0.0);
    for (size_t i = 1; i < points.size(); ++i)
      arc.push_back(arc.back() + (points[i] - points[i - 1]).length());
    const double length = arc.back();
    if (!(length > 0) || !std::isfinite(length))
      throw InputError(muscleSource(muscle), "fibre " + std::to_string(f),
                       "has zero or non-finite length");
    const double step = length / (resolution - 1);
    double jitter = 0;
    while (!(jitter > 0)) jitter = unit(random);
    size_t segment = 0;
    for (int k = 0; k < resolution; ++k) {
      const double s = k == 0 ? 0.0 : (jitter + (k - 1)) * step;
      while (segment + 2 < points.size() && arc[segment + 1] < s) ++segment;
      const double segmentLength = arc[segment + 1] - arc[segment];
      const double t = segmentLength > 0 ? (s - arc[segment]) / segmentLength : 0.0;
      const btVector3 position = points[segment].lerp(points[segment + 1], btScalar(t));
      out.fibreParticles.push_back(static_cast<uint32_t>(out.restPositions.size()));
      out.restPositions.push_back(position);
    }
    out.fibreOffsets.push_back(static_cast<uint32_t>(out.fibreParticles.size()));
  }
}

}  // namespace fibremss::detail
