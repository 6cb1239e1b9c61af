#pragma once
// Tearing (MuscleSettings::breakStretch, internal): after each kept step, a muscle's springs
// stretched beyond breakStretch times their rest length break for good, and with them the local
// volume terms that have an edge beyond it or particles in two pieces; the pieces are the
// components of the unbroken springs. Sequential per muscle, in the muscles' order, with no
// allocation: the same bits for every thread count.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

namespace fibremss {

struct MuscleSettings;
struct ParticleState;
struct TearState;

/// Gives a muscle its own copy of its `settings` (TearState::torn, which `settings` then points
/// to) and the scratch of its pieces when its settings tear (breakStretch > 0) or it is
/// `cuttable` (a blade may cut it); counts its pieces at rest. Nothing when it has them already.
void prepareTearing(std::shared_ptr<const MuscleSettings>& settings, TearState& tear,
                    bool cuttable = false);

/// Breaks spring `s` of a muscle prepared for tearing for good (a = b, no rest length, no
/// stiffness: no force, no deviation, in the spring list and in its AVX2 lane).
void breakSpring(TearState& tear, size_t s);

/// Whether a volume term of a muscle (its particles, its tearing state) on the particles `p`
/// breaks (`context`: the caller's).
using TermTest = bool (*)(const ParticleState& particles, const TearState& tear,
                          std::span<const uint32_t> p, const void* context);
/// Breaks the volume terms (fans, and the tetrahedra of the projective solver's matrix) of a
/// muscle prepared for tearing that `breaks` says: no rest gradient, no force. Returns the fans
/// broken.
size_t breakVolumeTerms(const ParticleState& particles, TearState& tear, TermTest breaks,
                        const void* context);

/// Whether `test(i, j)` holds for an edge i–j of one of the tetrahedra (a, b, r_k, r_k+1) of a
/// volume term's fan `p` (a, b, r_0 .. r_m; a tetrahedron is the fan of one).
template <typename Test>
bool anyTermEdge(std::span<const uint32_t> p, Test&& test) {
  if (test(p[0], p[1])) return true;
  for (size_t k = 2; k < p.size(); ++k)
    if (test(p[0], p[k]) || test(p[1], p[k]) || (k + 1 < p.size() && test(p[k], p[k + 1])))
      return true;
  return false;
}

/// After springs broke: recounts the muscle's pieces and breaks the volume terms across them.
void separatePieces(const ParticleState& particles, TearState& tear);

/// Breaks the springs and volume terms of a tearing muscle beyond its breakStretch at its
/// positions, but for springs whose break would leave a piece holding no fixed particle (restored),
/// then the volume terms across pieces; recounts its pieces when something broke.
/// Returns whether something broke (the integrator's workspace must then follow).
bool breakStretched(const ParticleState& particles, TearState& tear);

/// Whether a piece of a muscle (its `settings` and positions) has grown beyond `factor` times its
/// rest extent (bounding-box diagonal); a muscle in one piece as a whole.
bool piecesSpread(const MuscleSettings& settings, const ParticleState& particles, TearState& tear,
                  double factor);

}  // namespace fibremss
