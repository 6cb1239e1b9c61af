#include "Cutting.h"

#include <span>

#include "dynamics/Tearing.h"
#include "state/MuscleState.h"

namespace fibremss {
namespace {

/// The surface a blade's edge swept in the last two steps: per step the quadrilateral of its edge
/// at the start and at the end, as two triangles (exact for a blade that moves without turning).
struct Sweep {
  /// from and to at the end of the step before last, at the end of the last, at the target [m]
  btVector3 corner[6];
};

/// Whether segment p–q crosses triangle a, b, c (Möller–Trumbore; a segment in the triangle's
/// plane does not cross it).
bool crosses(const btVector3& p, const btVector3& q, const btVector3& a, const btVector3& b,
             const btVector3& c) {
  const btVector3 d = q - p, e1 = b - a, e2 = c - a;
  const btVector3 h = d.cross(e2);
  const btScalar det = e1.dot(h);
  if (det == 0) return false;
  const btScalar inverse = 1 / det;
  const btVector3 s = p - a;
  const btScalar u = inverse * s.dot(h);
  if (u < 0 || u > 1) return false;
  const btVector3 r = s.cross(e1);
  const btScalar v = inverse * d.dot(r);
  if (v < 0 || u + v > 1) return false;
  const btScalar t = inverse * e2.dot(r);
  return t >= 0 && t <= 1;
}

/// Whether segment p–q crosses the swept surface.
bool crossesSweep(const Sweep& sweep, const btVector3& p, const btVector3& q) {
  for (int k = 0; k < 4; k += 2) {
    const btVector3* c = sweep.corner + k;
    if (crosses(p, q, c[0], c[1], c[3]) || crosses(p, q, c[0], c[3], c[2])) return true;
  }
  return false;
}

/// Whether an edge of the volume term on particles `p` crosses the sweep `context`.
bool termCrossed(const ParticleState& particles, const TearState&, std::span<const uint32_t> p,
                 const void* context) {
  const Sweep& sweep = *static_cast<const Sweep*>(context);
  const btVector3* x = particles.positions.data();
  return anyTermEdge(p, [&](uint32_t i, uint32_t j) { return crossesSweep(sweep, x[i], x[j]); });
}

}  // namespace

bool cutBySweep(const ParticleState& muscle, TearState& tear, const BladeState& blade) {
  const Sweep sweep{{blade.before * blade.from, blade.before * blade.to, blade.last * blade.from,
                     blade.last * blade.to, blade.target * blade.from, blade.target * blade.to}};
  const btVector3* c = sweep.corner;
  if (c[0] == c[4] && c[1] == c[5] && c[2] == c[4] && c[3] == c[5]) return false;
  const std::vector<Spring>& springs = tear.torn->springs;
  const btVector3* x = muscle.positions.data();
  size_t cut = 0;
  for (size_t s = 0; s < springs.size(); ++s) {
    if (springs[s].a == springs[s].b || !crossesSweep(sweep, x[springs[s].a], x[springs[s].b]))
      continue;
    breakSpring(tear, s);
    ++cut;
  }
  const size_t volumeTerms = breakVolumeTerms(muscle, tear, termCrossed, &sweep);
  if (cut + volumeTerms == 0) return false;
  tear.cutSprings += cut;
  tear.brokenVolumeTerms += volumeTerms;
  separatePieces(muscle, tear);
  return true;
}

}  // namespace fibremss
