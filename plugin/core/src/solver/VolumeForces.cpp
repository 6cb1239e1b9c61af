#include "VolumeForces.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "ParticleSimd.h"

namespace fibremss {
namespace {

/// A tetrahedron's squared gradient G is bounded below by this share of its rest G0 in the
/// normalisation G0/G: only a tetrahedron shrunk towards a point comes near it.
constexpr btScalar kMinGradientShare = btScalar(0.01);

/// The tetrahedra of a muscle (MuscleSettings::tetParticles, tetInverseVolume, tetRestGradient).
struct Tetrahedra {
  const uint32_t* particles;
  const btScalar* inverseVolume;  ///< 1/(6·V0) [1/m³]
  const btScalar* restGradient;   ///< G0 [m⁴]
};

/// 1 − V/V0 from V/V0 for the force, clamped to [−1, 1]: an inverted tetrahedron is pushed open
/// and one beyond twice its rest volume pulled together with the force of strain ±1 (scaled by
/// G0/G, so the pull of a stretched one fades as it grows), never switched off: a switch would
/// hide an oscillation that a time step too large for the term starts (the tetrahedron flips
/// between inverted and torn with no force on it) from every check.
inline btScalar clampedStrain(btScalar ratio) {
  return std::min(std::max(1 - ratio, btScalar(-1)), btScalar(1));
}

/// Tetrahedra [begin, end) one at a time, modulus a sixth of K (the scalar kernel, and the
/// SIMD passes' last count mod 4).
void scalarTetrahedra(Tetrahedra t, size_t begin, size_t end, btScalar modulus, const btVector3* x,
                      btVector3* f) {
  for (size_t k = begin; k < end; ++k) {
    const uint32_t* tk = t.particles + 4 * k;
    const btVector3 origin = x[tk[0]];
    const btVector3 a = x[tk[1]] - origin, b = x[tk[2]] - origin, c = x[tk[3]] - origin;
    const btVector3 ga = b.cross(c), gb = c.cross(a), gc = a.cross(b), g0 = ga + gb + gc;
    const btScalar gradient = ga.length2() + gb.length2() + gc.length2() + g0.length2();
    const btScalar rest = t.restGradient[k];
    const btScalar scale = modulus * clampedStrain(a.dot(ga) * t.inverseVolume[k]) * rest /
                           std::max(gradient, rest * kMinGradientShare);
    f[tk[0]] -= g0 * scale;
    f[tk[1]] += ga * scale;
    f[tk[2]] += gb * scale;
    f[tk[3]] += gc * scale;
  }
}

}  // namespace

#if FIBREMSS_SSE_PARTICLES
namespace {

/// forces[i] += f as one 16-byte load and store: the next tetrahedron's load of the same
/// particle is forwarded from this store (btVector3's 8 + 4 byte stores are not).
inline void addPacked(btVector3& force, __m128 f) {
  _mm_store_ps(force.m_floats, _mm_add_ps(_mm_load_ps(force.m_floats), f));
}

/// forces[i] -= f, as addPacked.
inline void subtractPacked(btVector3& force, __m128 f) {
  _mm_store_ps(force.m_floats, _mm_sub_ps(_mm_load_ps(force.m_floats), f));
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

/// Tetrahedra k, k + groups, k + 2·groups and k + 3·groups (one per lane) of group k: their
/// particles in i[j], their 1/(6·V0) in the returned lanes, their G0 in `restGradient`.
inline __m128 groupTetrahedra(Tetrahedra t, size_t k, size_t groups, uint32_t (&i)[4][4],
                              __m128& restGradient) {
  for (size_t j = 0; j < 4; ++j)
    for (size_t v = 0; v < 4; ++v) i[j][v] = t.particles[4 * (k + j * groups) + v];
  restGradient = _mm_setr_ps(t.restGradient[k], t.restGradient[k + groups],
                             t.restGradient[k + 2 * groups], t.restGradient[k + 3 * groups]);
  return _mm_setr_ps(t.inverseVolume[k], t.inverseVolume[k + groups],
                     t.inverseVolume[k + 2 * groups], t.inverseVolume[k + 3 * groups]);
}

/// The four lanes' forces at their particles; vertex 0's force is minus the others' sum.
inline void addGroupForces(const uint32_t (&i)[4][4], const __m128 (&force)[4][4], btVector3* f) {
  for (size_t j = 0; j < 4; ++j) {
    subtractPacked(f[i[j][0]], force[0][j]);
    for (size_t v = 1; v < 4; ++v) addPacked(f[i[j][v]], force[v][j]);
  }
}

/// The forces (per vertex, per lane) of tetrahedra whose edges from vertex 0 are edge[0..2][j]
/// in lane j, with 1/(6·V0) `inverse`, G0 `rest` and modulus a sixth of K: force[0] is the sum
/// of the others, to subtract.
template <class V>
__attribute__((always_inline)) inline void tetrahedronLanes(const V (&edge)[3][4], V inverse,
                                                            V rest, V modulus, V (&force)[4][4]) {
  const Lanes<V> a = toLanes(edge[0][0], edge[0][1], edge[0][2], edge[0][3]),
                 b = toLanes(edge[1][0], edge[1][1], edge[1][2], edge[1][3]),
                 c = toLanes(edge[2][0], edge[2][1], edge[2][2], edge[2][3]);
  const Lanes<V> ga = cross(b, c), gb = cross(c, a), gc = cross(a, b), g0 = sum(ga, gb, gc);
  const V gradient = ((dot(ga, ga) + dot(gb, gb)) + dot(gc, gc)) + dot(g0, g0);
  const V s = modulus * clampedStrains(btScalar(1) - dot(a, ga) * inverse) * rest /
              larger(gradient, rest * kMinGradientShare);
  const Lanes<V> fa = scaled(ga, s), fb = scaled(gb, s), fc = scaled(gc, s);
  fromLanes(scaled(g0, s), force[0]);
  fromLanes(fa, force[1]);
  fromLanes(fb, force[2]);
  fromLanes(fc, force[3]);
}

/// The forces of tetrahedra k, k + groups, k + 2·groups and k + 3·groups (one per lane) for each
/// k < groups, in that order (addTetrahedronForces, modulus a sixth of K). The four lie in four
/// quarters of the sorted list, so they rarely share a particle: their stores do not wait on one
/// another. Indices are read before the stores (which may alias anything).
__attribute__((always_inline)) inline void tetrahedronGroups(Tetrahedra t, size_t first,
                                                             size_t groups, btScalar modulus,
                                                             const btVector3* x, btVector3* f) {
  for (size_t k = first; k < groups; ++k) {
    uint32_t i[4][4];
    __m128 rest;
    const __m128 inverse = groupTetrahedra(t, k, groups, i, rest);
    __m128 edge[3][4];
    for (size_t j = 0; j < 4; ++j)
      for (size_t e = 0; e < 3; ++e)
        edge[e][j] = loadVector(x[i[j][e + 1]]) - loadVector(x[i[j][0]]);
    __m128 force[4][4];
    tetrahedronLanes(edge, inverse, rest, _mm_set1_ps(modulus), force);
    addGroupForces(i, force, f);
  }
}

void ssePass(Tetrahedra t, size_t count, btScalar modulus, const btVector3* x, btVector3* f) {
  const size_t groups = count / 4;
  tetrahedronGroups(t, 0, groups, modulus, x, f);
  scalarTetrahedra(t, 4 * groups, count, modulus, x, f);
}

#if FIBREMSS_AVX2_PARTICLES
/// Groups k and k + 1 of tetrahedronGroups in the two halves of __m256 registers (AVX without
/// FMA: each lane rounds as there), their forces added in its order: the same bits as ssePass.
/// An odd last group and the tail as there.
FIBREMSS_AVX2_PASS void avxPass(Tetrahedra t, size_t count, btScalar modulus, const btVector3* x,
                                btVector3* f) {
  const size_t groups = count / 4;
  size_t k = 0;
  for (; k + 1 < groups; k += 2) {
    uint32_t i[2][4][4];
    __m128 rest0, rest1;
    const __m128 inverse0 = groupTetrahedra(t, k, groups, i[0], rest0);
    const __m128 inverse1 = groupTetrahedra(t, k + 1, groups, i[1], rest1);
    __m256 edge[3][4];
    for (size_t j = 0; j < 4; ++j)
      for (size_t e = 0; e < 3; ++e)
        edge[e][j] =
            loadPair(x[i[0][j][e + 1]], x[i[1][j][e + 1]]) - loadPair(x[i[0][j][0]], x[i[1][j][0]]);
    __m256 force[4][4];
    tetrahedronLanes(edge, _mm256_set_m128(inverse1, inverse0), _mm256_set_m128(rest1, rest0),
                     _mm256_set1_ps(modulus), force);
    __m128 half[2][4][4];
    for (size_t v = 0; v < 4; ++v)
      for (size_t j = 0; j < 4; ++j) {
        half[0][v][j] = _mm256_castps256_ps128(force[v][j]);
        half[1][v][j] = _mm256_extractf128_ps(force[v][j], 1);
      }
    addGroupForces(i[0], half[0], f);
    addGroupForces(i[1], half[1], f);
  }
  tetrahedronGroups(t, k, groups, modulus, x, f);
  scalarTetrahedra(t, 4 * groups, count, modulus, x, f);
}
#endif

}  // namespace
#endif

void addTetrahedronForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces, [[maybe_unused]] SpringKernel kernel,
                          size_t begin, size_t end) {
  const btScalar modulus = settings.volumeModulus / 6;  // ∂V/∂x is a sixth of a cross product
  const Tetrahedra t{settings.tetParticles.data() + 4 * begin,
                     settings.tetInverseVolume.data() + begin,
                     settings.tetRestGradient.data() + begin};
  const size_t count = end - begin;
#if FIBREMSS_AVX2_PARTICLES
  if (kernel == SpringKernel::avx2)
    return avxPass(t, count, modulus, positions.data(), forces.data());
#endif
#if FIBREMSS_SSE_PARTICLES
  if (kernel != SpringKernel::scalar)
    return ssePass(t, count, modulus, positions.data(), forces.data());
#endif
  scalarTetrahedra(t, 0, count, modulus, positions.data(), forces.data());
}

void addTetrahedronForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces, SpringKernel kernel) {
  addTetrahedronForces(settings, positions, forces, kernel, 0, settings.tetInverseVolume.size());
}

void addTetrahedronForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces) {
  addTetrahedronForces(settings, positions, forces, fastestSpringKernel());
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

RestGradients restTetrahedronGradients(const MuscleSettings& settings, size_t k) {
  const std::span<const btVector3> x = settings.restPositions;
  const uint32_t* t = settings.tetParticles.data() + 4 * k;
  const btVector3 a = x[t[1]] - x[t[0]], b = x[t[2]] - x[t[0]], c = x[t[3]] - x[t[0]];
  const btVector3 ga = b.cross(c), gb = c.cross(a), gc = a.cross(b);
  return {{-(ga + gb + gc), ga, gb, gc}};
}

void addTetrahedronStiffness(const MuscleSettings& settings, std::span<btScalar> stiffness) {
  const uint32_t* t = settings.tetParticles.data();
  for (size_t k = 0; k < settings.tetInverseVolume.size(); ++k, t += 4) {
    const RestGradients rest = restTetrahedronGradients(settings, k);
    btScalar g[4];
    for (size_t i = 0; i < 4; ++i) g[i] = rest.gradients[i].length();
    const btScalar sum = g[0] + g[1] + g[2] + g[3];
    const btScalar gradient = g[0] * g[0] + g[1] * g[1] + g[2] * g[2] + g[3] * g[3];
    // K/V0 · (g/6)(Σg/6) · G0/G with 1/V0 = 6·inverse: K·inverse·g·Σg/6 · G0/G, halved.
    const btScalar scale = settings.volumeModulus * settings.tetInverseVolume[k] * sum / 12 *
                           settings.tetRestGradient[k] / gradient;
    for (size_t i = 0; i < 4; ++i)
      if (!settings.isFixed(t[i])) stiffness[t[i]] += g[i] * scale;
  }
}

}  // namespace fibremss
