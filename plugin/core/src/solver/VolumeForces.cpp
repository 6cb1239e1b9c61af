#include "VolumeForces.h"

#include <algorithm>
#include <cmath>

#include "ParticleSimd.h"

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

/// The lanes of a rotated to (y, z, x, w).
inline __m128 yzx(__m128 a) {
  return _mm_shuffle_ps(a, a, _MM_SHUFFLE(3, 0, 2, 1));
}

/// a × b in lanes (z, x, y, w), from a, b and their yzx rotations: btVector3::cross's products
/// and differences before its last shuffle (w lane: 0 for finite input). yzx() puts it in order.
inline __m128 crossZxy(__m128 a, __m128 aYzx, __m128 b, __m128 bYzx) {
  return _mm_sub_ps(_mm_mul_ps(a, bYzx), _mm_mul_ps(aYzx, b));
}

/// a · g for g in lanes (z, x, y, w), in btVector3::dot's order (x + y) + z.
inline __m128 dotZxy(__m128 a, __m128 gZxy) {
  const __m128 p = _mm_mul_ps(_mm_shuffle_ps(a, a, _MM_SHUFFLE(3, 1, 0, 2)), gZxy);
  return _mm_add_ss(_mm_add_ss(_mm_shuffle_ps(p, p, _MM_SHUFFLE(1, 1, 1, 1)), _mm_movehl_ps(p, p)),
                    p);
}

/// forces[i] += f as one 16-byte load and store: the next tetrahedron's load of the same
/// particle is forwarded from this store (btVector3's 8 + 4 byte stores are not).
inline void addPacked(btVector3& force, __m128 f) {
  _mm_store_ps(force.m_floats, _mm_add_ps(_mm_load_ps(force.m_floats), f));
}

/// forces[i] -= f, as addPacked.
inline void subtractPacked(btVector3& force, __m128 f) {
  _mm_store_ps(force.m_floats, _mm_sub_ps(_mm_load_ps(force.m_floats), f));
}

/// x, y and z of four vectors, one vector per lane.
struct Lanes {
  __m128 x, y, z;
};

/// The coordinates of v0..v3 as lanes (their w lanes dropped).
inline Lanes toLanes(__m128 v0, __m128 v1, __m128 v2, __m128 v3) {
  const __m128 xy01 = _mm_unpacklo_ps(v0, v1), xy23 = _mm_unpacklo_ps(v2, v3);
  const __m128 zw01 = _mm_unpackhi_ps(v0, v1), zw23 = _mm_unpackhi_ps(v2, v3);
  return {_mm_movelh_ps(xy01, xy23), _mm_movehl_ps(xy23, xy01), _mm_movelh_ps(zw01, zw23)};
}

/// Lane j of v as a vector (w lane 0) in out[j].
inline void fromLanes(const Lanes& v, __m128 (&out)[4]) {
  const __m128 zero = _mm_setzero_ps();
  const __m128 xy01 = _mm_unpacklo_ps(v.x, v.y), xy23 = _mm_unpackhi_ps(v.x, v.y);
  const __m128 z01 = _mm_unpacklo_ps(v.z, zero), z23 = _mm_unpackhi_ps(v.z, zero);
  out[0] = _mm_movelh_ps(xy01, z01);
  out[1] = _mm_movehl_ps(z01, xy01);
  out[2] = _mm_movelh_ps(xy23, z23);
  out[3] = _mm_movehl_ps(z23, xy23);
}

/// g × h per lane, with btVector3::cross's products and differences.
inline Lanes cross(const Lanes& g, const Lanes& h) {
  return {_mm_sub_ps(_mm_mul_ps(g.y, h.z), _mm_mul_ps(g.z, h.y)),
          _mm_sub_ps(_mm_mul_ps(g.z, h.x), _mm_mul_ps(g.x, h.z)),
          _mm_sub_ps(_mm_mul_ps(g.x, h.y), _mm_mul_ps(g.y, h.x))};
}

inline Lanes scaled(const Lanes& g, __m128 s) {
  return {_mm_mul_ps(g.x, s), _mm_mul_ps(g.y, s), _mm_mul_ps(g.z, s)};
}

/// (a + b) + c per lane.
inline Lanes sum(const Lanes& a, const Lanes& b, const Lanes& c) {
  return {_mm_add_ps(_mm_add_ps(a.x, b.x), c.x), _mm_add_ps(_mm_add_ps(a.y, b.y), c.y),
          _mm_add_ps(_mm_add_ps(a.z, b.z), c.z)};
}

/// The forces of tetrahedra k, k + groups, k + 2·groups and k + 3·groups (one per lane) for each
/// k < groups, in that order (addTetrahedronForces, modulus a sixth of K). The four lie in four
/// quarters of the sorted list, so they rarely share a particle: their stores do not wait on one
/// another. Indices are read before the stores (which may alias anything).
__attribute__((always_inline)) inline void tetrahedronGroups(const uint32_t* t,
                                                             const btScalar* inverseVolume,
                                                             size_t groups, btScalar modulus,
                                                             const btVector3* x, btVector3* f) {
  const __m128 one = _mm_set1_ps(1), scale = _mm_set1_ps(modulus);
  const __m128 magnitude = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  for (size_t k = 0; k < groups; ++k) {
    uint32_t i[4][4];
    __m128 edge[3][4];
    for (size_t j = 0; j < 4; ++j) {
      const uint32_t* tj = t + 4 * (k + j * groups);
      for (size_t v = 0; v < 4; ++v) i[j][v] = tj[v];
      const __m128 origin = loadVector(x[i[j][0]]);
      for (size_t e = 0; e < 3; ++e) edge[e][j] = _mm_sub_ps(loadVector(x[i[j][e + 1]]), origin);
    }
    const Lanes a = toLanes(edge[0][0], edge[0][1], edge[0][2], edge[0][3]),
                b = toLanes(edge[1][0], edge[1][1], edge[1][2], edge[1][3]),
                c = toLanes(edge[2][0], edge[2][1], edge[2][2], edge[2][3]);
    const Lanes ga = cross(b, c), gb = cross(c, a), gc = cross(a, b);
    const __m128 sixVolume =
        _mm_add_ps(_mm_add_ps(_mm_mul_ps(a.x, ga.x), _mm_mul_ps(a.y, ga.y)), _mm_mul_ps(a.z, ga.z));
    const __m128 inverse =
        _mm_setr_ps(inverseVolume[k], inverseVolume[k + groups], inverseVolume[k + 2 * groups],
                    inverseVolume[k + 3 * groups]);
    // clampedStrain per lane: 1 − V/V0, 0 outside [0, 2·V0] (and for NaN).
    const __m128 strain = _mm_sub_ps(one, _mm_mul_ps(sixVolume, inverse));
    const __m128 s =
        _mm_mul_ps(scale, _mm_and_ps(strain, _mm_cmple_ps(_mm_and_ps(strain, magnitude), one)));
    const Lanes fa = scaled(ga, s), fb = scaled(gb, s), fc = scaled(gc, s);
    __m128 force[4][4];
    fromLanes(sum(fa, fb, fc), force[0]);
    fromLanes(fa, force[1]);
    fromLanes(fb, force[2]);
    fromLanes(fc, force[3]);
    for (size_t j = 0; j < 4; ++j) {
      subtractPacked(f[i[j][0]], force[0][j]);
      for (size_t v = 1; v < 4; ++v) addPacked(f[i[j][v]], force[v][j]);
    }
  }
}

/// The tetrahedra's forces one at a time (addTetrahedronForces' tail after the groups).
/// Tetrahedra are sorted by their first particle: its force is summed in a register along the
/// run of tetrahedra that share it, then added once. Gradients stay in (z, x, y) lanes until
/// they are added.
__attribute__((always_inline)) inline void tetrahedronPass(const uint32_t* t,
                                                           const btScalar* inverseVolume,
                                                           size_t count, btScalar modulus,
                                                           const btVector3* x, btVector3* f) {
  uint32_t first = count ? t[0] : 0;
  __m128 firstForce = _mm_setzero_ps();
  for (size_t k = 0; k < count; ++k, t += 4) {
    const uint32_t i0 = t[0], i1 = t[1], i2 = t[2], i3 = t[3];
    if (i0 != first) {
      addPacked(f[first], yzx(firstForce));
      first = i0;
      firstForce = _mm_setzero_ps();
    }
    const __m128 origin = loadVector(x[i0]);
    const __m128 a = _mm_sub_ps(loadVector(x[i1]), origin),
                 b = _mm_sub_ps(loadVector(x[i2]), origin),
                 c = _mm_sub_ps(loadVector(x[i3]), origin);
    const __m128 aYzx = yzx(a), bYzx = yzx(b), cYzx = yzx(c);
    const __m128 ga = crossZxy(b, bYzx, c, cYzx), gb = crossZxy(c, cYzx, a, aYzx),
                 gc = crossZxy(a, aYzx, b, bYzx);
    const __m128 scale =
        _mm_set1_ps(modulus * clampedStrain(_mm_cvtss_f32(dotZxy(a, ga)) * inverseVolume[k]));
    const __m128 fa = _mm_mul_ps(ga, scale), fb = _mm_mul_ps(gb, scale), fc = _mm_mul_ps(gc, scale);
    firstForce = _mm_sub_ps(firstForce, _mm_add_ps(_mm_add_ps(fa, fb), fc));
    addPacked(f[i1], yzx(fa));
    addPacked(f[i2], yzx(fb));
    addPacked(f[i3], yzx(fc));
  }
  if (count) addPacked(f[first], yzx(firstForce));
}

/// Groups of four, then the rest one at a time.
__attribute__((always_inline)) inline void tetrahedronForces(const uint32_t* t,
                                                             const btScalar* inverseVolume,
                                                             size_t count, btScalar modulus,
                                                             const btVector3* x, btVector3* f) {
  const size_t groups = count / 4;
  tetrahedronGroups(t, inverseVolume, groups, modulus, x, f);
  tetrahedronPass(t + 16 * groups, inverseVolume + 4 * groups, count - 4 * groups, modulus, x, f);
}

void ssePass(const uint32_t* t, const btScalar* inverseVolume, size_t count, btScalar modulus,
             const btVector3* x, btVector3* f) {
  tetrahedronForces(t, inverseVolume, count, modulus, x, f);
}

#if FIBREMSS_AVX2_PARTICLES
/// The same instructions VEX-encoded (three operands: no register copies), without FMA: the
/// same bits as ssePass.
FIBREMSS_AVX2_PASS void avxPass(const uint32_t* t, const btScalar* inverseVolume, size_t count,
                                btScalar modulus, const btVector3* x, btVector3* f) {
  tetrahedronForces(t, inverseVolume, count, modulus, x, f);
}
#endif

}  // namespace
#endif

void addTetrahedronForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces, SpringKernel kernel) {
  const btScalar modulus = settings.volumeModulus / 6;  // ∂V/∂x is a sixth of a cross product
  const uint32_t* t = settings.tetParticles.data();
  const btScalar* inverseVolume = settings.tetInverseVolume.data();
  const size_t count = settings.tetInverseVolume.size();
#if FIBREMSS_AVX2_PARTICLES
  if (kernel == SpringKernel::avx2)
    return avxPass(t, inverseVolume, count, modulus, positions.data(), forces.data());
#endif
#if FIBREMSS_SSE_PARTICLES
  if (kernel != SpringKernel::scalar)
    return ssePass(t, inverseVolume, count, modulus, positions.data(), forces.data());
#endif
  for (size_t k = 0; k < count; ++k, t += 4) {
    const btVector3 origin = positions[t[0]];
    const btVector3 a = positions[t[1]] - origin, b = positions[t[2]] - origin,
                    c = positions[t[3]] - origin;
    const btVector3 ga = b.cross(c), gb = c.cross(a), gc = a.cross(b);
    const btScalar scale = modulus * clampedStrain(a.dot(ga) * inverseVolume[k]);
    forces[t[0]] -= (ga + gb + gc) * scale;
    forces[t[1]] += ga * scale;
    forces[t[2]] += gb * scale;
    forces[t[3]] += gc * scale;
  }
}

void addTetrahedronForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces) {
  addTetrahedronForces(settings, positions, forces, fastestSpringKernel());
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
