#include "VolumeForces.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <vector>

#include "ParticleSimd.h"

namespace fibremss {
namespace {

/// A tetrahedron's squared gradient G is bounded below by this share of its rest G0 in the
/// normalisation G0/G: only a tetrahedron shrunk towards a point comes near it.
constexpr btScalar kMinGradientShare = btScalar(0.01);

/// 1 − V/V0 from V/V0 for the force, clamped to [−1, 1]: an inverted tetrahedron is pushed open
/// and one beyond twice its rest volume pulled together with the force of strain ±1 (scaled by
/// G0/G, so the pull of a stretched one fades as it grows), never switched off: a switch would
/// hide an oscillation that a time step too large for the term starts (the tetrahedron flips
/// between inverted and torn with no force on it) from every check.
inline btScalar clampedStrain(btScalar ratio) {
  return std::min(std::max(1 - ratio, btScalar(-1)), btScalar(1));
}

/// Fan k's forces alone (the scalar kernel), modulus a sixth of K: the lanes' operations.
void scalarFan(const MuscleSettings& settings, size_t k, btScalar modulus, const btVector3* x,
               btVector3* f) {
  const std::span<const uint32_t> p = fanParticles(settings, k);
  const FanGradients g = fanGradients(x, p);
  const btScalar rest = settings.fanRestGradient[k];
  const btScalar scale = modulus * clampedStrain(g.sixVolume * settings.fanInverseVolume[k]) *
                         rest / std::max(g.squared, rest * kMinGradientShare);
  for (size_t v = 0; v < p.size(); ++v) f[p[v]] += g.gradients[v] * scale;
}

}  // namespace

#if FIBREMSS_SSE_PARTICLES
namespace {

/// forces[i] += f as one 16-byte load and store: the next tetrahedron's load of the same
/// particle is forwarded from this store (btVector3's 8 + 4 byte stores are not).
inline void addPacked(btVector3& force, __m128 f) {
  _mm_store_ps(force.m_floats, _mm_add_ps(_mm_load_ps(force.m_floats), f));
}

// The templates below run on Float8 only inlined into avxPass (always_inline), compiled for AVX:
// no __m256 crosses a call without AVX, whatever -Wpsabi fears for such calls.
#pragma GCC diagnostic ignored "-Wpsabi"

/// __m128 and __m256 without their may_alias attribute (which a template argument drops).
using Float4 = float __attribute__((vector_size(16)));
using Float8 = float __attribute__((vector_size(32)));

/// x, y and z of four vectors, one vector per lane (of two sets of four in a __m256, one per
/// 128-bit half). Arithmetic with GCC's vector operators: the same instructions as the
/// intrinsics, one rounding each.
template <class V>
struct Lanes {
  V x, y, z;
};

/// The coordinates of v0..v3 as lanes (their w lanes dropped).
inline Lanes<Float4> toLanes(__m128 v0, __m128 v1, __m128 v2, __m128 v3) {
  const __m128 xy01 = _mm_unpacklo_ps(v0, v1), xy23 = _mm_unpacklo_ps(v2, v3);
  const __m128 zw01 = _mm_unpackhi_ps(v0, v1), zw23 = _mm_unpackhi_ps(v2, v3);
  return {_mm_movelh_ps(xy01, xy23), _mm_movehl_ps(xy23, xy01), _mm_movelh_ps(zw01, zw23)};
}

/// Lane j of v as a vector (w lane 0) in out[j].
inline void fromLanes(const Lanes<Float4>& v, __m128 (&out)[4]) {
  const __m128 zero = _mm_setzero_ps();
  const __m128 xy01 = _mm_unpacklo_ps(v.x, v.y), xy23 = _mm_unpackhi_ps(v.x, v.y);
  const __m128 z01 = _mm_unpacklo_ps(v.z, zero), z23 = _mm_unpackhi_ps(v.z, zero);
  out[0] = _mm_movelh_ps(xy01, z01);
  out[1] = _mm_movehl_ps(z01, xy01);
  out[2] = _mm_movelh_ps(xy23, z23);
  out[3] = _mm_movehl_ps(z23, xy23);
}

/// clampedStrain per lane (−1 for NaN).
inline __m128 clampedStrains(__m128 strain) {
  return _mm_min_ps(_mm_max_ps(strain, _mm_set1_ps(-1)), _mm_set1_ps(1));
}

/// The larger of a and b per lane.
inline __m128 larger(__m128 a, __m128 b) {
  return _mm_max_ps(a, b);
}

#if FIBREMSS_AVX2_PARTICLES
FIBREMSS_AVX2_PASS inline Lanes<Float8> toLanes(__m256 v0, __m256 v1, __m256 v2, __m256 v3) {
  const __m256 xy01 = _mm256_unpacklo_ps(v0, v1), xy23 = _mm256_unpacklo_ps(v2, v3);
  const __m256 zw01 = _mm256_unpackhi_ps(v0, v1), zw23 = _mm256_unpackhi_ps(v2, v3);
  return {_mm256_shuffle_ps(xy01, xy23, 0x44), _mm256_shuffle_ps(xy01, xy23, 0xee),
          _mm256_shuffle_ps(zw01, zw23, 0x44)};
}

FIBREMSS_AVX2_PASS inline void fromLanes(const Lanes<Float8>& v, __m256 (&out)[4]) {
  const __m256 zero = _mm256_setzero_ps();
  const __m256 xy01 = _mm256_unpacklo_ps(v.x, v.y), xy23 = _mm256_unpackhi_ps(v.x, v.y);
  const __m256 z01 = _mm256_unpacklo_ps(v.z, zero), z23 = _mm256_unpackhi_ps(v.z, zero);
  out[0] = _mm256_shuffle_ps(xy01, z01, 0x44);
  out[1] = _mm256_shuffle_ps(xy01, z01, 0xee);
  out[2] = _mm256_shuffle_ps(xy23, z23, 0x44);
  out[3] = _mm256_shuffle_ps(xy23, z23, 0xee);
}

FIBREMSS_AVX2_PASS inline __m256 clampedStrains(__m256 strain) {
  return _mm256_min_ps(_mm256_max_ps(strain, _mm256_set1_ps(-1)), _mm256_set1_ps(1));
}

FIBREMSS_AVX2_PASS inline __m256 larger(__m256 a, __m256 b) {
  return _mm256_max_ps(a, b);
}
#endif

/// g × h per lane, with btVector3::cross's products and differences.
template <class V>
__attribute__((always_inline)) inline Lanes<V> cross(const Lanes<V>& g, const Lanes<V>& h) {
  return {g.y * h.z - g.z * h.y, g.z * h.x - g.x * h.z, g.x * h.y - g.y * h.x};
}

template <class V>
__attribute__((always_inline)) inline Lanes<V> scaled(const Lanes<V>& g, V s) {
  return {g.x * s, g.y * s, g.z * s};
}

/// a · b per lane, in btVector3::dot's order.
template <class V>
__attribute__((always_inline)) inline V dot(const Lanes<V>& a, const Lanes<V>& b) {
  return (a.x * b.x + a.y * b.y) + a.z * b.z;
}

/// (a + b) + c per lane.
template <class V>
__attribute__((always_inline)) inline Lanes<V> sum(const Lanes<V>& a, const Lanes<V>& b,
                                                   const Lanes<V>& c) {
  return {(a.x + b.x) + c.x, (a.y + b.y) + c.y, (a.z + b.z) + c.z};
}

/// (a − b) per lane.
template <class V>
__attribute__((always_inline)) inline Lanes<V> difference(const Lanes<V>& a, const Lanes<V>& b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}

/// a + b per lane.
template <class V>
__attribute__((always_inline)) inline Lanes<V> plus(const Lanes<V>& a, const Lanes<V>& b) {
  return {a.x + b.x, a.y + b.y, a.z + b.z};
}

/// The gradients ∂(6V)/∂x_i (per particle, lane-wise) of fans with Ring ring particles,
/// `edge(0)` their edges from particle a to b and `edge(1 + r)` to ring particle r, a's negated
/// (grad[0]: its force is grad[0] times the negated scale, added), and the scale of their forces
/// K/6·s·G0/G, with 1/(6·V0) `inverse`, G0 `rest` and modulus a sixth of K: scalarFan's operations
/// lane-wise. Each ring edge is loaded once, as its cross products need it, so that only two are
/// live at a time.
template <size_t Ring, class V, class Edge>
__attribute__((always_inline)) inline V fanLanes(const Edge& edge, V inverse, V rest, V modulus,
                                                 Lanes<V> (&grad)[Ring + 2]) {
  const Lanes<V> e = edge(0);
  Lanes<V>* g = grad + 2;
  Lanes<V> before = edge(1), here = edge(2);  // u_r−1 and u_r as r goes round
  Lanes<V> gb = cross(before, here);
  g[0] = cross(here, e);
  for (size_t r = 2; r < Ring; ++r) {
    const Lanes<V> next = edge(1 + r);
    gb = plus(gb, cross(here, next));
    g[r - 1] = cross(e, difference(before, next));
    before = here;
    here = next;
  }
  g[Ring - 1] = cross(e, before);
  Lanes<V> sum = gb;
  V gradient = dot(gb, gb);
  for (size_t r = 0; r < Ring; ++r) {
    sum = plus(sum, g[r]);
    gradient = gradient + dot(g[r], g[r]);
  }
  gradient = gradient + dot(sum, sum);
  grad[0] = sum;
  grad[1] = gb;
  return modulus * clampedStrains(btScalar(1) - dot(e, gb) * inverse) * rest /
         larger(gradient, rest * kMinGradientShare);
}

/// Four fans of Count particles, one per lane, lane j's particles at the byte offsets
/// b[Count·j ..] and its 1/(6·V0) and G0 in inverse[j] and rest[j]: their gradients (fanLanes)
/// into grad, and the scale of their forces.
template <size_t Count>
__attribute__((always_inline)) inline Float4 groupLanes(const uint32_t* b, const btScalar* inverse,
                                                        const btScalar* rest, btScalar modulus,
                                                        const btVector3* x,
                                                        Lanes<Float4> (&grad)[Count]) {
  __m128 origin[4];
  for (size_t j = 0; j < 4; ++j) origin[j] = loadVector(at(x, b[Count * j]));
  const auto edge = [&](size_t v) {  // particle 1 + v of each lane's fan less its particle a
    const auto from = [&](size_t j) { return loadVector(at(x, b[Count * j + 1 + v])) - origin[j]; };
    return toLanes(from(0), from(1), from(2), from(3));
  };
  return fanLanes<Count - 2>(edge, _mm_loadu_ps(inverse), _mm_loadu_ps(rest), _mm_set1_ps(modulus),
                             grad);
}

/// Adds particle v's forces of groupLanes' fans in lanes [0, lanes) (a's with the scale negated).
template <size_t Count>
__attribute__((always_inline)) inline void addGroupForces(size_t v, const Lanes<Float4>& grad,
                                                          Float4 scale, const uint32_t* b,
                                                          btVector3* f, size_t lanes = 4) {
  __m128 force[4];
  fromLanes(scaled(grad, v == 0 ? -scale : scale), force);
  for (size_t j = 0; j < lanes; ++j) addPacked(at(f, b[Count * j + v]), force[j]);
}

/// A group of four lanes for the `lanes` (one to four) fans from fan k on, at the byte offsets b:
/// their byte offsets, 1/(6·V0) and G0 into bytes, inverse and rest, lane j ≥ lanes repeating the
/// first fan's (memcpy: GCC calls memmove for a std::copy_n of Count, and copies a loop element
/// by element).
template <size_t Count>
inline void paddedGroup(const MuscleSettings& settings, size_t k, size_t lanes, const uint32_t* b,
                        uint32_t (&bytes)[4 * Count], btScalar* inverse, btScalar* rest) {
  for (size_t j = 0; j < 4; ++j) {
    const size_t fan = j < lanes ? j : 0;
    std::memcpy(bytes + Count * j, b + Count * fan, sizeof(uint32_t) * Count);
    inverse[j] = settings.fanInverseVolume[k + fan];
    rest[j] = settings.fanRestGradient[k + fan];
  }
}

/// The fans [k, end) of Count particles, fewer than eight, at the byte offsets b: a group of
/// four, then the rest (one to three) as a group whose missing lanes repeat its first fan (their
/// forces not added).
template <size_t Count>
void fanClassEnd(const MuscleSettings& settings, size_t k, size_t end, const uint32_t* b,
                 btScalar modulus, const btVector3* x, btVector3* f) {
  const btScalar* const inverse = settings.fanInverseVolume.data();
  const btScalar* const rest = settings.fanRestGradient.data();
  Lanes<Float4> grad[Count];
  if (end - k >= 4) {
    const Float4 scale = groupLanes<Count>(b, inverse + k, rest + k, modulus, x, grad);
#pragma GCC unroll 8
    for (size_t v = 0; v < Count; ++v) addGroupForces<Count>(v, grad[v], scale, b, f);
    k += 4;
    b += 4 * Count;
  }
  const size_t lanes = end - k;
  if (lanes == 0) return;
  uint32_t bytes[4 * Count];
  btScalar laneInverse[4], laneRest[4];
  paddedGroup<Count>(settings, k, lanes, b, bytes, laneInverse, laneRest);
  const Float4 scale = groupLanes<Count>(bytes, laneInverse, laneRest, modulus, x, grad);
  for (size_t v = 0; v < Count; ++v) addGroupForces<Count>(v, grad[v], scale, bytes, f, lanes);
}

/// The fans [begin, end) of Count particles each: two groups of four at a time (one fan per
/// lane), their forces added particle by particle, for each the first group's four, then the
/// second's (avxFanClass' order); then fanClassEnd.
template <size_t Count>
void sseFanClass(const MuscleSettings& settings, size_t begin, size_t end, btScalar modulus,
                 const btVector3* x, btVector3* f) {
  const btScalar* const inverse = settings.fanInverseVolume.data();
  const btScalar* const rest = settings.fanRestGradient.data();
  const uint32_t* b = settings.fanBytes.data() + settings.fanOffsets[begin];
  size_t k = begin;
  for (; k + 8 <= end; k += 8, b += 8 * Count) {
    const uint32_t* second = b + 4 * Count;  // the second group's byte offsets
    Lanes<Float4> first[Count], next[Count];
    const Float4 scale = groupLanes<Count>(b, inverse + k, rest + k, modulus, x, first);
    const Float4 nextScale =
        groupLanes<Count>(second, inverse + k + 4, rest + k + 4, modulus, x, next);
    for (size_t v = 0; v < Count; ++v) {
      addGroupForces<Count>(v, first[v], scale, b, f);
      addGroupForces<Count>(v, next[v], nextScale, second, f);
    }
  }
  fanClassEnd<Count>(settings, k, end, b, modulus, x, f);
}

#if FIBREMSS_AVX2_PARTICLES
/// groupLanes for two groups of four fans at once, the first at the byte offsets b (its 1/(6·V0)
/// and G0 in inverse[0..4) and rest[0..4)) in the low halves of __m256 registers, the second at
/// `second` (inverse[4..8), rest[4..8)) in the high halves: per lane the same operations (AVX
/// without FMA: each lane rounds as there).
template <size_t Count>
FIBREMSS_AVX2_PASS __attribute__((always_inline)) inline Float8 pairLanes(
    const uint32_t* b, const uint32_t* second, const btScalar* inverse, const btScalar* rest,
    btScalar modulus, const btVector3* x, Lanes<Float8> (&grad)[Count]) {
  __m256 origin[4];
  for (size_t j = 0; j < 4; ++j)
    origin[j] = loadPair(at(x, b[Count * j]), at(x, second[Count * j]));
  const auto edge = [&](size_t v) __attribute__((always_inline)) {  // as groupLanes' edge
    const auto from = [&](size_t j) __attribute__((always_inline)) {
      return loadPair(at(x, b[Count * j + 1 + v]), at(x, second[Count * j + 1 + v])) - origin[j];
    };
    return toLanes(from(0), from(1), from(2), from(3));
  };
  return fanLanes<Count - 2>(edge, _mm256_loadu_ps(inverse), _mm256_loadu_ps(rest),
                             _mm256_set1_ps(modulus), grad);
}

/// Particle v's forces of pairLanes' fans (a's with the scale negated), lane j's in force[j]: the
/// first group's in its low half, the second's in its high half.
FIBREMSS_AVX2_PASS __attribute__((always_inline)) inline void pairForces(size_t v,
                                                                         const Lanes<Float8>& grad,
                                                                         Float8 scale,
                                                                         __m256 (&force)[4]) {
  fromLanes(scaled(grad, v == 0 ? -scale : scale), force);
}

/// fanClassEnd on AVX2: five to seven fans [k, end) as one pair of groups, the second's missing
/// lanes repeating its first fan, their forces added in fanClassEnd's order (the first group's
/// for every particle, then the rest's): the same bits, one gradient pass instead of two. Fewer
/// fans as there.
template <size_t Count>
FIBREMSS_AVX2_PASS void avxFanClassEnd(const MuscleSettings& settings, size_t k, size_t end,
                                       const uint32_t* b, btScalar modulus, const btVector3* x,
                                       btVector3* f) {
  if (end - k <= 4) return fanClassEnd<Count>(settings, k, end, b, modulus, x, f);
  const size_t lanes = end - k - 4;  // of the second group
  uint32_t second[4 * Count];
  btScalar inverse[8], rest[8];
  for (size_t j = 0; j < 4; ++j) {
    inverse[j] = settings.fanInverseVolume[k + j];
    rest[j] = settings.fanRestGradient[k + j];
  }
  paddedGroup<Count>(settings, k + 4, lanes, b + 4 * Count, second, inverse + 4, rest + 4);
  Lanes<Float8> grad[Count];
  const Float8 scale = pairLanes<Count>(b, second, inverse, rest, modulus, x, grad);
  __m256 force[4];
  for (size_t v = 0; v < Count; ++v) {
    pairForces(v, grad[v], scale, force);
    for (size_t j = 0; j < 4; ++j) addAt(f, b[Count * j + v], _mm256_castps256_ps128(force[j]));
  }
  for (size_t v = 0; v < Count; ++v) {
    pairForces(v, grad[v], scale, force);
    for (size_t j = 0; j < lanes; ++j)
      addAt(f, second[Count * j + v], _mm256_extractf128_ps(force[j], 1));
  }
}

/// sseFanClass with its two groups in the two halves of __m256 registers (pairLanes), their
/// forces added in its order: the same bits. The class's end as there (avxFanClassEnd).
template <size_t Count>
FIBREMSS_AVX2_PASS void avxFanClass(const MuscleSettings& settings, size_t begin, size_t end,
                                    btScalar modulus, const btVector3* x, btVector3* f) {
  const uint32_t* b = settings.fanBytes.data() + settings.fanOffsets[begin];
  // Read through locals: the force stores may alias settings' vectors as far as GCC knows.
  const btScalar* const inverseVolume = settings.fanInverseVolume.data();
  const btScalar* const restGradient = settings.fanRestGradient.data();
  size_t k = begin;
  for (; k + 8 <= end; k += 8, b += 8 * Count) {
    const uint32_t* second = b + 4 * Count;  // the second group's byte offsets
    Lanes<Float8> grad[Count];
    const Float8 scale =
        pairLanes<Count>(b, second, inverseVolume + k, restGradient + k, modulus, x, grad);
#pragma GCC unroll 8
    for (size_t v = 0; v < Count; ++v) {  // particle by particle, the first group's, the second's
      __m256 force[4];
      pairForces(v, grad[v], scale, force);
      for (size_t j = 0; j < 4; ++j) addAt(f, b[Count * j + v], _mm256_castps256_ps128(force[j]));
      for (size_t j = 0; j < 4; ++j)
        addAt(f, second[Count * j + v], _mm256_extractf128_ps(force[j], 1));
    }
  }
  avxFanClassEnd<Count>(settings, k, end, b, modulus, x, f);
}
#endif

}  // namespace
#endif

namespace {

/// The fans [begin, end) with Count particles on `kernel`'s instruction set.
template <size_t Count>
void fanClassForces(const MuscleSettings& settings, size_t begin, size_t end, btScalar modulus,
                    [[maybe_unused]] SpringKernel kernel, const btVector3* x, btVector3* f) {
#if FIBREMSS_AVX2_PARTICLES
  if (kernel == SpringKernel::avx2) return avxFanClass<Count>(settings, begin, end, modulus, x, f);
#endif
#if FIBREMSS_SSE_PARTICLES
  if (kernel != SpringKernel::scalar)
    return sseFanClass<Count>(settings, begin, end, modulus, x, f);
#endif
  for (size_t k = begin; k < end; ++k) scalarFan(settings, k, modulus, x, f);
}

/// fanClassForces for every count from Count up to that of kMaxFanTetrahedra, each on its class
/// of `classes`.
template <size_t Count>
void fanForces(const MuscleSettings& settings, const FanClasses& classes, btScalar modulus,
               SpringKernel kernel, const btVector3* x, btVector3* f) {
  const size_t begin = classes.at[Count - 4], end = classes.at[Count - 3];
  if (begin < end) fanClassForces<Count>(settings, begin, end, modulus, kernel, x, f);
  if constexpr (Count < kMaxFanTetrahedra + 3)
    fanForces<Count + 1>(settings, classes, modulus, kernel, x, f);
}

}  // namespace

size_t fansUpTo(const MuscleSettings& settings, size_t begin, size_t end, size_t count) {
  const std::span<const uint32_t> offsets = settings.fanOffsets;
  const auto within = [&](size_t k) { return offsets[k + 1] - offsets[k] <= count; };
  // A range inside one class (most of a chunk's) needs no search.
  if (begin == end || !within(begin)) return begin;
  if (within(end - 1)) return end;
  while (begin < end) {
    const size_t mid = begin + (end - begin) / 2;
    if (within(mid))
      begin = mid + 1;
    else
      end = mid;
  }
  return begin;
}

FanClasses fanClasses(const MuscleSettings& settings, size_t begin, size_t end) {
  FanClasses classes;
  classes.at[0] = begin;
  for (size_t c = 0; c < kMaxFanTetrahedra; ++c)
    classes.at[c + 1] = fansUpTo(settings, classes.at[c], end, c + 4);
  return classes;
}

void addLocalVolumeForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces, SpringKernel kernel,
                          const FanClasses& classes) {
  const btScalar modulus = settings.volumeModulus / 6;  // ∂V/∂x is a sixth of a cross product
  fanForces<4>(settings, classes, modulus, kernel, positions.data(), forces.data());
}

void addLocalVolumeForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces, SpringKernel kernel, size_t begin,
                          size_t end) {
  addLocalVolumeForces(settings, positions, forces, kernel, fanClasses(settings, begin, end));
}

void addLocalVolumeForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces, SpringKernel kernel) {
  addLocalVolumeForces(settings, positions, forces, kernel, 0, settings.fanInverseVolume.size());
}

void addLocalVolumeForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces, std::span<const uint32_t> fans) {
  const btScalar modulus = settings.volumeModulus / 6;  // ∂V/∂x is a sixth of a cross product
  for (uint32_t k : fans) scalarFan(settings, k, modulus, positions.data(), forces.data());
}

void addLocalVolumeForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces) {
  addLocalVolumeForces(settings, positions, forces, fastestSpringKernel());
}

double enclosedParticleVolume(const MuscleSettings& settings,
                              std::span<const btVector3> positions) {
  const std::span<const uint32_t> faces = settings.enclosedFaces;
  if (faces.empty()) return 0;
  const btVector3 origin = positions[faces[0]];
  double sixVolume = 0;
  for (size_t k = 0; k < faces.size(); k += 3) {
    const btVector3 a = positions[faces[k]];
    const btVector3 normal = (positions[faces[k + 1]] - a).cross(positions[faces[k + 2]] - a);
    sixVolume += double((a - origin).dot(normal));
  }
  return sixVolume / 6;
}

void addEnclosedVolumeForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                             std::span<btVector3> forces) {
  const std::span<const uint32_t> faces = settings.enclosedFaces;
  if (faces.empty()) return;
  const double ratio = enclosedParticleVolume(settings, positions) / settings.enclosedRestVolume;
  const btScalar scale = settings.enclosedModulus / 6 * clampedStrain(static_cast<btScalar>(ratio));
  for (size_t k = 0; k < faces.size(); k += 3) {
    const btVector3 a = positions[faces[k]];
    const btVector3 force =
        (positions[faces[k + 1]] - a).cross(positions[faces[k + 2]] - a) * scale;
    forces[faces[k]] += force;
    forces[faces[k + 1]] += force;
    forces[faces[k + 2]] += force;
  }
}

void localVolumeJacobian(const MuscleSettings& settings, std::span<const btVector3> positions,
                         std::span<btVector3> gradients, std::span<double> weights) {
  const double modulus = double(settings.volumeModulus) / 6;
  for (size_t k = 0; k < settings.fanInverseVolume.size(); ++k) {
    const std::span<const uint32_t> p = fanParticles(settings, k);
    const FanGradients g = fanGradients(positions.data(), p);
    const btScalar rest = settings.fanRestGradient[k];
    std::copy_n(g.gradients, p.size(), gradients.begin() + settings.fanOffsets[k]);
    weights[k] = modulus * double(settings.fanInverseVolume[k]) * double(rest) /
                 double(std::max(g.squared, rest * kMinGradientShare));
  }
}

double enclosedVolumeJacobian(const MuscleSettings& settings, std::span<const btVector3> positions,
                              std::span<btVector3> gradient) {
  const std::span<const uint32_t> faces = settings.enclosedFaces;
  if (faces.empty()) return 0;
  std::fill(gradient.begin(), gradient.end(), btVector3(0, 0, 0));
  for (size_t k = 0; k < faces.size(); k += 3) {
    const btVector3 a = positions[faces[k]];
    const btVector3 normal = (positions[faces[k + 1]] - a).cross(positions[faces[k + 2]] - a) / 6;
    for (size_t v = 0; v < 3; ++v) gradient[faces[k + v]] += normal;
  }
  return double(settings.enclosedModulus) / settings.enclosedRestVolume;
}

std::vector<btVector3> enclosedRestGradients(const MuscleSettings& settings) {
  const std::span<const uint32_t> faces = settings.enclosedFaces;
  const std::span<const btVector3> x = settings.restPositions;
  std::vector<btVector3> gradient(x.size(), btVector3(0, 0, 0));
  for (size_t k = 0; k < faces.size(); k += 3) {
    const btVector3 normal = (x[faces[k + 1]] - x[faces[k]]).cross(x[faces[k + 2]] - x[faces[k]]);
    for (size_t v = 0; v < 3; ++v) gradient[faces[k + v]] += normal / 6;
  }
  return gradient;
}

void addEnclosedVolumeStiffness(const MuscleSettings& settings, std::span<btScalar> stiffness) {
  if (settings.enclosedFaces.empty()) return;
  const std::span<const btVector3> x = settings.restPositions;
  const std::vector<btVector3> gradient = enclosedRestGradients(settings);
  double squared = 0;
  for (uint32_t i = 0; i < x.size(); ++i)
    if (!settings.isFixed(i)) squared += double(gradient[i].length2());
  const auto half =
      static_cast<btScalar>(settings.enclosedModulus * squared / settings.enclosedRestVolume / 2);
  for (uint32_t i = 0; i < x.size(); ++i)
    if (!settings.isFixed(i)) stiffness[i] += half;
}

std::vector<uint32_t> fanBytes(std::span<const uint32_t> particles) {
  std::vector<uint32_t> bytes(particles.size());
  for (size_t k = 0; k < particles.size(); ++k) {
    if (particles[k] > UINT32_MAX / sizeof(btVector3))
      throw std::length_error("a volume term's particle offset does not fit 32 bits");
    bytes[k] = particles[k] * uint32_t{sizeof(btVector3)};
  }
  return bytes;
}

FanGradients fanGradients(const btVector3* x, std::span<const uint32_t> p) {
  const size_t ring = p.size() - 2;
  btVector3 u[kMaxFanTetrahedra + 1];
  std::fill(std::begin(u), std::end(u), btVector3(0, 0, 0));  // ring ≥ 2: set for the compiler
  FanGradients out;
  btVector3* g = out.gradients + 2;
  const btVector3 origin = x[p[0]], e = x[p[1]] - origin;
  for (size_t r = 0; r < ring; ++r) u[r] = x[p[2 + r]] - origin;
  btVector3 gb = u[0].cross(u[1]);
  for (size_t r = 1; r + 1 < ring; ++r) gb += u[r].cross(u[r + 1]);
  g[0] = u[1].cross(e);
  for (size_t r = 1; r + 1 < ring; ++r) g[r] = e.cross(u[r - 1] - u[r + 1]);
  g[ring - 1] = e.cross(u[ring - 2]);
  btVector3 sum = gb;
  out.squared = gb.length2();
  for (size_t r = 0; r < ring; ++r) {
    sum += g[r];
    out.squared += g[r].length2();
  }
  out.squared += sum.length2();
  out.gradients[0] = -sum;
  out.gradients[1] = gb;
  out.sixVolume = e.dot(gb);
  return out;
}

RestGradients restTetrahedronGradients(const MuscleSettings& settings, size_t k) {
  const std::span<const btVector3> x = settings.restPositions;
  const uint32_t* t = settings.tetParticles.data() + 4 * k;
  const btVector3 a = x[t[1]] - x[t[0]], b = x[t[2]] - x[t[0]], c = x[t[3]] - x[t[0]];
  const btVector3 ga = b.cross(c), gb = c.cross(a), gc = a.cross(b);
  return {{-(ga + gb + gc), ga, gb, gc}};
}

void addLocalVolumeStiffness(const MuscleSettings& settings, std::span<btScalar> stiffness) {
  for (size_t k = 0; k < settings.fanInverseVolume.size(); ++k) {
    const std::span<const uint32_t> p = fanParticles(settings, k);
    const FanGradients rest = fanGradients(settings.restPositions.data(), p);
    btScalar g[kMaxFanTetrahedra + 3], sum = 0, gradient = 0;
    for (size_t v = 0; v < p.size(); ++v) {
      g[v] = rest.gradients[v].length();
      sum += g[v];
      gradient += g[v] * g[v];
    }
    // K/V0 · (g/6)(Σg/6) · G0/G with 1/V0 = 6·inverse: K·inverse·g·Σg/6 · G0/G, halved.
    const btScalar scale = settings.volumeModulus * settings.fanInverseVolume[k] * sum / 12 *
                           settings.fanRestGradient[k] / gradient;
    for (size_t v = 0; v < p.size(); ++v)
      if (!settings.isFixed(p[v])) stiffness[p[v]] += g[v] * scale;
  }
}

}  // namespace fibremss
