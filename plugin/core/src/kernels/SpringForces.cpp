#include "SpringForces.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "ParticleSimd.h"

#define FIBREMSS_SSE_SPRINGS FIBREMSS_SSE_PARTICLES
// The AVX2 kernel is compiled for its own target and chosen at run time: the library still runs
// on plain x86-64. With FMA, unlike the per-particle passes: the kernels differ in rounding anyway.
#define FIBREMSS_AVX2_SPRINGS FIBREMSS_AVX2_PARTICLES
#if FIBREMSS_AVX2_SPRINGS
#define FIBREMSS_AVX2 __attribute__((target("avx2,fma")))
#endif

namespace fibremss {
namespace {

/// The force on a of the springs that share the particle a: springs are sorted by a, so a run of
/// them sums in a register and reaches memory once.
struct RunSum {
  uint32_t particle;  ///< the run's particle a
  btVector3 sum;      ///< force summed over the run so far
};

/// One spring at a time, for every build (the tail of the SSE loop, and double precision).
void addSpring(const Spring& spring, const btVector3* x, btVector3* f, RunSum& run, btScalar watch,
               SpringForceResult& result) {
  const btVector3 d = x[spring.b] - x[spring.a];
  const btScalar length = d.length();
  const btScalar stretch = length - spring.restLength;
  result.deviation += std::fabs(stretch);
  if (!(stretch <= 2 * spring.restLength)) ++result.overstretched;
  if (length > watch * spring.restLength) ++result.nearLimit;
  const btVector3 force = d * (length > 0 ? spring.stiffness * stretch / length : 0);
  if (spring.a != run.particle) {
    f[run.particle] += run.sum;
    run = {spring.a, force};
  } else {
    run.sum += force;
  }
  f[spring.b] -= force;
}

#if FIBREMSS_SSE_SPRINGS
/// Springs per block: the deviation is summed in float lanes within a block, in double across
/// blocks, so that its rounding does not grow with the muscle.
constexpr size_t kDeviationBlock = 256;

static_assert(sizeof(Spring) == 16 && offsetof(Spring, restLength) == 8 &&
              offsetof(Spring, stiffness) == 12 && sizeof(btVector3) == 16);

/// RunSum in a register.
struct SseRunSum {
  uint32_t particle;  ///< the run's particle a
  __m128 sum;         ///< force summed over the run so far
};

void store(btVector3& v, __m128 value) {
  _mm_store_ps(v.m_floats, value);
}

/// Springs [0, count), count a multiple of 4, four at a time: vectors transposed into x, y, z
/// lanes for the lengths, square roots and divisions, the forces transposed back (w = 0) for
/// the scatter; springs longer than `watch` times their rest length counted in result.nearLimit.
/// Returns Σ|l − L0| in float lanes.
__m128 addSpringsSse(const Spring* springs, size_t count, const btVector3* x, btVector3* f,
                     SseRunSum& run, __m128 watch, SpringForceResult& result) {
  const __m128 absolute = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  const __m128 zero = _mm_setzero_ps();
  __m128 deviation = zero;
  for (size_t s = 0; s < count; s += 4) {
    const Spring* group = springs + s;
    const uint32_t a0 = group[0].a, a1 = group[1].a, a2 = group[2].a, a3 = group[3].a;
    const uint32_t b0 = group[0].b, b1 = group[1].b, b2 = group[2].b, b3 = group[3].b;
    __m128 dx = _mm_sub_ps(loadVector(x[b0]), loadVector(x[a0])),
           dy = _mm_sub_ps(loadVector(x[b1]), loadVector(x[a1])),
           dz = _mm_sub_ps(loadVector(x[b2]), loadVector(x[a2])),
           dw = _mm_sub_ps(loadVector(x[b3]), loadVector(x[a3]));
    _MM_TRANSPOSE4_PS(dx, dy, dz, dw);
    // Rest lengths and stiffnesses are the upper halves of the 16-byte springs.
    const float* raw = reinterpret_cast<const float*>(group);
    const __m128 low = _mm_unpackhi_ps(_mm_loadu_ps(raw), _mm_loadu_ps(raw + 4));
    const __m128 high = _mm_unpackhi_ps(_mm_loadu_ps(raw + 8), _mm_loadu_ps(raw + 12));
    const __m128 restLength = _mm_movelh_ps(low, high);
    const __m128 stiffness = _mm_movehl_ps(high, low);

    const __m128 length = _mm_sqrt_ps(
        _mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy)), _mm_mul_ps(dz, dz)));
    const __m128 stretch = _mm_sub_ps(length, restLength);
    deviation = _mm_add_ps(deviation, _mm_and_ps(stretch, absolute));
    // Not (stretch ≤ 2·L0): beyond 3× the rest length, or NaN.
    const int beyond = _mm_movemask_ps(_mm_cmpnle_ps(stretch, _mm_add_ps(restLength, restLength)));
    if (beyond) result.overstretched += std::popcount(static_cast<unsigned>(beyond));  // rare
    const int near = _mm_movemask_ps(_mm_cmpgt_ps(length, _mm_mul_ps(watch, restLength)));
    if (near) result.nearLimit += std::popcount(static_cast<unsigned>(near));
    // k·(l − L0)/l, 0 for coincident ends (0/0 masked).
    const __m128 factor =
        _mm_and_ps(_mm_div_ps(_mm_mul_ps(stiffness, stretch), length), _mm_cmpgt_ps(length, zero));
    __m128 f0 = _mm_mul_ps(dx, factor), f1 = _mm_mul_ps(dy, factor), f2 = _mm_mul_ps(dz, factor),
           f3 = zero;
    _MM_TRANSPOSE4_PS(f0, f1, f2, f3);

    store(f[b0], _mm_sub_ps(loadVector(f[b0]), f0));
    store(f[b1], _mm_sub_ps(loadVector(f[b1]), f1));
    store(f[b2], _mm_sub_ps(loadVector(f[b2]), f2));
    store(f[b3], _mm_sub_ps(loadVector(f[b3]), f3));
    if (a0 == run.particle && a3 == a0) {  // the common case: the whole group continues the run
      run.sum = _mm_add_ps(run.sum, _mm_add_ps(_mm_add_ps(f0, f1), _mm_add_ps(f2, f3)));
      continue;
    }
    const uint32_t ends[4] = {a0, a1, a2, a3};
    const __m128 forces[4] = {f0, f1, f2, f3};
    for (int k = 0; k < 4; ++k) {
      if (ends[k] != run.particle) {
        store(f[run.particle], _mm_add_ps(loadVector(f[run.particle]), run.sum));
        run = {ends[k], forces[k]};
      } else {
        run.sum = _mm_add_ps(run.sum, forces[k]);
      }
    }
  }
  return deviation;
}

/// Sum of the four lanes in double.
double laneSum(__m128 lanes) {
  alignas(16) float values[4];
  _mm_store_ps(values, lanes);
  return double(values[0]) + values[1] + values[2] + values[3];
}

/// SSE2 groups of four springs from the start: returns how many springs it took; `tail` holds
/// the run it leaves open.
size_t sse2Springs(const Spring* springs, size_t count, const btVector3* x, btVector3* f,
                   RunSum& tail, btScalar watch, SpringForceResult& result) {
  SseRunSum run{springs[0].a, _mm_setzero_ps()};
  const size_t groups = count & ~size_t{3};
  for (size_t s = 0; s < groups; s += kDeviationBlock) {
    const size_t n = std::min(kDeviationBlock, groups - s);
    result.deviation +=
        laneSum(addSpringsSse(springs + s, n, x, f, run, _mm_set1_ps(watch), result));
  }
  btVector3 sum;
  store(sum, run.sum);
  tail = {run.particle, sum};
  return groups;
}
#endif

#if FIBREMSS_AVX2_SPRINGS
/// Transposes the 4×4 blocks in each 128-bit half of four rows.
FIBREMSS_AVX2 void transpose(__m256& r0, __m256& r1, __m256& r2, __m256& r3) {
  const __m256d t0 = _mm256_castps_pd(_mm256_unpacklo_ps(r0, r1));
  const __m256d t1 = _mm256_castps_pd(_mm256_unpackhi_ps(r0, r1));
  const __m256d t2 = _mm256_castps_pd(_mm256_unpacklo_ps(r2, r3));
  const __m256d t3 = _mm256_castps_pd(_mm256_unpackhi_ps(r2, r3));
  r0 = _mm256_castpd_ps(_mm256_unpacklo_pd(t0, t2));
  r1 = _mm256_castpd_ps(_mm256_unpackhi_pd(t0, t2));
  r2 = _mm256_castpd_ps(_mm256_unpacklo_pd(t1, t3));
  r3 = _mm256_castpd_ps(_mm256_unpackhi_pd(t1, t3));
}

/// Overstretched springs among the lanes of a group whose mask bit is set in `beyond`: padding
/// lanes (b = a; a spring has a ≠ b) are not springs; they are beyond only with a non-finite
/// x[a].
[[gnu::cold, gnu::noinline]] size_t overstretchedSprings(int beyond, const uint32_t* a,
                                                         const uint32_t* b) {
  size_t count = 0;
  for (size_t k = 0; k < 8; ++k) count += (beyond >> k & 1) && b[k] != a[k / 4];
  return count;
}

// A group of eight lanes is two blocks, one per 128-bit half.
static_assert(SpringBlocks::kLanes == 4);

/// SpringBlocks' arrays, read through plain pointers (the force stores cannot change them).
struct BlockArrays {
  const uint32_t* a;           ///< SpringBlocks::a
  const uint32_t* b;           ///< SpringBlocks::b
  const btScalar* restLength;  ///< SpringBlocks::restLength
  const btScalar* stiffness;   ///< SpringBlocks::stiffness
};

/// Lanes of the blocks [first, first + count), count a multiple of 8, eight at a time: blocks 2g
/// and 2g + 1 in the low and high halves (lane r of block h in lane r of half h of every row). A
/// block shares one a, so its x[a] is one load and the force on a one sum of four rows, added to
/// f[a] after the group's scatter to f[b]: no transposes of spring records, no branch on where
/// runs end. Springs longer than `watch` times their rest length are counted in result.nearLimit
/// (padding lanes, of length and rest length 0, never). Returns Σ|l − L0| in float lanes.
FIBREMSS_AVX2 __m256 addSpringBlocksAvx2(BlockArrays blocks, size_t first, size_t count,
                                         const btVector3* x, btVector3* f, __m256 watch,
                                         SpringForceResult& result) {
  const __m256 absolute = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
  const __m256 zero = _mm256_setzero_ps();
  __m256 deviation = zero;
  for (size_t s = first; s < first + count; s += 8) {
    const uint32_t* b = blocks.b + s;
    const uint32_t a0 = blocks.a[s / 4], a1 = blocks.a[s / 4 + 1];
    const __m256 xa = loadPair(at(x, a0), at(x, a1));
    __m256 dx = _mm256_sub_ps(loadPair(at(x, b[0]), at(x, b[4])), xa);
    __m256 dy = _mm256_sub_ps(loadPair(at(x, b[1]), at(x, b[5])), xa);
    __m256 dz = _mm256_sub_ps(loadPair(at(x, b[2]), at(x, b[6])), xa);
    __m256 dw = _mm256_sub_ps(loadPair(at(x, b[3]), at(x, b[7])), xa);
    transpose(dx, dy, dz, dw);
    const __m256 restLength = _mm256_loadu_ps(blocks.restLength + s);
    const __m256 stiffness = _mm256_loadu_ps(blocks.stiffness + s);

    const __m256 length =
        _mm256_sqrt_ps(_mm256_fmadd_ps(dz, dz, _mm256_fmadd_ps(dy, dy, _mm256_mul_ps(dx, dx))));
    const __m256 stretch = _mm256_sub_ps(length, restLength);
    deviation = _mm256_add_ps(deviation, _mm256_and_ps(stretch, absolute));
    // Not (stretch ≤ 2·L0): beyond 3× the rest length, or NaN.
    const int beyond = _mm256_movemask_ps(
        _mm256_cmp_ps(stretch, _mm256_add_ps(restLength, restLength), _CMP_NLE_UQ));
    if (beyond) result.overstretched += overstretchedSprings(beyond, blocks.a + s / 4, b);
    const int near =
        _mm256_movemask_ps(_mm256_cmp_ps(length, _mm256_mul_ps(watch, restLength), _CMP_GT_OQ));
    if (near) result.nearLimit += std::popcount(static_cast<unsigned>(near));
    // −k·(l − L0)/l, 0 for coincident ends (0/0 masked) and padding lanes: the force on b, so
    // that its scatter is an add with the load folded in (x − y is x + (−y), bit for bit).
    const __m256 factor =
        _mm256_and_ps(_mm256_div_ps(_mm256_fnmadd_ps(stiffness, stretch, zero), length),
                      _mm256_cmp_ps(length, zero, _CMP_GT_OQ));
    __m256 f0 = _mm256_mul_ps(dx, factor), f1 = _mm256_mul_ps(dy, factor),
           f2 = _mm256_mul_ps(dz, factor), f3 = zero;
    transpose(f0, f1, f2, f3);
    const __m128 force[8] = {_mm256_castps256_ps128(f0),   _mm256_castps256_ps128(f1),
                             _mm256_castps256_ps128(f2),   _mm256_castps256_ps128(f3),
                             _mm256_extractf128_ps(f0, 1), _mm256_extractf128_ps(f1, 1),
                             _mm256_extractf128_ps(f2, 1), _mm256_extractf128_ps(f3, 1)};
    for (int k = 0; k < 8; ++k) addAt(f, b[k], force[k]);
    // The force on a, negated: f[a] + (−Σ) is f[a] − Σ bit for bit.
    const __m256 rows = _mm256_xor_ps(_mm256_add_ps(_mm256_add_ps(f0, f1), _mm256_add_ps(f2, f3)),
                                      _mm256_set1_ps(-0.0f));
    addAt(f, a0, _mm256_castps256_ps128(rows));
    addAt(f, a1, _mm256_extractf128_ps(rows, 1));
  }
  return deviation;
}

/// The spring blocks' lanes [begin, end) on AVX2 (settings.springBlocks, laid out for these
/// springs; begin and end multiples of 8).
FIBREMSS_AVX2 void avx2Springs(const SpringBlocks& blocks, size_t begin, size_t end,
                               const btVector3* x, btVector3* f, btScalar watch,
                               SpringForceResult& result) {
  const BlockArrays arrays{blocks.a.data(), blocks.b.data(), blocks.restLength.data(),
                           blocks.stiffness.data()};
  for (size_t s = begin; s < end; s += kDeviationBlock) {
    const __m256 sums = addSpringBlocksAvx2(arrays, s, std::min(kDeviationBlock, end - s), x, f,
                                            _mm256_set1_ps(watch), result);
    result.deviation +=
        laneSum(_mm256_castps256_ps128(sums)) + laneSum(_mm256_extractf128_ps(sums, 1));
  }
}
#endif

}  // namespace

bool springKernelAvailable(SpringKernel kernel) {
  switch (kernel) {
    case SpringKernel::scalar:
      return true;
    case SpringKernel::sse2:
      return FIBREMSS_SSE_SPRINGS;
    case SpringKernel::avx2:
#if FIBREMSS_AVX2_SPRINGS
      return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
      return false;
#endif
  }
  return false;
}

SpringKernel fastestSpringKernel() {
  static const SpringKernel fastest = [] {
    // FIBREMSS_SPRING_KERNEL names an available kernel to run instead (side-by-side timings,
    // instruction counts that do not depend on the CPU).
    if (const char* name = std::getenv("FIBREMSS_SPRING_KERNEL"))
      for (SpringKernel kernel : {SpringKernel::scalar, SpringKernel::sse2, SpringKernel::avx2})
        if (std::strcmp(name, springKernelName(kernel)) == 0 && springKernelAvailable(kernel))
          return kernel;
    for (SpringKernel kernel : {SpringKernel::avx2, SpringKernel::sse2})
      if (springKernelAvailable(kernel)) return kernel;
    return SpringKernel::scalar;
  }();
  return fastest;
}

const char* springKernelName(SpringKernel kernel) {
  switch (kernel) {
    case SpringKernel::scalar:
      return "scalar";
    case SpringKernel::sse2:
      return "sse2";
    case SpringKernel::avx2:
      return "avx2";
  }
  return "unknown";
}

namespace {

/// A block to lay out: the particle a and its springs [first, end), at most kLanes of them.
struct BlockSprings {
  uint32_t a;    ///< the block's particle
  size_t first;  ///< its first spring
  size_t end;    ///< one past its last spring
};

/// Appends `block` to `blocks`, padded to kLanes lanes.
void addBlock(SpringBlocks& blocks, const BlockSprings& block, const Spring* springs) {
  constexpr uint32_t kBytes = sizeof(btVector3);
  blocks.a.push_back(block.a * kBytes);
  for (size_t s = block.first; s < block.first + SpringBlocks::kLanes; ++s) {
    const bool spring = s < block.end;
    blocks.b.push_back((spring ? springs[s].b : block.a) * kBytes);
    blocks.restLength.push_back(spring ? springs[s].restLength : 0);
    blocks.stiffness.push_back(spring ? springs[s].stiffness : 0);
  }
}

/// The stretch from which a spring is counted as near its limit [1]: kStrainWatch of the strain
/// limit, or never without one.
btScalar strainWatch(const MuscleSettings& settings) {
  return settings.strainLimit > 0 ? kStrainWatch * settings.strainLimit
                                  : std::numeric_limits<btScalar>::infinity();
}

}  // namespace

SpringBlocks springBlocksFor(const MuscleSettings& settings) {
  if (settings.particleCount() > UINT32_MAX / sizeof(btVector3))
    throw std::length_error("layoutSprings: particle offsets do not fit 32 bits");
  // Runs alternate between the low and high halves of the kernel's groups: the halves add to
  // different f[a], so the read-modify-writes of one f[a] wait on one another but not on the
  // other half's (thigh13 spring-forces/40, one thread: about 0.82 of the previous AVX2 kernel's
  // time, about 0.89 with the runs one after the other).
  const std::vector<Spring>& springs = settings.springs;
  std::vector<BlockSprings> halves[2];
  for (size_t s = 0, run = 0; s < springs.size(); ++run) {
    size_t end = s;
    while (end < springs.size() && springs[end].a == springs[s].a) ++end;
    for (; s < end; s = std::min(end, s + SpringBlocks::kLanes))
      halves[run % 2].push_back({springs[s].a, s, std::min(end, s + SpringBlocks::kLanes)});
  }
  const size_t groups = std::max(halves[0].size(), halves[1].size());
  SpringBlocks blocks;
  blocks.springCount = springs.size();
  blocks.a.reserve(2 * groups);
  blocks.b.reserve(2 * groups * SpringBlocks::kLanes);
  blocks.restLength.reserve(2 * groups * SpringBlocks::kLanes);
  blocks.stiffness.reserve(2 * groups * SpringBlocks::kLanes);
  for (size_t g = 0; g < groups; ++g)
    for (const std::vector<BlockSprings>& half : halves) {
      // A half that ran out gets blocks of padding only (of its last particle).
      const uint32_t last = half.empty() ? halves[0].front().a : half.back().a;
      addBlock(blocks, g < half.size() ? half[g] : BlockSprings{last, 0, 0}, springs.data());
    }
  return blocks;
}

void layoutSprings(MuscleSettings& settings) {
  settings.springBlocks = springBlocksFor(settings);
}

SpringKernel springLayoutKernel(const MuscleSettings& settings, SpringKernel kernel) {
  if (kernel != SpringKernel::avx2) return kernel;
  // Not laid out: the springs as they are.
  return settings.springBlocks.springCount == settings.springs.size() ? kernel : SpringKernel::sse2;
}

size_t springLayoutSize(const MuscleSettings& settings, SpringKernel kernel) {
  return springLayoutKernel(settings, kernel) == SpringKernel::avx2 ? settings.springBlocks.b.size()
                                                                    : settings.springs.size();
}

size_t springLayoutBoundary(const MuscleSettings& settings, SpringKernel kernel, size_t index) {
  const size_t size = springLayoutSize(settings, kernel);
  if (index >= size) return size;
  if (springLayoutKernel(settings, kernel) == SpringKernel::avx2)
    return std::min(size, (index + 7) & ~size_t{7});  // a group of eight lanes
  const std::vector<Spring>& springs = settings.springs;
  while (index > 0 && index < size && springs[index].a == springs[index - 1].a) ++index;
  return index;
}

SpringForceResult addSpringForces(const MuscleSettings& settings,
                                  std::span<const btVector3> positions, std::span<btVector3> forces,
                                  SpringKernel kernel, size_t begin, size_t end) {
  const btVector3* x = positions.data();
  btVector3* f = forces.data();
  SpringForceResult result;
  if (begin >= end) return result;
  kernel = springLayoutKernel(settings, kernel);
  const btScalar watch = strainWatch(settings);
#if FIBREMSS_AVX2_SPRINGS
  if (kernel == SpringKernel::avx2) {
    avx2Springs(settings.springBlocks, begin, end, x, f, watch, result);
    result.exploded = result.overstretched > 0;
    return result;
  }
#endif
  const Spring* springs = settings.springs.data() + begin;
  const size_t count = end - begin;
  RunSum tail{springs[0].a, btVector3(0, 0, 0)};
  size_t s = 0;
#if FIBREMSS_SSE_SPRINGS
  if (kernel == SpringKernel::sse2) s = sse2Springs(springs, count, x, f, tail, watch, result);
#endif
  for (; s < count; ++s) addSpring(springs[s], x, f, tail, watch, result);
  f[tail.particle] += tail.sum;
  result.exploded = result.overstretched > 0;
  return result;
}

SpringForceResult addSpringForces(const MuscleSettings& settings,
                                  std::span<const btVector3> positions, std::span<btVector3> forces,
                                  std::span<const uint32_t> springs) {
  SpringForceResult result;
  if (springs.empty()) return result;
  const btScalar watch = strainWatch(settings);
  const Spring* all = settings.springs.data();
  RunSum tail{all[springs[0]].a, btVector3(0, 0, 0)};
  for (uint32_t s : springs)
    addSpring(all[s], positions.data(), forces.data(), tail, watch, result);
  forces[tail.particle] += tail.sum;
  result.exploded = result.overstretched > 0;
  return result;
}

SpringForceResult springForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                               std::span<btVector3> forces, SpringKernel kernel) {
  std::fill(forces.begin(), forces.end(), btVector3(0, 0, 0));
  return addSpringForces(settings, positions, forces, kernel, 0,
                         springLayoutSize(settings, kernel));
}

SpringForceResult springForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                               std::span<btVector3> forces) {
  return springForces(settings, positions, forces, fastestSpringKernel());
}

}  // namespace fibremss
