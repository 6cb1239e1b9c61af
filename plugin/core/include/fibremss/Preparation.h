#pragma once
// Preparation (method.md §2, §3, §6): from bone meshes, muscle surfaces and fibres to the
// particles, springs, radii, bone spheres and fixed particles a simulation starts from.
#include <memory>
#include <string>
#include <vector>

#include "fibremss/Geometry.h"
#include "fibremss/MuscleSettings.h"
#include "fibremss/Parameters.h"
#include "fibremss/TaskScheduler.h"

namespace fibremss {

/// A bone as given: its closed mesh in the rest pose.
struct BoneInput {
  std::string name;              ///< unique name
  TriangleMesh mesh;             ///< rest-pose mesh [m]
  BoneSphereParameters spheres;  ///< sphere generation settings
};

/// An attachment area a muscle declares (its origin or insertion): particles of the area are
/// fixed, each to the nearest of the area's bones. A particle belongs to the area when it lies
/// within the muscle's attachment distance of one of those bones and no more than that distance
/// farther from the area's surface vertices than from the surface (the area is where it meets
/// the surface).
struct DeclaredAttachment {
  std::string name;                       ///< "origin" or "insertion", for messages
  std::vector<uint32_t> surfaceVertices;  ///< the area: indices into the muscle's surface
  std::vector<uint32_t> bones;            ///< indices of the bones its particles are fixed to
};

/// A muscle as given: its surface and fibres in the rest pose.
struct MuscleInput {
  std::string name;              ///< unique name
  TriangleMesh surface;          ///< closed surface [m]
  FibreSet fibres;               ///< polylines from attachment to attachment [m]
  MuscleParameters parameters;   ///< resolution, attachment distance, springs
  int fibreGridColumns = 0;      ///< > 0: fibres form a row-major grid with this many columns
                                 ///< (needed by the lattice layouts)
  bool mergeConverging = false;  ///< merge near-coincident particles of different fibres
                                 ///< (fibres generated from a surface converge into tendons)
  /// Declared attachments (origin, insertion): only their particles are fixed, every other
  /// particle is free and meets bones through collision. Empty: every particle within the
  /// attachment distance of a bone is fixed to the nearest bone.
  std::vector<DeclaredAttachment> attachments;
};

/// What preparation found and changed in one muscle; printed by `fibremss check`.
struct MusclePreparationReport {
  size_t sampledParticles = 0;  ///< fibres × resolution, before merging
  size_t mergedParticles = 0;   ///< particles merged into a near-coincident one of another fibre
  btScalar mergeDistance = 0;   ///< particles of different fibres closer than this merge [m]
  btScalar shortestSpring = 0;  ///< shortest spring rest length after preparation [m]
  size_t tendonParticles = 0;   ///< free particles in a tendon (MuscleParameters::tendonFraction)
  size_t tendonSprings = 0;     ///< springs stiffened as tendon (tendonStiffness times)
  /// Fibres that end within the attachment distance of a bone but whose last particle is free:
  /// it lies up to one sample spacing before the fibre's end (method.md), held by neighbours.
  size_t looseFibreEnds = 0;
  /// Per earlier muscle: particles that lay inside its surface at rest, moved out along its
  /// normal (the earlier muscle keeps the overlap; seed 001 §4.1).
  std::vector<size_t> pushedOutOfMuscles;
  /// Per bone: free particles inside it at rest, moved out along its normal to a quarter of the
  /// sample spacing beyond its surface: all of them, except those within the attachment
  /// distance of a bone that fixes them (the nearest bone, or the bone of a declared area the
  /// particle lies in).
  std::vector<size_t> pushedOutOfBones;
  std::vector<btScalar>
      pushedOutOfBonesDepth;  ///< per bone: the deepest of those lay this deep [m]
  /// Per bone: surface vertices inside it at rest, moved out along its normal.
  std::vector<size_t> surfaceVerticesPushedOut;
};

/// What preparation measured and decided; printed by `fibremss check`.
struct PreparationReport {
  double seconds = 0;                 ///< wall time of the whole preparation
  std::vector<std::string> warnings;  ///< things a user should know (a bad mesh, ...)
  std::vector<std::string> repairs;   ///< what preparation changed, one sentence each
  /// Per muscle: fraction of surface vertices inside some particle sphere (0..1).
  std::vector<double> surfaceCoverage;
  std::vector<MusclePreparationReport> muscles;  ///< per muscle, same order as the inputs
};

/// Everything a simulation needs, immutable once made.
struct PreparedScene {
  std::vector<std::shared_ptr<const BoneSettings>> bones;      ///< same order as the inputs
  std::vector<std::shared_ptr<const MuscleSettings>> muscles;  ///< same order as the inputs
  PreparationReport report;
};

/// Rough upper estimate of the memory prepareScene() needs for these inputs [bytes]
/// (particles = fibres × resolution, their springs, the meshes' trees and copies).
size_t estimatePreparationBytes(const std::vector<BoneInput>& bones,
                                const std::vector<MuscleInput>& muscles);

/// The limit prepareScene() checks the estimate against [bytes]: the environment variable
/// FIBREMSS_MEMORY_LIMIT_MB when set, else the machine's available memory (/proc/meminfo).
size_t preparationMemoryLimit();

/// Throws InputError with the estimate when estimatePreparationBytes() exceeds the limit.
void requirePreparationMemory(const std::vector<BoneInput>& bones,
                              const std::vector<MuscleInput>& muscles);

/// Prepares all bodies together (radii shrink needs all of them). `seed` makes the fibre
/// jitter and sphere thinning reproducible. `threads` counts the caller, as
/// MuscleSystemDef::threads (0: the machine's hardware threads); the result is the same
/// for any count. Throws InputError for unusable input.
PreparedScene prepareScene(const std::vector<BoneInput>& bones,
                           const std::vector<MuscleInput>& muscles, uint32_t seed, int threads = 0);

/// prepareScene with its tasks run by the host's scheduler when `scheduler` is present (else on
/// `threads` threads): MuscleSystemDef::scheduler for preparation. The same result.
PreparedScene prepareScene(const std::vector<BoneInput>& bones,
                           const std::vector<MuscleInput>& muscles, uint32_t seed, int threads,
                           const TaskScheduler& scheduler);

}  // namespace fibremss
