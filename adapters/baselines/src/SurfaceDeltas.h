#pragma once
// A shipped gate's surfaces as differences from surfaces its reader already has: its
// reference's (whole, or one muscle's part of each) and its own earlier ones. A gate moves its
// reference by tenths of a millimetre, so the differences take a byte or two where a float takes
// four that gzip barely compresses.
#include <cstdint>
#include <deque>
#include <istream>
#include <ostream>
#include <string>
#include <vector>

#include "fibremss/ReferenceCache.h"

namespace fibremss {

/// Writes and reads surfaces, each after the last: a surface is stored as the difference from
/// the base surface of its vertex count that it is nearest to (every surface the codec was made
/// with or has written or read since, and each muscle's part of those that hold every muscle;
/// none: from the origin), coordinate by coordinate, each as the change from the vertex before's
/// (neighbours in a muscle's surface move alike), in zig-zag varints: in float ulps (exact,
/// as the floats of a shipped reference) where every one lies within a quantum of its base (so
/// that a solve that moves its reference by less, as increments halved, keeps its figure), else
/// in quanta of kShippedGateQuantum (within half a quantum and a float's rounding). Read
/// back, every coordinate is a float. A writer and a reader made with the same base surfaces
/// and muscle vertex counts stay in step.
class SurfaceDeltas {
 public:
  /// `base`: its pose, return and muscles' step surfaces; `muscleVertices`: each muscle's
  /// vertex count (a surface of their sum is also cut into muscles' parts).
  SurfaceDeltas(const CalculixSolution& base, std::vector<uint64_t> muscleVertices);

  void write(std::ostream& out, const std::vector<btVector3>& points);
  /// Throws InputError naming `path` when the stream is not what write wrote.
  std::vector<btVector3> read(std::istream& in, const std::string& path);

 private:
  struct Span {
    const btVector3* points;
    size_t size;
  };
  /// Keeps `surface` (as read back) as a base for the surfaces after it.
  void remember(std::vector<btVector3> surface);
  /// The index+1 in bases_ of the base of `target`'s size nearest to it in quanta; 0: none.
  uint32_t nearestBase(const std::vector<float>& target) const;
  const btVector3* basePoints(uint32_t base, size_t size, const std::string& path) const;

  std::vector<uint64_t> muscleVertices_;
  std::deque<std::vector<btVector3>> kept_;  // a deque: spans into it stay valid
  std::vector<Span> bases_;
};

}  // namespace fibremss
