// The embedding example (scenes/example/embed.cpp) builds a Bullet world with a FibreMSS
// muscle, kinematic bones, a btSoftBody and a rigid ball thrown at the muscle, steps it and exits
// cleanly.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <regex>
#include <string>
#include <vector>

#include "support/Process.h"

namespace fibremss {
namespace {

/// The example is built next to the fibremss tool (build/bin).
std::filesystem::path examplePath() {
  return std::filesystem::path(FIBREMSS_CLI).parent_path() / "fibremss_embed_example";
}

TEST(EmbedExample, StepsAWorldWithMuscleBonesAndSoftBody) {
  const auto example = examplePath();
  ASSERT_TRUE(std::filesystem::exists(example))
      << example << " is missing: build the target fibremss_embed_example";
  const auto result = testing::runProcess(example.string() + " 6");
  ASSERT_EQ(result.exitCode, 0) << result.output;

  const std::regex line(
      R"(step +(\d+): muscle centre \((\S+) (\S+) (\S+)\) m, (\d+) iterations, \d+ contacts, \S+ ms; soft ball centre y (\S+) m; rigid ball z (\S+) m, (\d+) muscle contacts)");
  std::vector<double> rigidBall;
  size_t touched = 0;
  std::vector<double> ballHeights;
  std::vector<std::array<double, 3>> muscleCentres;
  int expectedStep = 0;
  for (auto it = std::sregex_iterator(result.output.begin(), result.output.end(), line);
       it != std::sregex_iterator(); ++it, ++expectedStep) {
    const std::smatch& m = *it;
    EXPECT_EQ(std::stoi(m[1]), expectedStep);
    for (int c = 2; c <= 4; ++c) EXPECT_TRUE(std::isfinite(std::stod(m[c]))) << m[0];
    muscleCentres.push_back({std::stod(m[2]), std::stod(m[3]), std::stod(m[4])});
    EXPECT_GT(std::stoi(m[5]), 0);
    ballHeights.push_back(std::stod(m[6]));
    rigidBall.push_back(std::stod(m[7]));
    touched += std::stoul(m[8]);
  }
  ASSERT_EQ(ballHeights.size(), 6u) << result.output;
  EXPECT_LT(ballHeights.back(), ballHeights.front());  // the soft ball falls under gravity
  // The moving bone drags the muscle along (the centre is printed to 0.1 mm).
  const auto& first = muscleCentres.front();
  const auto& last = muscleCentres.back();
  EXPECT_GT(std::hypot(last[0] - first[0], last[1] - first[1], last[2] - first[2]), 5e-4);
  // The rigid ball thrown at the muscle (+z) hit it and bounced back (two-way contact).
  EXPECT_GT(touched, 0u);
  EXPECT_LT(rigidBall.back(), *std::max_element(rigidBall.begin(), rigidBall.end()));
}

}  // namespace
}  // namespace fibremss
