#include "VolumeForces.h"

#include <algorithm>

#include "ParticleSimd.h"
#include "SpringForces.h"

namespace fibremss {
namespace {

/// 1 − V/V0 from V/V0 for the force, 0 outside [0, 2·V0]: a tetrahedron beyond twice its rest
/// volume is torn (V grows with the cube of a stretch, and the pieces of a torn muscle must not
/// be pulled back together), an inverted one is crushed (between bones: pushing it open would
/// fight the contact).
inline btScalar clampedStrain(btScalar ratio) {
  const btScalar strain = 1 - ratio;
  return std::abs(strain) <= 1 ? strain : 0;
}

}  // namespace

#if FIBREMSS_SSE_PARTICLES
namespace {

/// a × b with btVector3::cross's rounding (w lanes: 0 for finite input).
inline __m128 crossPacked(__m128 a, __m128 b) {
  const __m128 aYzx = _mm_shuffle_ps(a, a, _MM_SHUFFLE(3, 0, 2, 1));
  const __m128 bYzx = _mm_shuffle_ps(b, b, _MM_SHUFFLE(3, 0, 2, 1));
  const __m128 c = _mm_sub_ps(_mm_mul_ps(a, bYzx), _mm_mul_ps(aYzx, b));
  return _mm_shuffle_ps(c, c, _MM_SHUFFLE(3, 0, 2, 1));
}

/// a · b in btVector3::dot's order, (x + y) + z.
inline float dotPacked(__m128 a, __m128 b) {
  const __m128 p = _mm_mul_ps(a, b);
  const __m128 y = _mm_shuffle_ps(p, p, _MM_SHUFFLE(1, 1, 1, 1));
  const __m128 z = _mm_shuffle_ps(p, p, _MM_SHUFFLE(2, 2, 2, 2));
  return _mm_cvtss_f32(_mm_add_ss(_mm_add_ss(p, y), z));
}

/// forces[i] += f as one 16-byte load and store: the next tetrahedron's load of the same
/// particle is forwarded from this store (btVector3's 8 + 4 byte stores are not).
inline void addPacked(btVector3& force, __m128 f) {
  _mm_store_ps(force.m_floats, _mm_add_ps(_mm_load_ps(force.m_floats), f));
}

#if FIBREMSS_AVX2_PARTICLES
/// Eight vectors in structure-of-arrays form, lane k holding vector k.
struct Vectors8 {
  __m256 x, y, z;
};

/// Corner `corner` of the eight tetrahedra from `t` (4 particles each), transposed.
FIBREMSS_AVX2_PASS inline Vectors8 gatherCorner(std::span<const btVector3> positions,
                                                const uint32_t* t, size_t corner) {
  __m256 r[4];
  for (size_t j = 0; j < 4; ++j)
    r[j] = loadPair(positions[t[4 * j + corner]], positions[t[4 * (j + 4) + corner]]);
  const __m256 t0 = _mm256_unpacklo_ps(r[0], r[1]), t1 = _mm256_unpacklo_ps(r[2], r[3]);
  const __m256 t2 = _mm256_unpackhi_ps(r[0], r[1]), t3 = _mm256_unpackhi_ps(r[2], r[3]);
  return {_mm256_shuffle_ps(t0, t1, 0x44), _mm256_shuffle_ps(t0, t1, 0xee),
          _mm256_shuffle_ps(t2, t3, 0x44)};
}

FIBREMSS_AVX2_PASS inline Vectors8 minus(const Vectors8& a, const Vectors8& b) {
  return {_mm256_sub_ps(a.x, b.x), _mm256_sub_ps(a.y, b.y), _mm256_sub_ps(a.z, b.z)};
}

/// a × b per lane with btVector3::cross's rounding.
FIBREMSS_AVX2_PASS inline Vectors8 cross8(const Vectors8& a, const Vectors8& b) {
  return {_mm256_sub_ps(_mm256_mul_ps(a.y, b.z), _mm256_mul_ps(a.z, b.y)),
          _mm256_sub_ps(_mm256_mul_ps(a.z, b.x), _mm256_mul_ps(a.x, b.z)),
          _mm256_sub_ps(_mm256_mul_ps(a.x, b.y), _mm256_mul_ps(a.y, b.x))};
}

FIBREMSS_AVX2_PASS inline Vectors8 scaled(const Vectors8& a, __m256 s) {
  return {_mm256_mul_ps(a.x, s), _mm256_mul_ps(a.y, s), _mm256_mul_ps(a.z, s)};
}

/// The eight vectors back as one register each (w lanes 0).
FIBREMSS_AVX2_PASS inline void scatterForm(const Vectors8& v, __m128 out[8]) {
  const __m256 zero = _mm256_setzero_ps();
  const __m256 xyLow = _mm256_unpacklo_ps(v.x, v.y), xyHigh = _mm256_unpackhi_ps(v.x, v.y);
  const __m256 zLow = _mm256_unpacklo_ps(v.z, zero), zHigh = _mm256_unpackhi_ps(v.z, zero);
  const __m256 lanes[4] = {
      _mm256_shuffle_ps(xyLow, zLow, 0x44), _mm256_shuffle_ps(xyLow, zLow, 0xee),
      _mm256_shuffle_ps(xyHigh, zHigh, 0x44), _mm256_shuffle_ps(xyHigh, zHigh, 0xee)};
  for (size_t j = 0; j < 4; ++j) {
    out[j] = _mm256_castps256_ps128(lanes[j]);
    out[j + 4] = _mm256_extractf128_ps(lanes[j], 1);
  }
}

/// The forces of the first count & ~7 tetrahedra, eight at a time (the scalar formula per lane,
/// the sums into `forces` in tetrahedron order, then corner order). Returns how many it did.
FIBREMSS_AVX2_PASS size_t tetrahedronForcesAvx2(const MuscleSettings& settings,
                                                std::span<const btVector3> positions,
                                                std::span<btVector3> forces, btScalar modulus) {
  const size_t done = settings.tetInverseVolume.size() & ~size_t{7};
  const __m256 one = _mm256_set1_ps(1), zero = _mm256_setzero_ps(), k = _mm256_set1_ps(modulus);
  for (size_t first = 0; first < done; first += 8) {
    const uint32_t* t = settings.tetParticles.data() + 4 * first;
    const Vectors8 origin = gatherCorner(positions, t, 0);
    const Vectors8 a = minus(gatherCorner(positions, t, 1), origin),
                   b = minus(gatherCorner(positions, t, 2), origin),
                   c = minus(gatherCorner(positions, t, 3), origin);
    const Vectors8 ga = cross8(b, c), gb = cross8(c, a), gc = cross8(a, b);
    const __m256 dot =
        _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(a.x, ga.x), _mm256_mul_ps(a.y, ga.y)),
                      _mm256_mul_ps(a.z, ga.z));
    const __m256 strain =
        _mm256_sub_ps(one, _mm256_mul_ps(dot, _mm256_loadu_ps(&settings.tetInverseVolume[first])));
    const __m256 kept = _mm256_and_ps(_mm256_cmp_ps(strain, _mm256_sub_ps(zero, one), _CMP_GE_OQ),
                                      _mm256_cmp_ps(strain, one, _CMP_LE_OQ));
    const __m256 scale = _mm256_mul_ps(k, _mm256_and_ps(kept, strain));
    const Vectors8 fa = scaled(ga, scale), fb = scaled(gb, scale), fc = scaled(gc, scale);
    const Vectors8 f0 = {
        _mm256_sub_ps(_mm256_setzero_ps(), _mm256_add_ps(_mm256_add_ps(fa.x, fb.x), fc.x)),
        _mm256_sub_ps(_mm256_setzero_ps(), _mm256_add_ps(_mm256_add_ps(fa.y, fb.y), fc.y)),
        _mm256_sub_ps(_mm256_setzero_ps(), _mm256_add_ps(_mm256_add_ps(fa.z, fb.z), fc.z))};
    __m128 corner[4][8];
    scatterForm(f0, corner[0]);
    scatterForm(fa, corner[1]);
    scatterForm(fb, corner[2]);
    scatterForm(fc, corner[3]);
    for (size_t j = 0; j < 8; ++j)
      for (size_t v = 0; v < 4; ++v) addPacked(forces[t[4 * j + v]], corner[v][j]);
  }
  return done;
}
#endif

}  // namespace
#endif

void addTetrahedronForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces) {
  const btScalar modulus = settings.volumeModulus / 6;  // ∂V/∂x is a sixth of a cross product
  const uint32_t* t = settings.tetParticles.data();
  const size_t count = settings.tetInverseVolume.size();
#if FIBREMSS_SSE_PARTICLES
  size_t k = 0;
#if FIBREMSS_AVX2_PARTICLES
  if (fastestSpringKernel() == SpringKernel::avx2) {
    k = tetrahedronForcesAvx2(settings, positions, forces, modulus);
    t += 4 * k;
  }
#endif
  // Tetrahedra are sorted by their first particle: its force is summed in a register along the
  // run of tetrahedra that share it, then added once.
  const size_t rest = k;
  uint32_t first = k < count ? t[0] : 0;
  __m128 firstForce = _mm_setzero_ps();
  for (; k < count; ++k, t += 4) {
    if (t[0] != first) {
      addPacked(forces[first], firstForce);
      first = t[0];
      firstForce = _mm_setzero_ps();
    }
    const __m128 origin = loadVector(positions[t[0]]);
    const __m128 a = _mm_sub_ps(loadVector(positions[t[1]]), origin),
                 b = _mm_sub_ps(loadVector(positions[t[2]]), origin),
                 c = _mm_sub_ps(loadVector(positions[t[3]]), origin);
    const __m128 ga = crossPacked(b, c), gb = crossPacked(c, a), gc = crossPacked(a, b);
    const __m128 scale =
        _mm_set1_ps(modulus * clampedStrain(dotPacked(a, ga) * settings.tetInverseVolume[k]));
    const __m128 fa = _mm_mul_ps(ga, scale), fb = _mm_mul_ps(gb, scale), fc = _mm_mul_ps(gc, scale);
    firstForce = _mm_sub_ps(firstForce, _mm_add_ps(_mm_add_ps(fa, fb), fc));
    addPacked(forces[t[1]], fa);
    addPacked(forces[t[2]], fb);
    addPacked(forces[t[3]], fc);
  }
  if (rest < count) addPacked(forces[first], firstForce);
#else
  for (size_t k = 0; k < count; ++k, t += 4) {
    const btVector3 origin = positions[t[0]];
    const btVector3 a = positions[t[1]] - origin, b = positions[t[2]] - origin,
                    c = positions[t[3]] - origin;
    const btVector3 ga = b.cross(c), gb = c.cross(a), gc = a.cross(b);
    const btScalar scale = modulus * clampedStrain(a.dot(ga) * settings.tetInverseVolume[k]);
    forces[t[0]] -= (ga + gb + gc) * scale;
    forces[t[1]] += ga * scale;
    forces[t[2]] += gb * scale;
    forces[t[3]] += gc * scale;
  }
#endif
}

void addTetrahedronStiffness(const MuscleSettings& settings, std::span<btScalar> stiffness) {
  const std::span<const btVector3> x = settings.restPositions;
  const uint32_t* t = settings.tetParticles.data();
  for (size_t k = 0; k < settings.tetInverseVolume.size(); ++k, t += 4) {
    const btVector3 a = x[t[1]] - x[t[0]], b = x[t[2]] - x[t[0]], c = x[t[3]] - x[t[0]];
    const btVector3 ga = b.cross(c), gb = c.cross(a), gc = a.cross(b);
    const btScalar g[4] = {(ga + gb + gc).length(), ga.length(), gb.length(), gc.length()};
    const btScalar sum = g[0] + g[1] + g[2] + g[3];
    // K/V0 · (g/6)(Σg/6) with 1/V0 = 6·inverse: K·inverse·g·Σg/6, halved.
    const btScalar scale = settings.volumeModulus * settings.tetInverseVolume[k] * sum / 12;
    for (size_t i = 0; i < 4; ++i)
      if (!settings.isFixed(t[i])) stiffness[t[i]] += g[i] * scale;
  }
}

}  // namespace fibremss
