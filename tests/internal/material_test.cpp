// The muscle material at preparation: the volume terms' tetrahedra and the springs'
// anisotropy along the fibres, and what the anisotropy does to a stretched cylinder; the volume
// terms' force kernels and the stiffness the implicit integrators take from them.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "fibremss/Analytic.h"
#include "fibremss/Error.h"
#include "fibremss/Geometry.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "kernels/SpringForces.h"
#include "kernels/VolumeForces.h"

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
    // G0: the rest sum of the squared gradients, capped at 12·(6·V0)^(4/3) for poor shapes.
    const btVector3 ga = b.cross(c), gb = c.cross(a), gc = a.cross(b);
    const double rest = ga.length2() + gb.length2() + gc.length2() + (ga + gb + gc).length2();
    EXPECT_NEAR(muscle.tetRestGradient[k], std::min(rest, 12 * std::pow(sixVolume, 4.0 / 3)),
                1e-3 * rest)
        << k;
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

/// The volume terms' forces at x in double precision for fans [begin, end), each from its
/// tetrahedra (a, b, r_k, r_k+1) one by one: K·s·(G0/G) times ∂V/∂x_i, s = 1 − V/V0 clamped to
/// [−1, 1], V and ∂V/∂x_i the sums over its tetrahedra, G = Σ|∂(6V)/∂x_i|² at least G0/100.
std::vector<btVector3> referenceVolumeForces(const MuscleSettings& muscle,
                                             const std::vector<btVector3>& x, size_t begin,
                                             size_t end) {
  using Vector = std::array<double, 3>;
  std::vector<Vector> f(x.size(), {0, 0, 0});
  const auto edge = [&](uint32_t i, uint32_t o) {
    return Vector{double(x[i].x()) - x[o].x(), double(x[i].y()) - x[o].y(),
                  double(x[i].z()) - x[o].z()};
  };
  const auto cross = [](const Vector& u, const Vector& v) {
    return Vector{u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
  };
  const auto dot = [](const Vector& u, const Vector& v) {
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
  };
  for (size_t k = begin; k < end; ++k) {
    const uint32_t* p = &muscle.fanParticles[muscle.fanOffsets[k]];
    const size_t count = muscle.fanOffsets[k + 1] - muscle.fanOffsets[k];
    std::vector<Vector> g(count, {0, 0, 0});  // ∂(6V)/∂x of the fan's particles
    double sixVolume = 0;
    for (size_t r = 2; r + 1 < count; ++r) {  // tetrahedron (a, b, r_k, r_k+1)
      const size_t t[4] = {0, 1, r, r + 1};
      const Vector a = edge(p[t[1]], p[t[0]]), b = edge(p[t[2]], p[t[0]]),
                   c = edge(p[t[3]], p[t[0]]);
      const Vector gt[3] = {cross(b, c), cross(c, a), cross(a, b)};
      sixVolume += dot(a, gt[0]);
      for (size_t i = 0; i < 3; ++i)
        for (size_t d = 0; d < 3; ++d) {
          g[t[i + 1]][d] += gt[i][d];
          g[t[0]][d] -= gt[i][d];
        }
    }
    double gradient = 0;
    for (const Vector& gi : g) gradient += dot(gi, gi);
    const double rest = muscle.fanRestGradient[k];
    const double strain = std::clamp(1 - sixVolume * double(muscle.fanInverseVolume[k]), -1.0, 1.0);
    const double scale =
        double(muscle.volumeModulus) / 6 * strain * rest / std::max(gradient, 0.01 * rest);
    for (size_t i = 0; i < count; ++i)
      for (size_t d = 0; d < 3; ++d) f[p[i]][d] += g[i][d] * scale;
  }
  std::vector<btVector3> out;
  for (const auto& v : f) out.emplace_back(btScalar(v[0]), btScalar(v[1]), btScalar(v[2]));
  return out;
}

std::vector<btVector3> volumeForces(const MuscleSettings& muscle, const std::vector<btVector3>& x,
                                    SpringKernel kernel, size_t begin, size_t end) {
  std::vector<btVector3> forces(x.size(), btVector3(0, 0, 0));
  addLocalVolumeForces(muscle, x, forces, kernel, begin, end);
  return forces;
}

std::vector<btVector3> volumeForces(const MuscleSettings& muscle, const std::vector<btVector3>& x,
                                    SpringKernel kernel) {
  return volumeForces(muscle, x, kernel, 0, muscle.fanInverseVolume.size());
}

// Every kernel, from the first fan of each count of particles on, on every count of fans up to
// eight (each class end: a group of four, a padded group, on AVX2 five to seven as one pair of
// groups), on more up to three groups of four and on all of them, at jittered positions: within
// float rounding of the double-precision sums over the fans' tetrahedra; AVX2 (the SSE2
// instructions VEX-encoded) gives SSE2's bits.
TEST(VolumeForces, EveryKernelMatchesTheReference) {
  const MuscleSettings muscle = preparedCylinder("cylinder-stretch", {});
  std::mt19937 random(18);
  std::uniform_real_distribution<float> jitter(-1, 1);
  const btScalar amplitude = btScalar(0.05) * muscle.springs.front().restLength;
  std::vector<btVector3> x(muscle.restPositions.begin(), muscle.restPositions.end());
  for (btVector3& p : x) p += btVector3(jitter(random), jitter(random), jitter(random)) * amplitude;
  const size_t all = muscle.fanInverseVolume.size();
  std::vector<size_t> starts{0};  // the first fan of each count of particles
  for (size_t k = 1; k < all; ++k)
    if (muscle.fanOffsets[k + 1] - muscle.fanOffsets[k] !=
        muscle.fanOffsets[k] - muscle.fanOffsets[k - 1])
      starts.push_back(k);
  ASSERT_EQ(starts.size(), kMaxFanTetrahedra);  // fans of 1 .. 4 tetrahedra
  std::vector<std::pair<size_t, size_t>> ranges{{0, all}};
  for (size_t start : starts)
    for (size_t count :
         {size_t(0), size_t(1), size_t(2), size_t(3), size_t(4), size_t(5), size_t(6), size_t(7),
          size_t(8), size_t(11), size_t(12), size_t(13), size_t(21)})
      ranges.emplace_back(start, std::min(all, start + count));
  for (const auto& [begin, end] : ranges) {
    const std::vector<btVector3> reference = referenceVolumeForces(muscle, x, begin, end);
    btScalar largest = 0;
    for (const btVector3& f : reference) largest = std::max(largest, f.length());
    ASSERT_TRUE(begin == end || largest > 0) << begin << ".." << end;
    std::vector<btVector3> sse2;
    for (SpringKernel kernel : {SpringKernel::scalar, SpringKernel::sse2, SpringKernel::avx2}) {
      if (!springKernelAvailable(kernel)) continue;
      const std::vector<btVector3> forces = volumeForces(muscle, x, kernel, begin, end);
      for (size_t i = 0; i < x.size(); ++i)
        ASSERT_LE((forces[i] - reference[i]).length(), btScalar(1e-4) * largest)
            << springKernelName(kernel) << ", fans " << begin << ".." << end << ", particle " << i;
      if (kernel == SpringKernel::sse2) sse2 = forces;
      if (kernel == SpringKernel::avx2 && !sse2.empty()) {
        EXPECT_EQ(std::memcmp(forces.data(), sse2.data(), sizeof(btVector3) * x.size()), 0)
            << begin << ".." << end;
      }
    }
  }
}

// The fans hold the local terms' tetrahedra, each once: fans of one to four tetrahedra around an
// edge, no particle twice, each tetrahedron positive at rest and the fan's 1/(6·V0) that of
// their sum; and they take at most 60 % of the tetrahedra's particle visits (what the kernel
// gathers and scatters: the reason for fans).
TEST(VolumeTetrahedra, FansHoldEveryTetrahedronOnce) {
  const MuscleSettings muscle = preparedCylinder("cylinder-stretch", {});
  const auto& x = muscle.restPositions;
  std::vector<std::array<uint32_t, 4>> fromFans, tetrahedra;
  for (size_t k = 0; k < muscle.fanInverseVolume.size(); ++k) {
    const std::vector<uint32_t> p(muscle.fanParticles.begin() + muscle.fanOffsets[k],
                                  muscle.fanParticles.begin() + muscle.fanOffsets[k + 1]);
    ASSERT_GE(p.size(), 4);
    ASSERT_LE(p.size(), kMaxFanTetrahedra + 3);
    std::vector<uint32_t> sorted = p;
    std::sort(sorted.begin(), sorted.end());
    EXPECT_EQ(std::adjacent_find(sorted.begin(), sorted.end()), sorted.end()) << k;
    double sixVolume = 0;
    for (size_t r = 2; r + 1 < p.size(); ++r) {
      const double six = (x[p[1]] - x[p[0]]).dot((x[p[r]] - x[p[0]]).cross(x[p[r + 1]] - x[p[0]]));
      EXPECT_GT(six, 0) << k;
      sixVolume += six;
      std::array<uint32_t, 4> t{p[0], p[1], p[r], p[r + 1]};
      std::sort(t.begin(), t.end());
      fromFans.push_back(t);
    }
    EXPECT_NEAR(sixVolume * muscle.fanInverseVolume[k], 1, 1e-3) << k;
  }
  for (size_t k = 0; k < muscle.tetInverseVolume.size(); ++k) {
    std::array<uint32_t, 4> t;
    std::copy_n(muscle.tetParticles.begin() + 4 * k, 4, t.begin());
    std::sort(t.begin(), t.end());
    tetrahedra.push_back(t);
  }
  std::sort(fromFans.begin(), fromFans.end());
  std::sort(tetrahedra.begin(), tetrahedra.end());
  EXPECT_EQ(fromFans, tetrahedra);
  EXPECT_LT(muscle.fanParticles.size(), 0.6 * muscle.tetParticles.size());
}

// addMuscle refuses fans the kernels cannot take (named in the error), and runs fans whose byte
// offsets were left stale on a copy that has them right: the same forces as prepared.
TEST(VolumeTetrahedra, AddMuscleChecksTheFansAndLaysOutTheirOffsets) {
  const LoadedScene scene = loadScene("cylinder-stretch", coarse({}));
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  const MuscleSettings& muscle = *prepared.muscles.at(0);
  ASSERT_GT(muscle.fanInverseVolume.size(), 1u);
  const auto add = [&](MuscleSettings settings, MuscleSystem& system) {
    std::vector<BoneHandle> bones;
    for (const auto& bone : prepared.bones) bones.push_back(system.addBone(bone));
    return system.addMuscle(std::make_shared<const MuscleSettings>(std::move(settings)), bones);
  };
  const auto refused = [&](MuscleSettings bad) {
    MuscleSystem system;
    try {
      add(std::move(bad), system);
    } catch (const InputError& error) {
      return std::string(error.what()).find("volume fans") != std::string::npos;
    }
    return false;
  };
  MuscleSettings shortOffsets = muscle;
  shortOffsets.fanOffsets.pop_back();
  EXPECT_TRUE(refused(shortOffsets));
  MuscleSettings unsorted = muscle;  // the last fan (the most particles) first
  std::swap(unsorted.fanOffsets[1], unsorted.fanOffsets[unsorted.fanOffsets.size() - 2]);
  EXPECT_TRUE(refused(unsorted));
  MuscleSettings outside = muscle;
  outside.fanParticles.back() = static_cast<uint32_t>(muscle.particleCount());
  EXPECT_TRUE(refused(outside));

  MuscleSettings stale = muscle;
  std::fill(stale.fanBytes.begin(), stale.fanBytes.end(), 0u);
  MuscleSystem system;
  const MuscleHandle handle = add(stale, system);
  EXPECT_EQ(system.settings(handle).fanBytes, muscle.fanBytes);
}

// Beyond twice its rest volume a tetrahedron's strain is clamped to −1 and its pull fades as it
// grows, in every kernel: scaled by s, ∂V/∂x grows as s² and G0/G falls as s⁻⁴, so the forces at
// s = 3 are those at s = 1.5 over four, and not zero.
TEST(VolumeForces, TornTetrahedraPullWithAForceThatFades) {
  const MuscleSettings muscle = preparedCylinder("cylinder-stretch", {});
  std::vector<btVector3> near(muscle.restPositions.begin(), muscle.restPositions.end()), far = near;
  for (btVector3& p : near) p *= btScalar(1.5);  // every volume × 3.375
  for (btVector3& p : far) p *= btScalar(3);
  for (SpringKernel kernel : {SpringKernel::scalar, SpringKernel::sse2, SpringKernel::avx2}) {
    if (!springKernelAvailable(kernel)) continue;
    const std::vector<btVector3> fNear = volumeForces(muscle, near, kernel),
                                 fFar = volumeForces(muscle, far, kernel);
    btScalar largest = 0;
    for (const btVector3& f : fNear) largest = std::max(largest, f.length());
    ASSERT_GT(largest, 0) << springKernelName(kernel);
    for (size_t i = 0; i < fNear.size(); ++i)
      ASSERT_LE((fFar[i] * 4 - fNear[i]).length(), btScalar(1e-4) * largest)
          << springKernelName(kernel) << ", particle " << i;
  }
}

/// cos θ of a spring against the cylinder's axis (y), the fibres' direction.
btScalar axialCosine(const MuscleSettings& muscle, const Spring& spring) {
  return std::abs((muscle.restPositions[spring.b] - muscle.restPositions[spring.a]).y()) /
         spring.restLength;
}

// The coarse local terms: the Delaunay tetrahedra of a subset of the particles, inside the
// surface, several times fewer than those of all of them.
TEST(VolumeTetrahedra, CoarseningTakesFewerOnASubsetOfTheParticles) {
  const MuscleSettings all = preparedCylinder("cylinder-stretch", {});
  const MuscleSettings coarse = preparedCylinder("cylinder-stretch", {"volume_coarsening=2"});
  const size_t count = coarse.tetInverseVolume.size();
  ASSERT_GT(count, 0);
  EXPECT_LT(count, all.tetInverseVolume.size() / 3);
  std::vector<uint8_t> used(coarse.particleCount(), 0);
  for (uint32_t i : coarse.tetParticles) used[i] = 1;
  EXPECT_LT(std::count(used.begin(), used.end(), 1), coarse.particleCount() / 2);
  const MeshDistance surface(coarse.restSurface);
  const auto& x = coarse.restPositions;
  for (size_t k = 0; k < count; ++k) {
    const uint32_t* t = &coarse.tetParticles[4 * k];
    EXPECT_GT((x[t[1]] - x[t[0]]).dot((x[t[2]] - x[t[0]]).cross(x[t[3]] - x[t[0]])), 0) << k;
    EXPECT_TRUE(surface.inside((x[t[0]] + x[t[1]] + x[t[2]] + x[t[3]]) * btScalar(0.25))) << k;
  }
}

// The enclosed-volume term's faces bound the interior tetrahedra: every edge is crossed as often
// one way as the other (a closed surface, consistently turned), and they enclose at least the
// local terms' tetrahedra (those less the slivers) and less than the muscle's surface.
TEST(EnclosedVolume, TheFacesAreClosedAndEncloseTheTetrahedra) {
  const MuscleSettings muscle =
      preparedCylinder("cylinder-stretch", {"enclosed_volume_stiffness=4"});
  const std::vector<uint32_t>& faces = muscle.enclosedFaces;
  ASSERT_GT(faces.size(), 0);
  ASSERT_EQ(faces.size() % 3, 0);
  EXPECT_GT(muscle.enclosedModulus, 0);
  std::vector<std::pair<uint32_t, uint32_t>> edges, reversed;
  for (size_t k = 0; k < faces.size(); k += 3)
    for (size_t v = 0; v < 3; ++v) {
      const uint32_t a = faces[k + v], b = faces[k + (v + 1) % 3];
      edges.emplace_back(a, b);
      reversed.emplace_back(b, a);
    }
  std::sort(edges.begin(), edges.end());
  std::sort(reversed.begin(), reversed.end());
  EXPECT_EQ(edges, reversed);
  double tetrahedra = 0;
  for (btScalar inverse : muscle.tetInverseVolume) tetrahedra += 1 / (6 * double(inverse));
  EXPECT_GE(muscle.enclosedRestVolume, tetrahedra * (1 - 1e-4));
  EXPECT_LT(muscle.enclosedRestVolume, muscle.restVolume);
  EXPECT_DOUBLE_EQ(enclosedParticleVolume(muscle, muscle.restPositions), muscle.enclosedRestVolume);

  const MuscleSettings off = preparedCylinder("cylinder-stretch", {});
  EXPECT_TRUE(off.enclosedFaces.empty());
  EXPECT_EQ(off.enclosedModulus, 0);
}

// The force on each particle is K·(1 − V/V0) times the volume's gradient, which a central
// difference of enclosedParticleVolume measures (at jittered, shrunk positions).
TEST(EnclosedVolume, ForcesAreThePressureTimesAFiniteDifferenceOfTheVolume) {
  MuscleSettings muscle = preparedCylinder("cylinder-stretch", {"enclosed_volume_stiffness=4"});
  std::mt19937 random(18);
  std::uniform_real_distribution<float> jitter(-1, 1);
  const btScalar spacing = muscle.springs.front().restLength;
  btVector3 centre(0, 0, 0);
  for (const btVector3& p : muscle.restPositions) centre += p;
  centre /= btScalar(muscle.particleCount());
  std::vector<btVector3> x;
  for (const btVector3& p : muscle.restPositions)
    x.push_back(centre + (p - centre) * btScalar(0.98) +
                btVector3(jitter(random), jitter(random), jitter(random)) * spacing *
                    btScalar(0.05));
  std::vector<btVector3> forces(x.size(), btVector3(0, 0, 0));
  addEnclosedVolumeForces(muscle, x, forces);
  const double strain = 1 - enclosedParticleVolume(muscle, x) / muscle.enclosedRestVolume;
  ASSERT_GT(strain, 0.03);  // shrunk by 2 % in each direction
  const double pressure = double(muscle.enclosedModulus) * strain;
  double largest = 0;
  for (const btVector3& f : forces) largest = std::max(largest, double(f.length()) / pressure);
  ASSERT_GT(largest, 0);
  const btScalar h = btScalar(1e-3) * spacing;
  for (uint32_t i = 0; i < x.size(); i += 7)
    for (int d = 0; d < 3; ++d) {
      std::vector<btVector3> moved = x;
      moved[i][d] = x[i][d] + h;
      const double up = enclosedParticleVolume(muscle, moved);
      moved[i][d] = x[i][d] - h;
      const double down = enclosedParticleVolume(muscle, moved);
      const double gradient = (up - down) / (double(x[i][d] + h) - double(x[i][d] - h));
      EXPECT_NEAR(forces[i][d] / pressure, gradient, 0.02 * largest) << i << " " << d;
    }
}

TEST(Anisotropy, SpringsAlongTheFibresGetTheRatio) {
  // By length, so that the factor is the anisotropy's alone (by volume the network is rescaled).
  const MuscleSettings iso = preparedCylinder("cylinder-stretch", {"spring_stiffness=length"});
  const MuscleSettings aniso =
      preparedCylinder("cylinder-stretch", {"spring_stiffness=length", "fibre_stiffness_ratio=3"});
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

/// Σ k·L0² of the springs whose midpoint lies in y ∈ [low, high] over the muscle's volume there
/// (the surface sampled on a 2 mm grid): the modulus of that slab of the network [Pa].
double slabModulus(const MuscleSettings& muscle, btScalar low, btScalar high) {
  double network = 0;
  for (const Spring& spring : muscle.springs) {
    const btScalar y =
        (muscle.restPositions[spring.a].y() + muscle.restPositions[spring.b].y()) / 2;
    if (y >= low && y < high)
      network += double(spring.stiffness) * spring.restLength * spring.restLength;
  }
  const MeshDistance surface(muscle.restSurface);
  const btScalar step = 0.002;
  size_t inside = 0;
  for (btScalar x = -0.025; x < 0.025; x += step)
    for (btScalar y = low + step / 2; y < high; y += step)
      for (btScalar z = -0.025; z < 0.025; z += step) inside += surface.inside(btVector3(x, y, z));
  return network / (double(inside) * step * step * step);
}

TEST(SpringStiffness, ByVolumeTheSpindlesThinEndIsAsStiffPerVolumeAsItsBelly) {
  // fusiform: as many fibres through its 6 mm ends as through its 20 mm belly. By length
  // (k = κ/L0) an end slab holds about the belly's Σk·L0² in a quarter of its volume; by volume
  // the springs share the stiffness as a continuum's E·A would.
  const auto prepare = [](const char* rule) {
    const LoadedScene scene =
        loadScene("fusiform", {"resolution=30", std::string("spring_stiffness=") + rule});
    return *prepareScene(scene.bones, scene.muscles, scene.simulation.seed).muscles.at(0);
  };
  const MuscleSettings volume = prepare("volume"), length = prepare("length");
  const btScalar endLow = 0.095, endHigh = 0.125, bellyLow = -0.015, bellyHigh = 0.015;
  const double byVolume =
      slabModulus(volume, endLow, endHigh) / slabModulus(volume, bellyLow, bellyHigh);
  const double byLength =
      slabModulus(length, endLow, endHigh) / slabModulus(length, bellyLow, bellyHigh);
  EXPECT_GT(byLength, 2) << "by length the thin end is stiffer per volume";
  EXPECT_GT(byVolume, 0.67);
  EXPECT_LT(byVolume, 1.5);
  // The network's modulus is shared, not changed: the same Σk·L0² (fixed springs dropped alike).
  EXPECT_NEAR(volume.volumeModulus, length.volumeModulus, 0.1 * length.volumeModulus);
}

// The volume terms' stiffness the implicit integrators' linear systems take (localVolumeJacobian,
// enclosedVolumeJacobian) is the derivative of their forces at rest: central differences of the
// forces along a random move d give −K·d, K = Σ w·g·gᵀ.
TEST(VolumeTerm, TheImplicitJacobianIsTheForcesDerivativeAtRest) {
  const LoadedScene scene = loadScene(
      "cylinder-twist", {"resolution=10", "fibre_count=16", "enclosed_volume_stiffness=4"});
  const PreparedScene prepared = prepareScene(scene.bones, scene.muscles, scene.simulation.seed);
  const MuscleSettings& settings = *prepared.muscles[0];
  ASSERT_FALSE(settings.fanInverseVolume.empty());
  ASSERT_FALSE(settings.enclosedFaces.empty());
  const size_t n = settings.particleCount();
  std::mt19937 random(7);
  std::uniform_real_distribution<float> unit(-1, 1);
  std::vector<btVector3> direction(n);
  for (btVector3& d : direction) d = btVector3(unit(random), unit(random), unit(random));
  const btScalar step = btScalar(1e-6);  // [m], against particles about a millimetre apart
  std::vector<btVector3> plus = settings.restPositions, minus = settings.restPositions;
  for (size_t i = 0; i < n; ++i) {
    plus[i] += direction[i] * step;
    minus[i] -= direction[i] * step;
  }
  std::vector<btVector3> forcePlus(n, btVector3(0, 0, 0)), forceMinus(n, btVector3(0, 0, 0));
  addLocalVolumeForces(settings, plus, forcePlus);
  addEnclosedVolumeForces(settings, plus, forcePlus);
  addLocalVolumeForces(settings, minus, forceMinus);
  addEnclosedVolumeForces(settings, minus, forceMinus);

  std::vector<btVector3> gradients(settings.fanParticles.size()), enclosed(n);
  std::vector<double> weights(settings.fanInverseVolume.size());
  localVolumeJacobian(settings, settings.restPositions, gradients, weights);
  const double enclosedWeight = enclosedVolumeJacobian(settings, settings.restPositions, enclosed);
  EXPECT_GT(enclosedWeight, 0);
  std::vector<double> product(3 * n, 0.0);  // K·d
  const auto addRankOne = [&](std::span<const uint32_t> particles, const btVector3* g, double w) {
    double dot = 0;
    for (size_t v = 0; v < particles.size(); ++v) dot += double(g[v].dot(direction[particles[v]]));
    for (size_t v = 0; v < particles.size(); ++v)
      for (int j = 0; j < 3; ++j) product[3 * particles[v] + j] += w * dot * double(g[v][j]);
  };
  for (size_t k = 0; k < weights.size(); ++k)
    addRankOne(fanParticles(settings, k), gradients.data() + settings.fanOffsets[k], weights[k]);
  std::vector<uint32_t> all(n);
  for (uint32_t i = 0; i < n; ++i) all[i] = i;
  addRankOne(all, enclosed.data(), enclosedWeight);

  double error = 0, norm = 0;
  for (size_t i = 0; i < n; ++i)
    for (int j = 0; j < 3; ++j) {
      const double difference = double(forcePlus[i][j] - forceMinus[i][j]) / (2 * double(step));
      error += (difference + product[3 * i + j]) * (difference + product[3 * i + j]);
      norm += product[3 * i + j] * product[3 * i + j];
    }
  ASSERT_GT(norm, 0);
  EXPECT_LT(std::sqrt(error / norm), 0.02);
}

}  // namespace
}  // namespace fibremss
