#pragma once
// A slab muscle lying on a box bone, for the rigid contact tests: what a ball lands on and a
// probe presses into.
#include <cmath>
#include <memory>

#include "PrepFixtures.h"
#include "SolverFixtures.h"
#include "fibremss/MuscleSettings.h"

namespace fibremss::testing {

/// A slab of nx × ny × nz particles at `spacing` (y up, the bottom layer at y = 0 from the
/// corner `origin`), every particle a boundary sphere of radius spacing/2, 26-neighbour springs
/// with k = κ/L0, mass from 1060 kg/m³, damping `damping` [N·s/m]. With `fixedBottom` the bottom
/// layer is fixed to bone 0 (else the slab floats free, no bone).
inline std::shared_ptr<MuscleSettings> slabMuscle(int nx, int ny, int nz, btScalar spacing,
                                                  btScalar kappa, btScalar damping,
                                                  bool fixedBottom,
                                                  const btVector3& origin = {0, 0, 0}) {
  std::vector<btVector3> points;
  for (int y = 0; y < ny; ++y)
    for (int z = 0; z < nz; ++z)
      for (int x = 0; x < nx; ++x) points.push_back(origin + btVector3(x, y, z) * spacing);
  const btScalar volume = nx * ny * nz * spacing * spacing * spacing;
  const std::vector<btScalar> radii(points.size(), spacing / 2);
  auto muscle = makeSpheres(points, radii, 1060 * volume / btScalar(points.size()));
  muscle->name = "slab";
  muscle->damping = damping;
  const auto index = [&](int x, int y, int z) { return uint32_t((y * nz + z) * nx + x); };
  for (int y = 0; y < ny; ++y)
    for (int z = 0; z < nz; ++z)
      for (int x = 0; x < nx; ++x) {
        const uint32_t a = index(x, y, z);
        if (fixedBottom) {
          muscle->nearestBone[a] = 0;
          if (y == 0) fix(*muscle, a, 0);
        }
        for (int dy = -1; dy <= 1; ++dy)
          for (int dz = -1; dz <= 1; ++dz)
            for (int dx = -1; dx <= 1; ++dx) {
              const int X = x + dx, Y = y + dy, Z = z + dz;
              if (X < 0 || Y < 0 || Z < 0 || X >= nx || Y >= ny || Z >= nz) continue;
              const uint32_t b = index(X, Y, Z);
              if (b <= a) continue;
              const btScalar rest = spacing * std::sqrt(btScalar(dx * dx + dy * dy + dz * dz));
              muscle->springs.push_back({a, b, rest, kappa / rest});
            }
      }
  std::sort(muscle->springs.begin(), muscle->springs.end(),
            [](const Spring& s, const Spring& t) { return s.a != t.a ? s.a < t.a : s.b < t.b; });
  return muscle;
}

/// A box bone under a slab of `width` × `depth` from the corner `origin` (its top face half a
/// spacing below the slab's bottom layer), with collision spheres in a grid under that face.
inline std::shared_ptr<BoneSettings> slabBone(btScalar width, btScalar depth, btScalar spacing,
                                              const btVector3& origin = {0, 0, 0}) {
  auto bone = makeBone();
  bone->name = "slab bone";
  const btScalar top = origin.y() - spacing / 2;
  bone->mesh = boxMesh(origin + btVector3(-spacing, top - 4 * spacing - origin.y(), -spacing),
                       origin + btVector3(width + spacing, top - origin.y(), depth + spacing));
  for (btScalar z = 0; z <= depth + btScalar(1e-6); z += spacing)
    for (btScalar x = 0; x <= width + btScalar(1e-6); x += spacing) {
      bone->sphereCentres.push_back(origin + btVector3(x, top - spacing - origin.y(), z));
      bone->sphereRadii.push_back(spacing);
    }
  return bone;
}

}  // namespace fibremss::testing
