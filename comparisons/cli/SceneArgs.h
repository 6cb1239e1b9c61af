#pragma once
// The arguments every scene-taking subcommand shares: SCENE and repeated --set key=value.
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
}

}  // namespace fibremss::cli
