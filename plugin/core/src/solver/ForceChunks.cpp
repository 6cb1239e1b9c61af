#include "ForceChunks.h"

#include <algorithm>

namespace fibremss {
namespace {

/// Widens [lower, upper) to hold particle i.
void touch(ForceChunk& chunk, uint32_t i) {
  if (chunk.lower == chunk.upper) {
    chunk.lower = i;
    chunk.upper = i + 1;
    return;
  }
  chunk.lower = std::min(chunk.lower, i);
  chunk.upper = std::max(chunk.upper, i + 1);
}

/// The particles the chunk's springs and tetrahedra touch.
void touchParticles(const MuscleSettings& settings, SpringKernel kernel, ForceChunk& chunk) {
  if (springLayoutKernel(settings, kernel) == SpringKernel::avx2) {
    const SpringBlocks& blocks = settings.springBlocks;
    constexpr uint32_t kBytes = sizeof(btVector3);  // the blocks hold byte offsets
    for (size_t s = chunk.springBegin; s < chunk.springEnd; ++s) {
      touch(chunk, blocks.a[s / SpringBlocks::kLanes] / kBytes);
      touch(chunk, blocks.b[s] / kBytes);
    }
  } else {
    for (size_t s = chunk.springBegin; s < chunk.springEnd; ++s) {
      touch(chunk, settings.springs[s].a);
      touch(chunk, settings.springs[s].b);
    }
  }
  for (size_t k = 4 * chunk.tetBegin; k < 4 * chunk.tetEnd; ++k)
    touch(chunk, settings.tetParticles[k]);
}

}  // namespace

std::vector<ForceChunk> forceChunks(const MuscleSettings& settings, SpringKernel kernel,
                                    size_t work) {
  const size_t springs = springLayoutSize(settings, kernel);
  const size_t tetrahedra = settings.tetInverseVolume.size();
  const size_t total = springs + kTetrahedronWork * tetrahedra;
  const size_t count = std::max<size_t>(1, (total + work / 2) / std::max<size_t>(work, 1));
  std::vector<ForceChunk> chunks(count);
  size_t springBegin = 0;
  for (size_t c = 0; c < count; ++c) {
    ForceChunk& chunk = chunks[c];
    chunk.springBegin = springBegin;
    chunk.springEnd =
        std::max(springBegin, springLayoutBoundary(settings, kernel, springs * (c + 1) / count));
    springBegin = chunk.springEnd;
    chunk.tetBegin = tetrahedra * c / count;
    chunk.tetEnd = tetrahedra * (c + 1) / count;
    chunk.work =
        chunk.springEnd - chunk.springBegin + kTetrahedronWork * (chunk.tetEnd - chunk.tetBegin);
    touchParticles(settings, kernel, chunk);
  }
  return chunks;
}

}  // namespace fibremss
