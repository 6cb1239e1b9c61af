#include "ForceChunks.h"

#include <algorithm>

#include "ParticleSimd.h"

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
  for (size_t k = settings.fanOffsets[chunk.fanBegin()]; k < settings.fanOffsets[chunk.fanEnd()];
       ++k)
    touch(chunk, settings.fanParticles[k]);
}

/// `end` moved to the nearest multiple of kFanLaneGroup fans from the start of its class (the
/// fans with as many particles as fan `end`), at most to the class's end: a chunk's share of a
/// class then runs in whole lane groups, with fans one at a time only at the class's end.
size_t groupedFanEnd(const MuscleSettings& settings, size_t end) {
  const std::span<const uint32_t> offsets = settings.fanOffsets;
  const size_t fans = offsets.size() - 1;
  if (end >= fans) return fans;
  const size_t count = offsets[end + 1] - offsets[end];
  const size_t first = fansUpTo(settings, 0, end, count - 1);
  const size_t last = fansUpTo(settings, end, fans, count);
  const size_t grouped = first + (end - first + kFanLaneGroup / 2) / kFanLaneGroup * kFanLaneGroup;
  return std::min(grouped, last);
}

#if FIBREMSS_AVX2_PARTICLES
/// clearForces four vectors per iteration (float: two per 256-bit store).
FIBREMSS_AVX2_PASS void clearForcesAvx2(std::span<btVector3> forces) {
  if (forces.empty()) return;  // data() may be null: no member to take
  float* f = forces.data()->m_floats;
  const size_t floats = 4 * forces.size(), blocks = floats & ~size_t{15};
  const __m256 zero = _mm256_setzero_ps();
  for (size_t k = 0; k < blocks; k += 16) {
    _mm256_storeu_ps(f + k, zero);
    _mm256_storeu_ps(f + k + 8, zero);
  }
  std::fill(f + blocks, f + floats, 0.0f);
}

/// moveForces four vectors per iteration.
FIBREMSS_AVX2_PASS void moveForcesAvx2(std::span<btVector3> to, std::span<btVector3> from) {
  if (to.empty()) return;  // data() may be null: no member to take
  float* t = to.data()->m_floats;
  float* f = from.data()->m_floats;
  const size_t floats = 4 * to.size(), blocks = floats & ~size_t{15};
  const __m256 zero = _mm256_setzero_ps();
#pragma GCC unroll 4
  for (size_t k = 0; k < blocks; k += 16) {
    _mm256_storeu_ps(t + k, _mm256_add_ps(_mm256_loadu_ps(t + k), _mm256_loadu_ps(f + k)));
    _mm256_storeu_ps(t + k + 8,
                     _mm256_add_ps(_mm256_loadu_ps(t + k + 8), _mm256_loadu_ps(f + k + 8)));
    _mm256_storeu_ps(f + k, zero);
    _mm256_storeu_ps(f + k + 8, zero);
  }
  for (size_t k = blocks; k < floats; ++k) {
    t[k] += f[k];
    f[k] = 0;
  }
}
#endif

}  // namespace

void clearForces(std::span<btVector3> forces) {
#if FIBREMSS_AVX2_PARTICLES
  if (fastestSpringKernel() == SpringKernel::avx2) return clearForcesAvx2(forces);
#endif
  std::fill(forces.begin(), forces.end(), btVector3(0, 0, 0));
}

void moveForces(std::span<btVector3> to, std::span<btVector3> from) {
#if FIBREMSS_AVX2_PARTICLES
  if (fastestSpringKernel() == SpringKernel::avx2) return moveForcesAvx2(to, from);
#endif
  for (size_t i = 0; i < to.size(); ++i) {
#if FIBREMSS_SSE_PARTICLES  // SSE2: a whole vector per instruction
    _mm_store_ps(to[i].m_floats, _mm_add_ps(loadVector(to[i]), loadVector(from[i])));
    _mm_store_ps(from[i].m_floats, _mm_setzero_ps());
#else
    for (int k = 0; k < 4; ++k) {
      to[i].m_floats[k] += from[i].m_floats[k];
      from[i].m_floats[k] = 0;
    }
#endif
  }
}

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
    // The fans whose particles start below the chunk's share.
    const size_t fanEnd = std::max(
        fanBegin, groupedFanEnd(settings, static_cast<size_t>(
                                              std::lower_bound(offsets.begin(), offsets.end() - 1,
                                                               particles * (c + 1) / count) -
                                              offsets.begin())));
    chunk.fanClasses = fanClasses(settings, fanBegin, fanEnd);
    chunk.work = chunk.springEnd - chunk.springBegin +
                 kFanParticleWork * (offsets[fanEnd] - offsets[fanBegin]);
    fanBegin = fanEnd;
    touchParticles(settings, kernel, chunk);
  }
  return chunks;
}

}  // namespace fibremss
