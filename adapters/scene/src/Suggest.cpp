#include "fibremss/Suggest.h"

#include <algorithm>
#include <cctype>

namespace fibremss {
namespace {

/// Optimal string alignment distance between `a` and `b`, case ignored.
size_t editDistance(const std::string& a, const std::string& b) {
  const auto same = [](char x, char y) {
    return std::tolower(static_cast<unsigned char>(x)) ==
           std::tolower(static_cast<unsigned char>(y));
  };
  const size_t columns = b.size() + 1;
  std::vector<size_t> d((a.size() + 1) * columns);
  for (size_t i = 0; i <= a.size(); ++i) d[i * columns] = i;
  for (size_t j = 0; j <= b.size(); ++j) d[j] = j;
  for (size_t i = 1; i <= a.size(); ++i)
    for (size_t j = 1; j <= b.size(); ++j) {
      size_t& cell = d[i * columns + j];
      cell = std::min({d[(i - 1) * columns + j] + 1, d[i * columns + j - 1] + 1,
                       d[(i - 1) * columns + j - 1] + (same(a[i - 1], b[j - 1]) ? 0 : 1)});
      if (i > 1 && j > 1 && same(a[i - 1], b[j - 2]) && same(a[i - 2], b[j - 1]))
        cell = std::min(cell, d[(i - 2) * columns + j - 2] + 1);
    }
  return d.back();
}

}  // namespace

std::string closestName(const std::string& word, const std::vector<std::string>& candidates) {
  if (word.empty()) return {};
  const size_t limit = std::min<size_t>(2, (word.size() - 1) / 2);
  std::string best;
  size_t bestDistance = limit + 1;
  for (const std::string& candidate : candidates) {
    const size_t distance = editDistance(word, candidate);
    if (distance < bestDistance) best = candidate, bestDistance = distance;
  }
  return best;
}

std::string didYouMean(const std::string& word, const std::vector<std::string>& candidates) {
  const std::string closest = closestName(word, candidates);
  return closest.empty() ? std::string() : "; did you mean '" + closest + "'?";
}

}  // namespace fibremss
