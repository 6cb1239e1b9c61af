// The muscle material of issue 18 at preparation: the volume terms' tetrahedra and the springs'
// anisotropy along the fibres, and what the anisotropy does to a stretched cylinder.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "fibremss/Analytic.h"
#include "fibremss/Geometry.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"

namespace fibremss {
namespace {

std::vector<std::string> coarse(std::vector<std::string> overrides) {
  overrides.insert(overrides.end(), {"resolution=24", "fibre_count=48"});
  return overrides;
}

MuscleSettings preparedCylinder(const char* name, const std::vector<std::string>& overrides) {
  const LoadedScene scene = loadScene(name, coarse(overrides));
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  return *prepared.muscles.at(0);
}

TEST(VolumeTetrahedra, LieInsideTheSurfaceWithTheirRestVolume) {
  const MuscleSettings muscle = preparedCylinder("cylinder-stretch", {});
  const size_t count = muscle.tetInverseVolume.size();
  ASSERT_GT(count, muscle.particleCount());  // a tetrahedralization has several per particle
  ASSERT_EQ(muscle.tetParticles.size(), 4 * count);
  EXPECT_GT(muscle.volumeModulus, 0);
  const MeshDistance surface(muscle.restSurface);
  const auto& x = muscle.restPositions;
  double total = 0;
  for (size_t k = 0; k < count; ++k) {
    const uint32_t* t = &muscle.tetParticles[4 * k];
    const btVector3 a = x[t[1]] - x[t[0]], b = x[t[2]] - x[t[0]], c = x[t[3]] - x[t[0]];
    const double sixVolume = a.dot(b.cross(c));
    ASSERT_GT(sixVolume, 0) << k;  // positive orientation
    EXPECT_NEAR(sixVolume * muscle.tetInverseVolume[k], 1, 1e-3) << k;
    EXPECT_TRUE(surface.inside((x[t[0]] + x[t[1]] + x[t[2]] + x[t[3]]) * btScalar(0.25))) << k;
    total += sixVolume / 6;
  }
  // They fill the particles' hull, which lies inside the surface.
  EXPECT_LT(total, muscle.restVolume);
  EXPECT_GT(total, 0.3 * muscle.restVolume);

  const MuscleSettings off = preparedCylinder("cylinder-stretch", {"volume_stiffness=0"});
  EXPECT_TRUE(off.tetParticles.empty());
  EXPECT_EQ(off.volumeModulus, 0);
}

/// cos θ of a spring against the cylinder's axis (y), the fibres' direction.
btScalar axialCosine(const MuscleSettings& muscle, const Spring& spring) {
  return std::abs((muscle.restPositions[spring.b] - muscle.restPositions[spring.a]).y()) /
         spring.restLength;
}

TEST(Anisotropy, SpringsAlongTheFibresGetTheRatio) {
  const MuscleSettings iso = preparedCylinder("cylinder-stretch", {});
  const MuscleSettings aniso = preparedCylinder("cylinder-stretch", {"fibre_stiffness_ratio=3"});
  ASSERT_EQ(iso.springs.size(), aniso.springs.size());
  size_t along = 0, across = 0;
  for (size_t s = 0; s < iso.springs.size(); ++s) {
    const Spring &a = iso.springs[s], &b = aniso.springs[s];
    ASSERT_EQ(a.a, b.a);
    ASSERT_EQ(a.b, b.b);
    const btScalar factor = b.stiffness / a.stiffness;
    EXPECT_GE(factor, btScalar(1) - btScalar(1e-5));
    EXPECT_LE(factor, btScalar(3) + btScalar(1e-5));
    const btScalar cosine = axialCosine(iso, a);
    if (cosine > btScalar(0.995)) {
      EXPECT_GT(factor, btScalar(2.8)) << s;
      ++along;
    } else if (cosine < btScalar(0.1)) {
      EXPECT_LT(factor, btScalar(1.2)) << s;
      ++across;
    }
  }
  EXPECT_GT(along, 0u);
  EXPECT_GT(across, 0u);
}

/// The axial force through the cylinder's mid-plane (y = its rest centre) after the stretch: the
/// springs' tensions projected on the axis, summed over the springs that cross the plane [N].
double stretchedAxialForce(const std::vector<std::string>& overrides) {
  const LoadedScene scene = loadScene("cylinder-stretch", coarse(overrides));
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  MuscleSystem system(scene.simulation);
  std::vector<BoneHandle> bones;
  for (const auto& bone : prepared.bones) bones.push_back(system.addBone(bone));
  const MuscleHandle handle = system.addMuscle(prepared.muscles[0], bones);
  for (int pose = 0; pose < scene.poseCount; ++pose) {
    for (size_t b = 0; b < bones.size(); ++b)
      system.setBoneTransform(bones[b], scene.bonePose(b, pose));
    system.step();
  }
  const MuscleSettings& muscle = *prepared.muscles[0];
  const std::span<const btVector3> x = system.positions(handle);
  const btScalar mid = (scene.analytic.axisStart.y() + scene.analytic.axisEnd.y()) / 2;
  double force = 0;
  for (const Spring& spring : muscle.springs) {
    const btVector3 &p = x[spring.a], &q = x[spring.b];
    if ((p.y() < mid) == (q.y() < mid)) continue;
    const btVector3 d = q - p;
    const btScalar length = d.length();
    force += double(spring.stiffness * (length - spring.restLength) * std::abs(d.y()) / length);
  }
  return force;
}

// Stretched along its fibres, a cylinder with ratio r resists more, but less than r times: the
// springs across the fibres keep their stiffness. For springs in every direction and an affine
// stretch the along-fibre modulus grows by (r·⟨cos⁶⟩ + ⟨cos⁴·sin²⟩)/⟨cos⁴⟩ = (5r + 2)/7.
TEST(Anisotropy, StretchingAlongTheFibresTakesMoreForce) {
  const double iso = stretchedAxialForce({});
  const double aniso = stretchedAxialForce({"fibre_stiffness_ratio=3"});
  ASSERT_GT(iso, 0);
  EXPECT_GT(aniso / iso, 1.5);
  EXPECT_LT(aniso / iso, 3);
}

}  // namespace
}  // namespace fibremss
