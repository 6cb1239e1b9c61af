#pragma once
// Accuracy measures shared by every method (FibreMSS, btSoftBody, FEM), so that all are
// measured the same way (method.md §7).
#include <LinearMath/btTransform.h>
#include <LinearMath/btVector3.h>

#include <span>
#include <vector>

#include "fibremss/Geometry.h"
#include "fibremss/MuscleSettings.h"

namespace fibremss {

/// Depth of points inside bones' true triangle meshes.
struct Penetration {
  double maxMm = 0;        ///< deepest point [mm]
  double meanMm = 0;       ///< mean depth over the penetrating points [mm] (0 if none)
  size_t penetrating = 0;  ///< points with depth > 0
  size_t points = 0;       ///< points tested
};

/// Penetration of world-space points into each bone (bone b's rest-frame mesh `bones[b]`
/// placed at `boneTransforms[b]`); a point's depth is max(0, −signed distance), deepest bone.
/// `depthsMm`, when not empty (one per point), receives every point's depth [mm] (0 outside).
Penetration measurePenetration(std::span<const btVector3> points,
                               std::span<const MeshDistance* const> bones,
                               std::span<const btTransform> boneTransforms,
                               std::span<float> depthsMm = {});

/// Merges two penetration results (max of max, mean weighted by penetrating counts).
Penetration combine(const Penetration& a, const Penetration& b);

/// Signed volume enclosed by `triangles` over `vertices`, summed in double (positive when the
/// normals point outward) [length unit³].
double enclosedVolume(std::span<const std::array<uint32_t, 3>> triangles,
                      std::span<const btVector3> vertices);

/// Volume change of a deformed surface against its rest volume, in percent.
double volumeChangePercent(const TriangleMesh& rest, std::span<const btVector3> deformedVertices);

/// Spring-deviation ratio Σ|l − L0| / Σ L0 over `springs` at `positions`.
double springDeviationRatio(std::span<const Spring> springs, std::span<const btVector3> positions);

/// The largest ratio l / L0 of any spring at `positions` (0 without springs).
double worstSpringRatio(std::span<const Spring> springs, std::span<const btVector3> positions);

/// Mean length of the muscle's fibres (polylines through their particles) at `positions` [m].
double meanFibreLength(const MuscleSettings& muscle, std::span<const btVector3> positions);

/// Particles of the muscle fixed to each bone (index = bone index; `boneCount` entries).
std::vector<size_t> fixedParticlesPerBone(const MuscleSettings& muscle, size_t boneCount);

/// Whether a spring (or a mesh edge) of rest length `rest` counts as exploded at `length`:
/// longer than 3× its rest length and longer than it by more than `meanRest`, its body's mean
/// rest length. The 3× rule alone trips on springs of a few µm (converging fibre ends, jittered
/// neighbours) whose stretch is harmless. A NaN length counts as exploded.
inline bool springExploded(double length, double rest, double meanRest) {
  const double stretch = length - rest;
  return !(stretch <= 2.0 * rest || stretch <= meanRest);
}

/// Root-mean-square distance between corresponding points, in millimetres.
double rmsDistanceMm(std::span<const btVector3> a, std::span<const btVector3> b);

}  // namespace fibremss
