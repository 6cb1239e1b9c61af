#pragma once
// The arguments every scene-taking subcommand shares: SCENE, repeated --set key=value and
// --threads N (short for --set threads=N).
#include <CLI/CLI.hpp>
#include <string>
#include <vector>

namespace fibremss::cli {

struct SceneArgs {
  std::string scene;                   ///< built-in scene name or .json path
  std::vector<std::string> overrides;  ///< key=value overrides, in order
};

inline void addSceneArgs(CLI::App& command, SceneArgs& args) {
  command
      .add_option("scene", args.scene, "Built-in scene name (see `fibremss scenes`) or .json file")
      ->required();
  command
      .add_option("--set", args.overrides,
                  "Override a scene parameter, e.g. --set resolution=40 (repeatable)")
      ->allow_extra_args(false);
  command.add_option_function<int>(
      "--threads",
      [&args](int threads) { args.overrides.push_back("threads=" + std::to_string(threads)); },
      "Solver threads, the caller included (0: the machine's hardware threads); "
      "short for --set threads=N");
}

}  // namespace fibremss::cli
