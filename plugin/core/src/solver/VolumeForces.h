#pragma once
// The volume-preservation terms of a muscle (issue 18), internal: one per tetrahedron of the
// particles (MuscleSettings::tetParticles), against the change of its volume, and one for the
// whole muscle (MuscleSettings::enclosedFaces), against the change of the volume its particles
// enclose.
#include <LinearMath/btVector3.h>

#include <span>

#include "SpringForces.h"
#include "fibremss/MuscleSettings.h"

namespace fibremss {

/// Adds the volume terms' forces at `positions` into `forces`: each tetrahedron of
/// settings.tetParticles with volume V and rest volume V0 gives its particle i the force
/// K·s·(G0/G)·∂V/∂x_i (K = settings.volumeModulus), s = 1 − V/V0 clamped to [−1, 1], G the sum
/// over its four particles of |∂(6V)/∂x_i|² (at least G0/100), G0 settings.tetRestGradient (G at
/// rest, capped for poorly shaped tetrahedra). Near rest, uncapped, that is the gradient of the
/// energy ½·K·(V − V0)²/V0; the factor G0/G keeps the
/// term's stiffness K·G0/(36·V0) along its gradient what it was at rest however the
/// tetrahedron is deformed (without it the stiffness grows with the squared face areas, and a
/// fixed step that is stable at rest is not once the muscle moves). On the spring kernel's
/// instruction set (fastestSpringKernel): with SSE2 four tetrahedra at a time, one from each
/// quarter of the list, then the rest one at a time; with AVX2 two such groups at a time (no FMA,
/// the same order: SSE2's bits); scalar, one at a time. A fixed order for a given kernel: the same
/// sums for any thread count.
void addTetrahedronForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces);
/// The same on `kernel`'s instruction set (tests compare them).
void addTetrahedronForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces, SpringKernel kernel);
/// The same for the tetrahedra [begin, end) only, grouped as if they were the whole list (a task's
/// share of the muscle: the order depends on the range, not on the thread).
void addTetrahedronForces(const MuscleSettings& settings, std::span<const btVector3> positions,
                          std::span<btVector3> forces, SpringKernel kernel, size_t begin,
                          size_t end);

/// The gradients ∂(6V)/∂x_i at rest of a tetrahedron's four particles (tetParticles' order).
struct RestGradients {
  btVector3 gradients[4];  ///< ∂(6V)/∂x_i [m²]
};
/// RestGradients of tetrahedron `k` of settings.tetParticles.
RestGradients restTetrahedronGradients(const MuscleSettings& settings, size_t k);

/// Adds to each free particle's row of `stiffness` half the Gershgorin bound of the volume
/// terms' stiffness at rest, K/V0·|∂V/∂x_i|·Σ_j |∂V/∂x_j|·G0/G per tetrahedron [N/m]:
/// stableTimeStep doubles spring rows the same way.
void addTetrahedronStiffness(const MuscleSettings& settings, std::span<btScalar> stiffness);

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

/// ∂V/∂x_i of the volume settings.enclosedFaces enclose, at rest, per particle (zero for a
/// particle on no face) [m²]. Allocates (start-up only).
std::vector<btVector3> enclosedRestGradients(const MuscleSettings& settings);

/// Adds to each free particle's row of `stiffness` half of K/V0·Σ_j |∂V/∂x_j|² at rest (j over
/// the free particles): the largest eigenvalue of the term's stiffness K/V0·g·gᵀ, which bounds
/// its share of the system's largest one whatever the other terms' rows are [N/m].
void addEnclosedVolumeStiffness(const MuscleSettings& settings, std::span<btScalar> stiffness);

}  // namespace fibremss
