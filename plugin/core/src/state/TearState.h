#pragma once
// What tearing keeps of a muscle (Tearing.h in dynamics/ breaks its springs and finds its
// pieces), a part of MuscleState.
#include <LinearMath/btVector3.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace fibremss {

struct MuscleSettings;

/// What tearing keeps of a muscle, sized when the muscle is added (empty when it does not tear).
struct TearState {
  /// The muscle's own copy of its settings, whose springs and volume terms break (null: the muscle
  /// does not tear; MuscleState::settings then is the shared one).
  std::shared_ptr<MuscleSettings> torn;
  /// The muscle's settings before anything broke (restores a spring a tear must not break).
  std::shared_ptr<const MuscleSettings> intact;
  /// The springs the last tearing pass broke, in order (sized for all; the pass counts them).
  std::vector<uint32_t> passBroken;
  /// Per piece root: whether the piece holds a fixed particle (1) or not (0).
  std::vector<uint8_t> pieceHeld;
  /// Per spring: its lane in torn->springBlocks (empty when the springs are not laid out).
  std::vector<uint32_t> springLanes;
  /// Per particle: its union-find parent, after counting the root of its piece.
  std::vector<uint32_t> pieceOf;
  /// Per particle: its unbroken springs (never 0 for one that had a spring: its last one holds;
  /// a fixed particle whose springs all linked fixed ones has none and is no piece).
  std::vector<uint32_t> springCounts;
  std::vector<btVector3> pieceLower;  ///< per piece root: lower corner of its particles' box [m]
  std::vector<btVector3> pieceUpper;  ///< per piece root: upper corner of its particles' box [m]
  std::vector<btVector3> restLower;   ///< per piece root: lower corner at rest [m]
  std::vector<btVector3> restUpper;   ///< per piece root: upper corner at rest [m]
  size_t brokenSprings = 0;           ///< springs broken so far
  size_t brokenVolumeTerms = 0;       ///< local volume terms (fans) broken so far
  size_t cutSprings = 0;              ///< springs blades cut so far (Cutting.h)
                          /// Pieces: components of the unbroken springs among the particles
                          /// that had a spring at rest.
  size_t pieces = 1;
};

}  // namespace fibremss
