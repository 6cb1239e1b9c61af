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

}  // namespace
#endif

void addTetrahedronForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces) {
  const btScalar modulus = settings.volumeModulus / 6;  // ∂V/∂x is a sixth of a cross product
  const uint32_t* t = settings.tetParticles.data();
  const size_t count = settings.tetInverseVolume.size();
#if FIBREMSS_SSE_PARTICLES
  // Tetrahedra are sorted by their first particle: its force is summed in a register along the
  // run of tetrahedra that share it, then added once.
  uint32_t first = count ? t[0] : 0;
  __m128 firstForce = _mm_setzero_ps();
  for (size_t k = 0; k < count; ++k, t += 4) {
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
  if (count) addPacked(forces[first], firstForce);
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
