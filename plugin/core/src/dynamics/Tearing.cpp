#include "Tearing.h"

#include <algorithm>
#include <span>

#include "fibremss/UnionFind.h"
#include "kernels/VolumeForces.h"
#include "state/MuscleState.h"

namespace fibremss {
namespace {

/// Counts the components of the unbroken springs among the particles that had a spring at
/// rest, leaving each particle's root (its piece's smallest particle) in pieceOf.
size_t countPieces(const MuscleSettings& settings, TearState& tear) {
  std::vector<uint32_t>& parent = tear.pieceOf;
  for (uint32_t i = 0; i < parent.size(); ++i) parent[i] = i;
  for (const Spring& spring : settings.springs) unionFindJoin(parent, spring.a, spring.b);
  size_t pieces = 0;
  for (uint32_t i = 0; i < parent.size(); ++i) {
    // A root is smaller than its other particles: final already.
    parent[i] = unionFindRoot(parent, i);
    pieces += parent[i] == i && tear.springCounts[i] > 0 ? 1 : 0;
  }
  return pieces;
}

/// Whether the distance of particles i and j is beyond `limit` times their rest distance.
bool beyond(const MuscleSettings& settings, const btVector3* x, btScalar limit, uint32_t i,
            uint32_t j) {
  const btScalar rest = settings.restPositions[i].distance2(settings.restPositions[j]);
  return x[i].distance2(x[j]) > limit * limit * rest;
}

/// Whether the particles `p` lie in more than one piece.
bool acrossPieces(const TearState& tear, std::span<const uint32_t> p) {
  return std::any_of(p.begin(), p.end(),
                     [&](uint32_t i) { return tear.pieceOf[i] != tear.pieceOf[p[0]]; });
}

/// Breaks the springs beyond the limit, in their order, but for a particle's last spring: a
/// particle whose springs all passed the limit at once stays with the piece of the one that comes
/// last, not a loose fragment of its own. Returns how many broke.
size_t breakSprings(const ParticleState& particles, TearState& tear) {
  const MuscleSettings& settings = *tear.torn;
  const btVector3* x = particles.positions.data();
  size_t broken = 0;
  for (size_t s = 0; s < settings.springs.size(); ++s) {
    const Spring& spring = settings.springs[s];
    const btScalar longest = settings.breakStretch * spring.restLength;
    if (spring.a == spring.b || !(x[spring.a].distance2(x[spring.b]) > longest * longest) ||
        tear.springCounts[spring.a] == 1 || tear.springCounts[spring.b] == 1)
      continue;
    breakSpring(tear, s);
    tear.passBroken[broken++] = uint32_t(s);
  }
  return broken;
}

/// Restores spring s of a muscle prepared for tearing as it was before anything broke.
void restoreSpring(TearState& tear, size_t s) {
  MuscleSettings& settings = *tear.torn;
  const Spring& spring = settings.springs[s] = tear.intact->springs[s];
  ++tear.springCounts[spring.a];
  ++tear.springCounts[spring.b];
  if (tear.springLanes.empty()) return;
  const uint32_t lane = tear.springLanes[s];
  const SpringBlocks& intact = tear.intact->springBlocks;
  settings.springBlocks.b[lane] = intact.b[lane];
  settings.springBlocks.restLength[lane] = intact.restLength[lane];
  settings.springBlocks.stiffness[lane] = intact.stiffness[lane];
}

/// Restores, of the `broken` springs the last pass broke (in their order), each that links a piece
/// holding no fixed particle to another piece, joining the two: a stretch tears a muscle apart
/// between the bones that hold it, and a layer both of whose sides parted in the same step (at the
/// narrowest section) stays with the side of its first such spring, not a free sliver. Nothing in
/// a muscle with no fixed particle. Returns how many were restored (the pieces then recounted).
size_t holdFreePieces(TearState& tear, size_t broken) {
  const MuscleSettings& settings = *tear.torn;
  if (settings.fixedParticles.empty()) return 0;
  std::vector<uint32_t>& parent = tear.pieceOf;
  std::fill(tear.pieceHeld.begin(), tear.pieceHeld.end(), uint8_t(0));
  for (const uint32_t f : settings.fixedParticles) tear.pieceHeld[parent[f]] = 1;
  size_t restored = 0;
  for (size_t k = 0; k < broken; ++k) {
    const Spring& spring = tear.intact->springs[tear.passBroken[k]];
    const uint32_t a = unionFindRoot(parent, spring.a), b = unionFindRoot(parent, spring.b);
    if (a == b || (tear.pieceHeld[a] && tear.pieceHeld[b])) continue;
    restoreSpring(tear, tear.passBroken[k]);
    unionFindJoin(parent, a, b);
    tear.pieceHeld[std::min(a, b)] = tear.pieceHeld[a] | tear.pieceHeld[b];
    ++restored;
  }
  if (restored > 0) tear.pieces = countPieces(settings, tear);
  return restored;
}

/// Whether a volume term's particles `p` have an edge beyond the muscle's breakStretch.
bool stretchedTerm(const ParticleState& particles, const TearState& tear,
                   std::span<const uint32_t> p, const void*) {
  const MuscleSettings& settings = *tear.torn;
  return anyTermEdge(p, [&](uint32_t i, uint32_t j) {
    return beyond(settings, particles.positions.data(), settings.breakStretch, i, j);
  });
}

/// Whether a volume term's particles `p` lie in more than one piece.
bool termAcrossPieces(const ParticleState&, const TearState& tear, std::span<const uint32_t> p,
                      const void*) {
  return acrossPieces(tear, p);
}

}  // namespace

void breakSpring(TearState& tear, size_t s) {
  MuscleSettings& settings = *tear.torn;
  Spring& spring = settings.springs[s];
  --tear.springCounts[spring.a];
  --tear.springCounts[spring.b];
  spring = {spring.a, spring.a, 0, 0};
  if (tear.springLanes.empty()) return;
  SpringBlocks& blocks = settings.springBlocks;
  const uint32_t lane = tear.springLanes[s];
  blocks.b[lane] = spring.a * uint32_t(sizeof(btVector3));
  blocks.restLength[lane] = blocks.stiffness[lane] = 0;
}

size_t breakVolumeTerms(const ParticleState& particles, TearState& tear, TermTest breaks,
                        const void* context) {
  MuscleSettings& settings = *tear.torn;
  size_t broken = 0;
  for (size_t k = 0; k < settings.fanRestGradient.size(); ++k) {
    if (settings.fanRestGradient[k] == 0 ||
        !breaks(particles, tear, fanParticles(settings, k), context))
      continue;
    settings.fanRestGradient[k] = 0;
    ++broken;
  }
  for (size_t k = 0; k < settings.tetRestGradient.size(); ++k) {
    const std::span<const uint32_t> p(settings.tetParticles.data() + 4 * k, 4);
    // A tetrahedron is the fan (p0, p1, p2, p3) of one.
    if (settings.tetRestGradient[k] != 0 && breaks(particles, tear, p, context))
      settings.tetRestGradient[k] = 0;
  }
  return broken;
}

void separatePieces(const ParticleState& particles, TearState& tear) {
  tear.pieces = countPieces(*tear.torn, tear);
  tear.brokenVolumeTerms += breakVolumeTerms(particles, tear, termAcrossPieces, nullptr);
}

void prepareTearing(std::shared_ptr<const MuscleSettings>& shared, TearState& tear, bool cuttable) {
  if (tear.torn || !(cuttable || shared->breakStretch > 0)) return;
  tear.intact = shared;
  tear.torn = std::make_shared<MuscleSettings>(*shared);
  shared = tear.torn;
  const MuscleSettings& settings = *tear.torn;
  const size_t n = settings.particleCount();
  tear.pieceOf.resize(n);
  tear.springCounts.assign(n, 0);
  for (const Spring& spring : settings.springs) {
    ++tear.springCounts[spring.a];
    ++tear.springCounts[spring.b];
  }
  tear.passBroken.resize(settings.springs.size());
  tear.pieceHeld.resize(n);
  tear.pieceLower.resize(n);
  tear.pieceUpper.resize(n);
  tear.restLower.resize(n);
  tear.restUpper.resize(n);
  if (settings.springBlocks.springCount == settings.springs.size()) {
    // The lanes in block order hold the springs of each run in order: find each by (a, b).
    const SpringBlocks& blocks = settings.springBlocks;
    tear.springLanes.resize(settings.springs.size());
    for (size_t lane = 0; lane < blocks.b.size(); ++lane) {
      const uint32_t a = blocks.a[lane / SpringBlocks::kLanes] / sizeof(btVector3);
      const uint32_t b = blocks.b[lane] / sizeof(btVector3);
      if (a == b) continue;
      const auto at =
          std::lower_bound(settings.springs.begin(), settings.springs.end(), std::pair(a, b),
                           [](const Spring& s, std::pair<uint32_t, uint32_t> key) {
                             return std::pair(s.a, s.b) < key;
                           });
      tear.springLanes[size_t(at - settings.springs.begin())] = uint32_t(lane);
    }
  }
  tear.pieces = countPieces(settings, tear);
}

bool breakStretched(const ParticleState& particles, TearState& tear) {
  if (!tear.torn || !(tear.torn->breakStretch > 0)) return false;
  const size_t springs = breakSprings(particles, tear);
  const size_t volumeTerms = breakVolumeTerms(particles, tear, stretchedTerm, nullptr);
  if (springs + volumeTerms == 0) return false;
  tear.pieces = countPieces(*tear.torn, tear);
  tear.brokenSprings += springs - holdFreePieces(tear, springs);
  tear.brokenVolumeTerms +=
      volumeTerms + breakVolumeTerms(particles, tear, termAcrossPieces, nullptr);
  return true;
}

bool piecesSpread(const MuscleSettings& settings, const ParticleState& particles, TearState& tear,
                  double factor) {
  const size_t n = settings.particleCount();
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t r = tear.pieceOf[i];
    if (r == i) {
      tear.pieceLower[r] = tear.pieceUpper[r] = particles.positions[i];
      tear.restLower[r] = tear.restUpper[r] = settings.restPositions[i];
    }
  }
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t r = tear.pieceOf[i];
    tear.pieceLower[r].setMin(particles.positions[i]);
    tear.pieceUpper[r].setMax(particles.positions[i]);
    tear.restLower[r].setMin(settings.restPositions[i]);
    tear.restUpper[r].setMax(settings.restPositions[i]);
  }
  for (uint32_t i = 0; i < n; ++i) {
    if (tear.pieceOf[i] != i) continue;
    // Written so that a NaN extent counts as spread too.
    if (!(double(tear.pieceLower[i].distance(tear.pieceUpper[i])) <=
          factor * double(tear.restLower[i].distance(tear.restUpper[i]))))
      return true;
  }
  return false;
}

}  // namespace fibremss
