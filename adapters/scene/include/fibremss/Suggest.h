#pragma once
// "Did you mean ...?" for a mistyped name: a scene, a --set key, a subcommand, a field.
#include <string>
#include <vector>

namespace fibremss {

/// The candidate closest to `word` in edits (insertions, deletions, substitutions and swaps of
/// two neighbours, case ignored), when it is near enough to be a typo: at most 2 edits, and
/// fewer than half of the word's letters. Empty when none is.
std::string closestName(const std::string& word, const std::vector<std::string>& candidates);

/// "; did you mean 'X'?" for the closest candidate, empty when there is none.
std::string didYouMean(const std::string& word, const std::vector<std::string>& candidates);

}  // namespace fibremss
