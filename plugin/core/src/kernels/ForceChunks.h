#pragma once
// A muscle's spring and volume forces in chunks, internal: tasks finer than one per
// muscle, so that muscles of very different sizes balance on the threads. The chunks are fixed
// ranges of the spring layout and of the tetrahedra, chosen from the muscle alone (never from the
// thread count); each chunk but the first sums into a buffer of its own, and the buffers are
// added in chunk order: the same bits for any thread count.
#include <LinearMath/btVector3.h>

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "SpringForces.h"
#include "VolumeForces.h"
#include "fibremss/MuscleSettings.h"

namespace fibremss {

/// What one particle of a volume term's fan costs against one spring (kernel instructions on
/// AVX2, thigh13 R=20 under callgrind: about 16 per fan particle, 17 per spring).
constexpr size_t kFanParticleWork = 1;

/// Work per chunk by default, in springs (a fan's particle counts kFanParticleWork): thigh13 R=40
/// runs 39 chunks, R=20 20 (one term per tetrahedron, counted 4 springs each, gave 60 and 26).
/// Halving it from 32 768 (then 28 chunks at R=40, R=20 muscles whole) raised the pool's
/// schedule bound on 2 threads from 1.93× to 1.94× at R=40 and from 1.88× to 1.91× at R=20; at 1
/// thread a 10-iteration step at R=40 costs +1.9 % instructions against one task per muscle
/// (docs/performance.md).
constexpr size_t kForceChunkWork = 16384;

/// One chunk of a muscle's forces pass.
struct ForceChunk {
  /// Its springs: a range of the kernel's layout (springLayoutSize; its ends are boundaries).
  size_t springBegin = 0;
  size_t springEnd = 0;  ///< see springBegin
  /// Its volume terms: fans [fanBegin(), fanEnd()) of settings.fanOffsets, cut by class (the
  /// kernel's ranges).
  FanClasses fanClasses;
  uint32_t lower = 0;  ///< the particles its springs and tetrahedra touch: [lower, upper)
  uint32_t upper = 0;  ///< see lower
  size_t work = 0;     ///< springs (or lanes) + kFanParticleWork · the fans' particles

  size_t fanBegin() const { return fanClasses.at[0]; }                ///< its first fan
  size_t fanEnd() const { return fanClasses.at[kMaxFanTetrahedra]; }  ///< past its last fan
};

/// Sets every vector of `forces` to zero (chunk 0's, the muscle's forces, before its pass).
void clearForces(std::span<btVector3> forces);
/// to[i] += from[i] over all four lanes (w is 0 in both), then from[i] = 0: a chunk's buffer added
/// to the muscle's forces and left clear for its next pass, in one pass over it; per lane the same
/// sum whatever the instruction set.
void moveForces(std::span<btVector3> to, std::span<btVector3> from);

/// The muscle's forces pass in about total work / `work` chunks of nearly equal work (at least
/// one) for `kernel`'s spring layout.
std::vector<ForceChunk> forceChunks(const MuscleSettings& settings, SpringKernel kernel,
                                    size_t work);

}  // namespace fibremss
