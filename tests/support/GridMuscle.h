#pragma once
// A hand-made muscle between two cube bones, for the world, guard and determinism tests.
#include <memory>

#include "PrepFixtures.h"
#include "fibremss/MuscleSettings.h"

namespace fibremss::testing {

/// A cube bone of side 2 cm around `centre`, with one collision sphere inside it.
inline std::shared_ptr<const BoneSettings> cubeBone(const char* name, const btVector3& centre) {
  auto bone = std::make_shared<BoneSettings>();
  bone->name = name;
  const btVector3 half(0.01f, 0.01f, 0.01f);
  bone->mesh = boxMesh(centre - half, centre + half);
  bone->sphereCentres = {centre};
  bone->sphereRadii = {btScalar(0.009)};
  return bone;
}

/// A hand-made muscle between the cubes at x = ∓2 cm: a 7 × 3 × 3 particle grid along x from
/// −12 mm to +12 mm (shifted by `offsetY` along y), its end layers fixed to bone 0 (x < 0) and
/// bone 1 (x > 0), springs to the 26 neighbours with stiffness `stiffnessScale`/L0, nine fibres
/// along x, a box surface skinned to the closest particle.
inline std::shared_ptr<const MuscleSettings> gridMuscle(const char* name = "grid",
                                                        btScalar offsetY = 0,
                                                        btScalar stiffnessScale = 1) {
  auto muscle = std::make_shared<MuscleSettings>();
  muscle->name = name;
  const btScalar spacing = btScalar(0.004);
  auto index = [](int i, int j, int k) { return static_cast<uint32_t>((j * 3 + k) * 7 + i); };
  muscle->restPositions.resize(63);
  for (int j = 0; j < 3; ++j)
    for (int k = 0; k < 3; ++k) {
      for (int i = 0; i < 7; ++i) {
        const uint32_t p = index(i, j, k);
        muscle->restPositions[p] =
            btVector3((i - 3) * spacing, (j - 1) * spacing + offsetY, (k - 1) * spacing);
        muscle->fibreParticles.push_back(p);
      }
      muscle->fibreOffsets.push_back(static_cast<uint32_t>(muscle->fibreParticles.size()));
    }
  for (uint32_t p = 0; p < 63; ++p) {
    const int i = static_cast<int>(p % 7), j = static_cast<int>(p / 7 / 3),
              k = static_cast<int>(p / 7 % 3);
    const bool boundary = j != 1 || k != 1;
    const bool fixed = i == 0 || i == 6;
    muscle->flags.push_back(
        static_cast<uint8_t>((boundary ? kBoundary : 0) | (fixed ? kFixed : 0)));
    muscle->radii.push_back(boundary ? btScalar(0.0015) : btScalar(0));
    muscle->fixedBone.push_back(fixed ? (i == 0 ? 0 : 1) : -1);
    muscle->nearestBone.push_back(i <= 3 ? 0 : 1);
    if (boundary) muscle->boundaryParticles.push_back(p);
    if (fixed) muscle->fixedParticles.push_back(p);
  }
  for (uint32_t a = 0; a < 63; ++a)
    for (uint32_t b = a + 1; b < 63; ++b) {
      const btScalar length = muscle->restPositions[a].distance(muscle->restPositions[b]);
      if (length < spacing * btScalar(1.8))
        muscle->springs.push_back({a, b, length, stiffnessScale / length});
    }
  muscle->particleMass = btScalar(2.6e-5);
  muscle->damping = btScalar(0.2);
  muscle->restSurface = boxMesh(btVector3(-0.012f, offsetY - 0.005f, -0.005f),
                                btVector3(0.012f, offsetY + 0.005f, 0.005f));
  muscle->skinNeighbours = 1;
  for (const btVector3& v : muscle->restSurface.vertices) {
    uint32_t closest = 0;
    for (uint32_t p = 1; p < 63; ++p)
      if (v.distance2(muscle->restPositions[p]) < v.distance2(muscle->restPositions[closest]))
        closest = p;
    muscle->skinParticles.push_back(closest);
    muscle->skinWeights.push_back(1);
  }
  return muscle;
}

}  // namespace fibremss::testing
