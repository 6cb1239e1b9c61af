// Spring layouts (method.md §3): N nearest neighbours, Delaunay edges, 6- and 26-neighbour
// lattices over the fibre grid. All produce particle pairs; the pairs are made unique and
// sorted, then get their rest length L0 = distance and stiffness k = κ / L0.
#include <algorithm>
#include <cmath>

#include "PreparationInternal.h"
#include "SpringsDelaunay.h"
#include "fibremss/Error.h"

namespace fibremss::detail {
namespace {

using Pair = std::pair<uint32_t, uint32_t>;

void addPair(std::vector<Pair>& pairs, uint32_t i, uint32_t j) {
  if (i != j) pairs.emplace_back(std::min(i, j), std::max(i, j));
}

std::vector<Pair> nearestPairs(const MuscleInput& muscle, size_t particleCount,
                               std::span<const btVector3> positions, const KdTree& particles) {
  const int n = muscle.parameters.springs.neighbours;
  if (n < 1 || size_t(n) >= particleCount)
    throw InputError(muscleSource(muscle), "springs.neighbours",
                     "N must be between 1 and the particle count − 1 (" +
                         std::to_string(particleCount - 1) + "), got " + std::to_string(n));
  std::vector<Pair> pairs;
  pairs.reserve(particleCount * n);
  std::vector<uint32_t> indices(n + 1);
  std::vector<btScalar> distances2(n + 1);
  for (uint32_t i = 0; i < particleCount; ++i) {
    const size_t found = particles.nearest(positions[i], n + 1, indices.data(), distances2.data());
    // The query point itself is among the results (at distance 0); take the N others.
    int taken = 0;
    for (size_t r = 0; r < found && taken < n; ++r)
      if (indices[r] != i) {
        addPair(pairs, i, indices[r]);
        ++taken;
      }
  }
  return pairs;
}

std::vector<Pair> latticePairs(const MuscleInput& muscle, size_t fibreCount, bool full) {
  const int columns = muscle.fibreGridColumns;
  const char* name = full ? "lattice26" : "lattice6";
  if (columns <= 0)
    throw InputError(muscleSource(muscle), "springs.layout",
                     std::string(name) +
                         " needs fibres on a grid (fibre grid columns), and this muscle's fibres "
                         "are not given as a grid");
  if (fibreCount % columns != 0)
    throw InputError(muscleSource(muscle), "fibre grid",
                     std::to_string(fibreCount) + " fibres do not fill a grid of " +
                         std::to_string(columns) + " columns");
  const int rows = static_cast<int>(fibreCount / columns);
  const int samples = muscle.parameters.resolution;
  auto index = [&](int r, int c, int k) {
    return static_cast<uint32_t>((r * columns + c) * samples + k);
  };
  std::vector<Pair> pairs;
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < columns; ++c)
      for (int k = 0; k < samples; ++k)
        for (int dr = -1; dr <= 1; ++dr)
          for (int dc = -1; dc <= 1; ++dc)
            for (int dk = -1; dk <= 1; ++dk) {
              if (!full && std::abs(dr) + std::abs(dc) + std::abs(dk) != 1) continue;
              const int r2 = r + dr, c2 = c + dc, k2 = k + dk;
              if (r2 < 0 || r2 >= rows || c2 < 0 || c2 >= columns || k2 < 0 || k2 >= samples)
                continue;
              const uint32_t i = index(r, c, k), j = index(r2, c2, k2);
              if (i < j) pairs.emplace_back(i, j);
            }
  return pairs;
}

/// ratio·cos²θ + sin²θ, θ the angle between the spring and the mean fibre direction at its ends
/// (1 where neither end has one).
btScalar anisotropyFactor(std::span<const btVector3> positions,
                          std::span<const btVector3> directions, const Spring& spring,
                          btScalar ratio) {
  const btVector3 &first = directions[spring.a], &second = directions[spring.b];
  // Fibre directions are lines, not arrows: align the second with the first before averaging.
  const btVector3 fibre = first + (first.dot(second) < 0 ? -second : second);
  if (!(fibre.length2() > 0)) return 1;
  const btScalar cosine =
      (positions[spring.b] - positions[spring.a]).dot(fibre) / (spring.restLength * fibre.length());
  const btScalar cos2 = std::min(cosine * cosine, btScalar(1));
  return ratio * cos2 + (1 - cos2);
}

}  // namespace

std::vector<Spring> buildSprings(const MuscleInput& muscle, std::span<const btVector3> positions,
                                 const KdTree& particles, std::span<const btVector3> directions) {
  const SpringParameters& parameters = muscle.parameters.springs;
  if (!(parameters.kappa > 0))
    throw InputError(muscleSource(muscle), "springs.kappa",
                     "must be positive, got " + std::to_string(parameters.kappa));
  std::vector<Pair> pairs;
  switch (parameters.layout) {
    case SpringLayout::NearestNeighbours:
      pairs = nearestPairs(muscle, positions.size(), positions, particles);
      break;
    case SpringLayout::Delaunay:
      pairs = delaunayEdges(muscle, positions);
      break;
    case SpringLayout::Lattice6:
    case SpringLayout::Lattice26:
      pairs = latticePairs(muscle, muscle.fibres.fibreCount(),
                           parameters.layout == SpringLayout::Lattice26);
      break;
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());

  std::vector<Spring> springs;
  springs.reserve(pairs.size());
  for (const auto& [a, b] : pairs) {
    const btScalar length = (positions[a] - positions[b]).length();
    // Coincident particles make a spring of infinite stiffness and no direction.
    if (!(length > 0))
      throw InputError(muscleSource(muscle),
                       "particles " + std::to_string(a) + " and " + std::to_string(b),
                       "coincide (a zero-length spring): fibres overlap or repeat a point");
    springs.push_back({a, b, length, parameters.kappa / length});
  }
  if (parameters.fibreStiffnessRatio != 1 && !directions.empty())
    for (Spring& spring : springs)
      spring.stiffness *=
          anisotropyFactor(positions, directions, spring, parameters.fibreStiffnessRatio);
  return springs;
}

btScalar zelenyDamping(std::span<const Spring> springs, btScalar particleMass) {
  if (springs.empty()) return 0;
  double stiffness = 0;
  for (const Spring& spring : springs) stiffness += spring.stiffness;
  const double mean = stiffness / springs.size();
  // c = √(4·k̄·2m): critical damping of one spring between two particles of mass m, with the
  // mean stiffness standing for all springs (000 eq 2.11 without its unit-bound constant "2").
  return static_cast<btScalar>(std::sqrt(4.0 * mean * 2.0 * particleMass));
}

}  // namespace fibremss::detail
