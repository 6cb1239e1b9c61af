#pragma once
// A muscle's spring and volume forces in chunks (issue 18), internal: tasks finer than one per
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
#include "fibremss/MuscleSettings.h"

namespace fibremss {

/// What one tetrahedron of the volume term costs against one spring (kernel instructions on
/// AVX2: about 63 against 17, thigh13 R=40 under callgrind).
constexpr size_t kTetrahedronWork = 4;

/// Work per chunk by default, in springs (a tetrahedron counts kTetrahedronWork): thigh13 R=40
/// (about 74 000 per muscle) runs 60 chunks, four or five per muscle; at R=20 two per muscle.
/// Halving it from 32 768 (28 chunks at R=40, R=20 muscles whole) raised the pool's schedule
/// bound on 2 threads from 1.93× to 1.94× at R=40 and from 1.88× to 1.91× at R=20; at 1 thread
/// a 10-iteration step at R=40 costs +1.9 % instructions against one task per muscle
/// (docs/performance.md).
constexpr size_t kForceChunkWork = 16384;

/// One chunk of a muscle's forces pass.
struct ForceChunk {
  /// Its springs: a range of the kernel's layout (springLayoutSize; its ends are boundaries).
  size_t springBegin = 0;
  size_t springEnd = 0;  ///< see springBegin
  size_t tetBegin = 0;   ///< its tetrahedra [tetBegin, tetEnd) of settings.tetParticles
  size_t tetEnd = 0;     ///< see tetBegin
  uint32_t lower = 0;    ///< the particles its springs and tetrahedra touch: [lower, upper)
  uint32_t upper = 0;    ///< see lower
  size_t work = 0;       ///< springs (or lanes) + kTetrahedronWork · tetrahedra
};

/// The muscle's forces pass in about total work / `work` chunks of nearly equal work (at least
/// one) for `kernel`'s spring layout.
std::vector<ForceChunk> forceChunks(const MuscleSettings& settings, SpringKernel kernel,
                                    size_t work);

}  // namespace fibremss
