#pragma once
// The scene keys that set how a step's iterations run and stop rather than the model they solve.
#include <string>
#include <vector>

namespace fibremss {

/// The keys of the "simulation" and "model" sections (as `--set` takes them without a path) that
/// set how a step's iterations run and stop rather than the model they solve: a run differing
/// from the scene only in these solves the scene's own model.
const std::vector<std::string>& solverSettings();

}  // namespace fibremss
