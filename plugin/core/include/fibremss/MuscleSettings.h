#pragma once
// The prepared, immutable description of muscles and bones (Jolt's "shared settings"): made
// once by preparation, shared read-only by every simulation instance, never changed by a step.
// Particle data is structure-of-arrays; everything refers to particles by index.
#include <LinearMath/btScalar.h>
#include <LinearMath/btVector3.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "fibremss/Geometry.h"

namespace fibremss {

/// One spring between particles a < b.
struct Spring {
  uint32_t a;           ///< first particle index (a < b)
  uint32_t b;           ///< second particle index
  btScalar restLength;  ///< L0 [m]
  btScalar stiffness;   ///< k = κ / L0 [N/m]
};

/// The springs as the AVX2 spring-force kernel reads them (layoutSprings in SpringForces.h):
/// each run of springs that share a split into blocks of kLanes lanes with one a,
/// structure-of-arrays, so that x[a] is one load and the force on a one sum per block. Runs
/// alternate between even and odd blocks (an even number of blocks, padded with empty ones).
/// Particles are byte offsets i·sizeof(btVector3) into the particle arrays (an address is one
/// add). Padding lanes have b = a, L0 = 0, k = 0 (zero force, zero deviation).
struct SpringBlocks {
  static constexpr size_t kLanes = 4;  ///< springs per block
  std::vector<uint32_t> a;             ///< the particle a of each block (byte offset)
  std::vector<uint32_t> b;             ///< kLanes per block: b, or a in a padding lane (offsets)
  std::vector<btScalar> restLength;    ///< kLanes per block: L0, or 0 in a padding lane
  std::vector<btScalar> stiffness;     ///< kLanes per block: k, or 0 in a padding lane
  size_t springCount = 0;              ///< springs laid out (the kernel's check against `springs`)

  bool operator==(const SpringBlocks&) const = default;
};

/// Bit flags per particle.
enum ParticleFlag : uint8_t {
  kBoundary = 1,  ///< closest particle of at least one surface vertex: collides
  kFixed = 2,     ///< attached to a bone: moves rigidly with it, never integrated
  kTendon = 4,    ///< free, in a tendon: between the attachment and the belly along a fibre
};

/// A prepared muscle in its rest pose (world coordinates of the rest pose).
struct MuscleSettings {
  std::string name;  ///< muscle name from the scene

  // Particles, structure-of-arrays, all of size particleCount().
  std::vector<btVector3> restPositions;  ///< rest position [m]
  std::vector<btScalar> radii;           ///< collision sphere radius [m] (0 if not boundary)
  std::vector<uint8_t> flags;            ///< ParticleFlag bits
  std::vector<int32_t> fixedBone;        ///< bone index a fixed particle follows, else -1
  std::vector<int32_t> nearestBone;      ///< bone whose motion pre-transforms it (-1: none)
  // Blended pre-transform (empty: nearestBone alone is used): a free particle moves by
  // p + (1−w)·(T_A·p − p) + w·(T_B·p − p); A its nearest bone, B the second nearest, w from their
  // rest distances, so the motion is continuous where the nearest bone changes.
  std::vector<int32_t> blendBoneA;    ///< first bone of the blend (the nearest; -1: none)
  std::vector<int32_t> blendBoneB;    ///< second bone (the second nearest; == A if only one)
  std::vector<btScalar> blendWeight;  ///< w, the share of blendBoneB's motion (0..½)

  std::vector<uint32_t> boundaryParticles;  ///< indices of boundary particles, ascending
  std::vector<uint32_t> fixedParticles;     ///< indices of fixed particles, ascending

  btScalar particleMass = 0;  ///< the same for every particle [kg]
  btScalar damping = 0;       ///< spring damping coefficient c [N·s/m]
  double restVolume = 0;      ///< volume enclosed by restSurface [m³]
  /// Largest current / rest length of a spring after an iteration (SpringParameters::strainLimit)
  /// [1]; 0: none.
  btScalar strainLimit = 0;
  /// Current / rest length beyond which a spring breaks after a step (SpringParameters::
  /// breakStretch) [1]; 0: none.
  btScalar breakStretch = 0;
  // Local volume terms (VolumeForces.h): the Delaunay tetrahedra of the particles whose centroid
  // lies inside restSurface, without slivers; empty when volumeModulus is 0.
  btScalar volumeModulus = 0;              ///< bulk modulus K of the volume terms [Pa]; 0: none
  std::vector<uint32_t> tetParticles;      ///< 4 per tetrahedron, positive rest orientation
  std::vector<btScalar> tetInverseVolume;  ///< per tetrahedron: 1 / (6·V0) [1/m³]
  /// per tetrahedron: G0 = Σ over its four particles of |∂(6V)/∂x_i|² at rest, capped for
  /// poorly shaped ones (VolumeForces.h) [m⁴]
  std::vector<btScalar> tetRestGradient;
  // The same tetrahedra as fans around their edges, each fan one volume term (its m ≤ 4
  // tetrahedra's summed volume): fan f is the particles a, b, r_0 .. r_m at
  // fanParticles[fanOffsets[f] .. fanOffsets[f+1]), its tetrahedra (a, b, r_k, r_k+1) of positive
  // rest orientation; sorted by their count of particles. The forces and the stable step use the
  // fans; the projective solver's matrix the tetrahedra.
  std::vector<uint32_t> fanParticles;   ///< particle indices, m + 3 per fan of m tetrahedra
  std::vector<uint32_t> fanOffsets{0};  ///< fan count + 1 entries
  std::vector<uint32_t> fanBytes;       ///< fanParticles × sizeof(btVector3): the kernels' offsets
  std::vector<btScalar> fanInverseVolume;  ///< per fan: 1 / (6·V0) [1/m³]
  /// per fan: G0 = Σ over its particles of |∂(6V)/∂x_i|² at rest, capped for poorly shaped ones
  /// [m⁴]
  std::vector<btScalar> fanRestGradient;
  // Enclosed-volume term (VolumeForces.h): one pressure per muscle on the volume the interior
  // Delaunay tetrahedra (all of them, slivers too) enclose, through the faces of their boundary;
  // empty when enclosedModulus is 0.
  btScalar enclosedModulus = 0;  ///< bulk modulus K of the enclosed-volume term [Pa]; 0: none
  std::vector<uint32_t> enclosedFaces;  ///< 3 per boundary face, counter-clockwise from outside
  double enclosedRestVolume = 0;        ///< volume enclosedFaces enclose at rest [m³]

  std::vector<Spring> springs;  ///< contiguous, no duplicates, sorted by (a, b)
  SpringBlocks springBlocks;    ///< `springs` laid out for the AVX2 kernel (empty: not laid out)

  // Fibres: fibre f is particles fibreParticles[fibreOffsets[f] .. fibreOffsets[f+1]).
  std::vector<uint32_t> fibreParticles;   ///< particle indices in fibre order
  std::vector<uint32_t> fibreOffsets{0};  ///< fibreCount()+1 entries

  TriangleMesh restSurface;             ///< the muscle's surface at rest, for output
  int skinNeighbours = 3;               ///< particles per surface vertex (N closest)
  std::vector<uint32_t> skinParticles;  ///< restSurface.vertices.size() × skinNeighbours
  std::vector<btScalar> skinWeights;    ///< weights matching skinParticles (sum to 1 per vertex)

  size_t particleCount() const { return restPositions.size(); }
  size_t fibreCount() const { return fibreOffsets.size() - 1; }
  bool isFixed(uint32_t i) const { return flags[i] & kFixed; }
  bool isBoundary(uint32_t i) const { return flags[i] & kBoundary; }
  bool isTendon(uint32_t i) const { return flags[i] & kTendon; }
};

/// A prepared rigid bone; coordinates are those of the rest pose, which is the bone frame:
/// the bone's current world transform maps rest coordinates to current ones.
struct BoneSettings {
  std::string name;                      ///< bone name from the scene
  TriangleMesh mesh;                     ///< the true triangle mesh at rest
  std::vector<btVector3> sphereCentres;  ///< collision spheres, bone frame [m]
  std::vector<btScalar> sphereRadii;     ///< their radii [m]
};

}  // namespace fibremss
