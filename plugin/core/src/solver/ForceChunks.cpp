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
  for (size_t k = settings.fanOffsets[chunk.fanBegin]; k < settings.fanOffsets[chunk.fanEnd]; ++k)
    touch(chunk, settings.fanParticles[k]);
}

}  // namespace

std::vector<ForceChunk> forceChunks(const MuscleSettings& settings, SpringKernel kernel,
                                    size_t work) {
  const size_t springs = springLayoutSize(settings, kernel);
  const std::span<const uint32_t> offsets = settings.fanOffsets;
  const size_t particles = offsets.back();  // of the fans, with repeats
  const size_t total = springs + kFanParticleWork * particles;
  const size_t count = std::max<size_t>(1, (total + work / 2) / std::max<size_t>(work, 1));
  std::vector<ForceChunk> chunks(count);
  size_t springBegin = 0, fanBegin = 0;
  for (size_t c = 0; c < count; ++c) {
    ForceChunk& chunk = chunks[c];
    chunk.springBegin = springBegin;
    chunk.springEnd =
        std::max(springBegin, springLayoutBoundary(settings, kernel, springs * (c + 1) / count));
    springBegin = chunk.springEnd;
    chunk.fanBegin = fanBegin;  // the fans whose particles start below the chunk's share
    chunk.fanEnd = static_cast<size_t>(
        std::lower_bound(offsets.begin(), offsets.end() - 1, particles * (c + 1) / count) -
        offsets.begin());
    fanBegin = chunk.fanEnd;
    chunk.work = chunk.springEnd - chunk.springBegin +
                 kFanParticleWork * (offsets[chunk.fanEnd] - offsets[chunk.fanBegin]);
    touchParticles(settings, kernel, chunk);
  }
  return chunks;
}

}  // namespace fibremss
