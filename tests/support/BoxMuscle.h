#pragma once
// Hand-made muscles of particles and springs for the solver tests (simulation_test,
// threads_test): a free set of particles and a box of them stretched along its fibres.
#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include "SolverFixtures.h"
#include "fibremss/MuscleSettings.h"

namespace fibremss::testing {

/// Particles at `points` (no springs yet), all boundary spheres of `radius` (0: none collide).
inline std::shared_ptr<MuscleSettings> makeMuscle(const std::vector<btVector3>& points,
                                                  btScalar mass, btScalar damping,
                                                  btScalar radius = 0) {
  auto muscle = std::make_shared<MuscleSettings>();
  muscle->name = "muscle";
  muscle->restPositions = points;
  muscle->radii.assign(points.size(), radius);
  muscle->flags.assign(points.size(), radius > 0 ? kBoundary : 0);
  muscle->fixedBone.assign(points.size(), -1);
  muscle->nearestBone.assign(points.size(), -1);
  if (radius > 0)
    for (uint32_t i = 0; i < points.size(); ++i) muscle->boundaryParticles.push_back(i);
  muscle->particleMass = mass;
  muscle->damping = damping;
  return muscle;
}

/// A spring between a and b of `stiffness`, at rest at `restLength` (negative: their rest
/// distance).
inline void addSpring(MuscleSettings& muscle, uint32_t a, uint32_t b, btScalar stiffness,
                      btScalar restLength = -1) {
  if (restLength < 0) restLength = (muscle.restPositions[b] - muscle.restPositions[a]).length();
  muscle.springs.push_back({std::min(a, b), std::max(a, b), restLength, stiffness});
}

/// A box of nx × ny × nz particles (along z the "fibres"), 26-neighbour springs with k = κ/L0 and
/// rest lengths of a lattice of `restSpacing`, positions stretched by `zStretch` along z; the z = 0
/// layer is fixed to bone 0, every particle's nearest bone is 0. Boundary: all, radius
/// restSpacing/2.
inline std::shared_ptr<MuscleSettings> makeBox(int nx, int ny, int nz, btScalar restSpacing,
                                               btScalar zStretch, btScalar kappa, btScalar mass,
                                               btScalar damping, btVector3 origin = {0, 0, 0}) {
  std::vector<btVector3> points;
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x)
        points.push_back(origin + btVector3(x, y, z * zStretch) * restSpacing);
  auto muscle = makeMuscle(points, mass, damping, restSpacing / 2);
  auto index = [&](int x, int y, int z) { return static_cast<uint32_t>((z * ny + y) * nx + x); };
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) {
        muscle->nearestBone[index(x, y, z)] = 0;
        if (z == 0) fix(*muscle, index(x, y, z), 0);
        for (int dz = -1; dz <= 1; ++dz)
          for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
              const int X = x + dx, Y = y + dy, Z = z + dz;
              if (X < 0 || Y < 0 || Z < 0 || X >= nx || Y >= ny || Z >= nz) continue;
              const uint32_t a = index(x, y, z), b = index(X, Y, Z);
              if (b <= a) continue;
              const btScalar rest =
                  restSpacing * std::sqrt(static_cast<btScalar>(dx * dx + dy * dy + dz * dz));
              addSpring(*muscle, a, b, kappa / rest, rest);
            }
      }
  std::sort(muscle->springs.begin(), muscle->springs.end(),
            [](const Spring& s, const Spring& t) { return s.a != t.a ? s.a < t.a : s.b < t.b; });
  return muscle;
}

/// Zeleny's estimate c = √(4·k̄·2m) for the box (method.md §3).
inline btScalar zelenyDamping(const MuscleSettings& muscle) {
  double sum = 0;
  for (const Spring& s : muscle.springs) sum += s.stiffness;
  return static_cast<btScalar>(
      std::sqrt(4 * sum / muscle.springs.size() * 2 * muscle.particleMass));
}

}  // namespace fibremss::testing
