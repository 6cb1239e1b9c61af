#pragma once
// Checks that two runs of a muscle that tears or is cut (one thread and two) broke the same and
// left the same bits.
#include <gtest/gtest.h>

#include <cstring>
#include <vector>

#include "fibremss/MuscleSystem.h"

namespace fibremss::testing {

/// Expects the same counts in `one` and `two`, and the same bits in their particles [m].
inline void expectSameTear(const MuscleTear& one, const MuscleTear& two,
                           const std::vector<btVector3>& onePositions,
                           const std::vector<btVector3>& twoPositions) {
  EXPECT_EQ(one.brokenSprings, two.brokenSprings);
  EXPECT_EQ(one.cutSprings, two.cutSprings);
  EXPECT_EQ(one.brokenVolumeTerms, two.brokenVolumeTerms);
  EXPECT_EQ(one.pieces, two.pieces);
  ASSERT_EQ(onePositions.size(), twoPositions.size());
  EXPECT_EQ(std::memcmp(onePositions.data(), twoPositions.data(),
                        onePositions.size() * sizeof(btVector3)),
            0);
}

}  // namespace fibremss::testing
