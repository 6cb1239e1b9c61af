#pragma once
// The stages of preparation (method.md §2, §3, §6), one file each; prepareScene() in
// Preparation.cpp runs them in order. Internal to the library.
#include <array>
#include <cstdint>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "PreparationKdTree.h"
#include "fibremss/Geometry.h"
#include "fibremss/MuscleSettings.h"
#include "fibremss/Preparation.h"

namespace fibremss::detail {

/// "muscle 'name'": the source named in InputErrors about a muscle.
std::string muscleSource(const MuscleInput& muscle);

/// A generator for one body's random choices, independent of the other bodies (so results do
/// not depend on the order or the thread that prepares them).
std::mt19937 bodyRandom(uint32_t seed, uint32_t kind, size_t bodyIndex);

/// Fibre sampling (FibreSampling.cpp): fills restPositions, fibreParticles and fibreOffsets of
/// `out`. Particle i of fibre f gets index f·resolution + i (until mergeCloseParticles).
void sampleFibres(const MuscleInput& muscle, std::mt19937& random, MuscleSettings& out);

/// Median over the fibres of the regular step between particles (PreparationMerge.cpp) [m];
/// 0 when no fibre has three particles.
btScalar medianSampleSpacing(const MuscleSettings& muscle);

/// Merges every particle closer than `distance` to an earlier kept particle of another fibre
/// into it (PreparationMerge.cpp): kept particles of different fibres are at least `distance`
/// apart. Compacts
/// restPositions and renumbers fibreParticles/fibreOffsets (a fibre keeps one of two
/// consecutive merged particles); call before any other per-particle array exists. Returns
/// how many particles were removed.
size_t mergeCloseParticles(MuscleSettings& muscle, btScalar distance);

/// What pushOutOf moved.
struct PushedOut {
  size_t count = 0;      ///< points moved
  btScalar deepest = 0;  ///< the deepest of them lay this far inside [m]
};

/// Moves every point inside `body` out along its normal to `margin` beyond its surface
/// (PreparationOverlap.cpp, seed 001 §4.1), except those no deeper than `minDepth` that
/// `mayStay` (when given) lets stay.
PushedOut pushOutOf(std::span<btVector3> points, const MeshDistance& body, btScalar minDepth,
                    btScalar margin, const std::function<bool(const btVector3&)>& mayStay = {});

/// Springs of the muscle's layout (Springs.cpp), sorted by (a, b), a < b, no duplicates;
/// rest length = distance, k = κ / L0. Throws InputError for unusable layouts or coincident
/// particles.
/// With directions (fibreDirections, empty: none) and springs.fibreStiffnessRatio ≠ 1, a spring
/// at angle θ to the mean fibre direction of its ends gets k = κ/L0 · (ratio·cos²θ + sin²θ).
std::vector<Spring> buildSprings(const MuscleInput& muscle, std::span<const btVector3> positions,
                                 const KdTree& particles,
                                 std::span<const btVector3> directions = {});

/// Unit fibre direction at each particle (SpringsVolume.cpp): along its fibre between its two
/// neighbours (one-sided at the ends); zero for a particle on no fibre of two or more particles.
std::vector<btVector3> fibreDirections(const MuscleSettings& muscle);

/// Tetrahedra whose shape quality 6√2·V/l³ (1: regular) is below this are slivers and get no
/// volume term.
constexpr double kMinTetrahedronQuality = 0.1;

/// A tetrahedron's G0 (MuscleSettings::tetRestGradient) is at most this times (6·V0)^(4/3): a
/// regular one has 3·2^(2/3) ≈ 4.76, a sliver of quality 0.1 about 100. Capping softens the
/// poorly shaped ones (quality below about 0.5), whose stiffness K·G0/(36·V0) would otherwise
/// set the largest stable step (as the Verlet hard-case matrix showed).
constexpr double kMaxRestGradient = 12;

/// Four particle indices.
using Tetrahedron = std::array<uint32_t, 4>;

/// A muscle's interior tetrahedra (SpringsVolume.cpp): the Delaunay tetrahedra of `positions`
/// whose centroid lies inside `surface` (Delaunay fills the convex hull, and over a concave
/// surface that lies outside the muscle), in qhull's order and orientation; none when there are
/// fewer than five particles or they do not span space.
std::vector<Tetrahedron> interiorTetrahedra(const MuscleInput& input,
                                            std::span<const btVector3> positions,
                                            const TriangleMesh& surface);

/// The interior tetrahedra (interiorTetrahedra) of a subset of `positions`: particles taken in
/// order, each dropping those closer to it than `coarsening` times its distance to its nearest
/// particle (`particles` indexes `positions`); numbered as `positions`.
std::vector<Tetrahedron> coarseTetrahedra(const MuscleInput& input,
                                          std::span<const btVector3> positions,
                                          const KdTree& particles, const TriangleMesh& surface,
                                          double coarsening);

/// Renames the tetrahedra's particles after reorderParticles(muscle, order): old particle
/// order[k] becomes k.
void renumberTetrahedra(std::vector<Tetrahedron>& tetrahedra, std::span<const uint32_t> order);

/// SpringStiffness::Volume (SpringsVolume.cpp): multiplies each spring's k (κ/L0 times its
/// anisotropy) by V_a/S_a + V_b/S_b, V a particle's quarter of the interior tetrahedra around it
/// (at least a quarter of the median) and S the Σ L0 of its springs, then scales all springs so
/// that the network's Σ k·L0² (its modulus) is what it was: each particle's springs then hold
/// Σ k·L0² in proportion to its volume. Returns false, changing nothing, when the tetrahedra
/// give no volume.
bool shareStiffnessByVolume(std::span<const btVector3> positions,
                            std::span<const Tetrahedron> interior, std::vector<Spring>& springs);

/// The local volume terms (SpringsVolume.cpp): when muscle.volumeModulus > 0, fills tetParticles,
/// tetInverseVolume and tetRestGradient from the interior tetrahedra (numbered as restPositions)
/// not all of whose particles are fixed and that are not slivers; sorted by their particles.
void buildVolumeTetrahedra(MuscleSettings& muscle, std::span<const Tetrahedron> interior);

/// The enclosed-volume term (SpringsVolume.cpp): when muscle.enclosedModulus > 0, fills
/// enclosedFaces with the boundary of the interior tetrahedra (numbered as restPositions; all of
/// them, so that the faces are closed) and enclosedRestVolume with the volume they enclose; none
/// when that is not positive.
void buildEnclosedVolume(MuscleSettings& muscle, std::span<const Tetrahedron> interior);

/// Zeleny's damping estimate c = √(4·k̄·2m) (000 eq 2.11), k̄ the mean spring stiffness.
btScalar zelenyDamping(std::span<const Spring> springs, btScalar particleMass);

/// Removes the springs whose two ends are fixed (PreparationBlend.cpp): they move nothing, and
/// across two bones their length follows the joint. Returns how many were removed.
size_t dropFixedSprings(MuscleSettings& muscle);

/// Tendons (Tendons.cpp): marks kTendon on the free particles of each fibre within `fraction` of
/// its rest length beyond its last fixed particle at either end (an end without a fixed particle
/// has none), and multiplies by `stiffness` the k of every spring whose ends are both tendon or
/// fixed. Needs the fixed flags; returns how many springs it stiffened.
size_t stiffenTendons(MuscleSettings& muscle, btScalar fraction, btScalar stiffness);

/// Distance from a point to bone `bone`'s mesh, or infinity when farther than `limit` [m].
using BoneDistance = std::function<btScalar(const btVector3&, int32_t bone, btScalar limit)>;

/// The share [1] of the second-nearest bone's motion for a particle d1 ≤ d2 ≤ d3 from its three
/// nearest bones [m] (d3 = ∞ with two bones): ½ at d1 = d2, 0 at d2 = d3 (PreparationBlend.cpp).
double blendWeight(double d1, double d2, double d3);

/// The blended pre-transform (PreparationBlend.cpp): per particle, its nearest bone (A) and
/// second-nearest bone (B) at rest and w = blendWeight(d_A, d_B, d_C), the share of B's motion
/// (C the third-nearest bone; with two bones w = d_A² / (d_A² + d_B²)). Needs nearestBone. With
/// fewer than two bones: the nearest bone twice, w = 0.
void blendAttachments(MuscleSettings& muscle, size_t boneCount, const BoneDistance& distance);

/// Boundary particles, initial radii and skinning from the surface vertices (Radii.cpp):
/// sets the kBoundary flags, boundaryParticles, radii (mean distance of the vertices that
/// chose the particle), skinNeighbours, skinParticles and skinWeights.
void bindSurface(MuscleSettings& muscle, const KdTree& particles, int skinNeighbours);

/// What radius shrinking did (Radii.cpp).
struct ShrinkReport {
  size_t muscleSpheresShrunk = 0;  ///< muscle spheres made smaller
  size_t muscleSpheresZeroed = 0;  ///< of these, shrunk to radius 0
  size_t muscleSpheresCapped = 0;  ///< of these, capped at the spacing near another muscle
  size_t boneSpheresShrunk = 0;    ///< bone spheres that held a muscle particle's centre
};

/// Shrinks sphere radii until no sphere of one body overlaps a sphere of another body at rest
/// (fixed particles are not tested against their own bone). Bone spheres shrink only when a
/// muscle particle's centre lies inside them. Muscle spheres within their muscle's sample
/// spacing of another muscle's sphere are first capped at that spacing.
ShrinkReport shrinkRadii(std::vector<MuscleSettings>& muscles, std::vector<BoneSettings>& bones);

/// Fraction of surface vertices inside some sphere of the muscle.
double surfaceCoverage(const MuscleSettings& muscle);

/// What bone sphere generation did (BoneSpheres.cpp).
struct BoneSphereReport {
  size_t degenerateTriangles = 0;  ///< zero-area triangles ignored
  size_t capped = 0;               ///< spheres whose longest edge was capped
  size_t dropped = 0;              ///< spheres dropped (maxRadius, no usable normal)
  size_t pulledBack = 0;           ///< centres moved back inside a thin part of the bone
  size_t thinned = 0;              ///< roots skipped by thinning
};

/// Bone spheres by the two-ring heuristic (method.md §6); fills sphereCentres/sphereRadii.
BoneSphereReport makeBoneSpheres(const BoneInput& bone, const MeshDistance& distance,
                                 std::mt19937& random, BoneSettings& out);

}  // namespace fibremss::detail
