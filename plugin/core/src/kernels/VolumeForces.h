#pragma once
// The volume-preservation terms of a muscle, internal: local ones on fans of the
// tetrahedra of the particles (MuscleSettings::fanParticles), each against the change of its
// volume, and one for the whole muscle (MuscleSettings::enclosedFaces), against the change of the
// volume its particles enclose.
#include <LinearMath/btVector3.h>

#include <span>
#include <vector>

#include "SpringForces.h"
#include "fibremss/MuscleSettings.h"

namespace fibremss {

/// The most tetrahedra in one fan of the local volume terms (MuscleSettings::fanParticles).
constexpr size_t kMaxFanTetrahedra = 4;

/// Adds the local volume terms' forces at `positions` into `forces`: each fan of
/// settings.fanParticles (m ≤ kMaxFanTetrahedra tetrahedra around an edge) with volume V (its
/// tetrahedra's sum) and rest volume V0 gives its particle i the force K·s·(G0/G)·∂V/∂x_i (K =
/// settings.volumeModulus), s = 1 − V/V0 clamped to [−1, 1], G the sum over its particles of
/// |∂(6V)/∂x_i|² (at least G0/100), G0 settings.fanRestGradient (G at rest, capped for poorly
/// shaped fans). Near rest, uncapped, that is the gradient of the energy ½·K·(V − V0)²/V0; the
/// factor G0/G keeps the term's stiffness K·G0/(36·V0) along its gradient what it was at rest
/// however the fan is deformed (without it the stiffness grows with the squared face areas, and
/// a fixed step that is stable at rest is not once the muscle moves). A fan of m tetrahedra
/// gathers and scatters m + 3 particles and takes 2m + 1 cross products, where its tetrahedra
/// one by one would take 4m and 3m. On the spring kernel's instruction set
/// (fastestSpringKernel): with SSE2 two groups of four fans with as many particles at a time,
/// their forces added particle by particle (the first group's four, then the second's), then a
/// group of four and a group of the rest (its missing lanes repeating a fan); with AVX2 the two
/// groups in one register (no FMA, the same order: SSE2's bits); scalar, one at a time. A fixed
/// order for a given kernel: the same sums for any thread count.
void addLocalVolumeForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces);
/// The same on `kernel`'s instruction set (tests compare them).
void addLocalVolumeForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces, SpringKernel kernel);
/// The same for the fans [begin, end) only, grouped as if they were the whole list (a task's share
/// of the muscle: the order depends on the range, not on the thread).
void addLocalVolumeForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces, SpringKernel kernel, size_t begin,
                          size_t end);

/// The same for the fans `fans` (indices of settings.fanParticles' fans) one at a time on the
/// scalar kernel, in that order (a local step's share of a muscle, MuscleSystem::stepLocal).
void addLocalVolumeForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces, std::span<const uint32_t> fans);

/// A range of fans cut by their count of particles (they are sorted by it): those with c + 4
/// particles (c + 1 tetrahedra) are [at[c], at[c + 1]).
struct FanClasses {
  size_t at[kMaxFanTetrahedra + 1] = {};  ///< fan indices, at[0] the range's first
};
/// The FanClasses of the fans [begin, end).
FanClasses fanClasses(const MuscleSettings& settings, size_t begin, size_t end);
/// addLocalVolumeForces for the fans `classes` cut, found once (a force chunk's, so that a step
/// does not search them again).
void addLocalVolumeForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces, SpringKernel kernel,
                          const FanClasses& classes);

/// Fans the widest kernel takes at a time (two groups of four); a class's fans beyond a multiple
/// of it from the start of a call's range go as a group of four, then a group of the rest.
constexpr size_t kFanLaneGroup = 8;

/// The first fan of [begin, end) with more than `count` particles (end if none): the fans are
/// sorted by their count of particles, so [begin, that) are those with at most `count`.
size_t fansUpTo(const MuscleSettings& settings, size_t begin, size_t end, size_t count);

/// The byte offsets of `particles` in an array of btVector3 (MuscleSettings::fanBytes). Throws
/// std::length_error when they do not fit 32 bits.
std::vector<uint32_t> fanBytes(std::span<const uint32_t> particles);

/// A fan's ∂(6V)/∂x_i and volume at some positions.
struct FanGradients {
  btVector3 gradients[kMaxFanTetrahedra + 3];  ///< ∂(6V)/∂x_i, the fan's particle order [m²]
  btScalar sixVolume = 0;                      ///< 6V [m³]
  btScalar squared = 0;                        ///< Σ_i |∂(6V)/∂x_i|² [m⁴]
};
/// FanGradients of the fan of particles p (a, b, then its ring r_0 .. r_m) at x: 6V = Σ over its
/// tetrahedra (a, b, r_k, r_k+1) of (x_b − x_a)·(u_k × u_k+1), u_k = x_r_k − x_a, so ∂/∂x_b =
/// Σ u_k × u_k+1, ∂/∂x_r_k = e × (u_k−1 − u_k+1) (e = x_b − x_a, absent terms zero at the ends)
/// and ∂/∂x_a minus their sum: 2m + 1 cross products for m tetrahedra. The lane kernels compute
/// the same in the same order.
FanGradients fanGradients(const btVector3* x, std::span<const uint32_t> p);

/// The particles of fan k and their count, m + 3 for m tetrahedra (MuscleSettings::fanParticles).
inline std::span<const uint32_t> fanParticles(const MuscleSettings& settings, size_t k) {
  return {settings.fanParticles.data() + settings.fanOffsets[k],
          settings.fanOffsets[k + 1] - settings.fanOffsets[k]};
}

/// The gradients ∂(6V)/∂x_i at rest of a tetrahedron's four particles (tetParticles' order).
struct RestGradients {
  btVector3 gradients[4];  ///< ∂(6V)/∂x_i [m²]
};
/// RestGradients of tetrahedron `k` of settings.tetParticles.
RestGradients restTetrahedronGradients(const MuscleSettings& settings, size_t k);

/// Adds to each free particle's row of `stiffness` half the Gershgorin bound of the local volume
/// terms' stiffness at rest, K/V0·|∂V/∂x_i|·Σ_j |∂V/∂x_j|·G0/G per fan [N/m]:
/// stableTimeStep doubles spring rows the same way.
void addLocalVolumeStiffness(const MuscleSettings& settings, std::span<btScalar> stiffness);

/// The local volume terms' stiffness −∂F/∂x at `positions` for an implicit step's linear system:
/// fan k's is w_k·g gᵀ over its particles, g the stacked ∂(6V)/∂x_i written to `gradients` (in
/// settings.fanParticles' layout) and w_k = K/6·(1/(6·V0))·G0/G (G at least G0/100) to
/// `weights[k]`: the derivative of addLocalVolumeForces' force through its strain, with G0/G held.
/// Positive semidefinite: the strain's product with the second derivative of V (indefinite, zero
/// at rest) is left out, as the springs' compressive geometric stiffness is. The clamp of the
/// strain is not: a fan beyond it keeps its stiffness in the system. No allocation.
void localVolumeJacobian(const MuscleSettings& settings, std::span<const btVector3> positions,
                         std::span<btVector3> gradients, std::span<double> weights);

/// The volume settings.enclosedFaces enclose at `positions` [m³]: the cones of the faces from the
/// first face's first particle, each in float, summed in double.
double enclosedParticleVolume(const MuscleSettings& settings, std::span<const btVector3> positions);

/// Adds the enclosed-volume term's forces at `positions` into `forces`: each particle i of
/// settings.enclosedFaces gets K·s·∂V/∂x_i (K = settings.enclosedModulus, V
/// enclosedParticleVolume, V0 settings.enclosedRestVolume, s = 1 − V/V0 clamped to [−1, 1]), with
/// ∂V/∂x_i a sixth of the sum of (x_b − x_a) × (x_c − x_a) over the faces (a, b, c) around i (the
/// gradient of V, the faces being closed): the gradient of the energy ½·K·(V − V0)²/V0, a pressure
/// K·s on the boundary of the particles. One pass over the faces for V, one for the forces; a
/// fixed order, the same sums for any thread count.
void addEnclosedVolumeForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                             std::span<btVector3> forces);

/// The enclosed-volume term's stiffness −∂F/∂x at `positions` for an implicit step's linear
/// system, w·g gᵀ: g = ∂V/∂x_i per particle written to `gradient` (zero for a particle on no face)
/// and w = K/V0 returned (0 without the term); the strain's product with the second derivative of
/// V left out as in localVolumeJacobian. No allocation.
double enclosedVolumeJacobian(const MuscleSettings& settings, std::span<const btVector3> positions,
                              std::span<btVector3> gradient);

/// ∂V/∂x_i of the volume settings.enclosedFaces enclose, at rest, per particle (zero for a
/// particle on no face) [m²]. Allocates (start-up only).
std::vector<btVector3> enclosedRestGradients(const MuscleSettings& settings);

/// Adds to each free particle's row of `stiffness` half of K/V0·Σ_j |∂V/∂x_j|² at rest (j over
/// the free particles): the largest eigenvalue of the term's stiffness K/V0·g·gᵀ, which bounds
/// its share of the system's largest one whatever the other terms' rows are [N/m].
void addEnclosedVolumeStiffness(const MuscleSettings& settings, std::span<btScalar> stiffness);

}  // namespace fibremss
