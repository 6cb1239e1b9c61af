// `fibremss scenes`: list the built-in scenes; `--export NAME` prints one as complete JSON.
#include <algorithm>
#include <iostream>
#include <memory>

#include "Commands.h"
#include "fibremss/Scene.h"

namespace fibremss::cli {
namespace {

struct ScenesArgs {
  std::string exportName;              ///< scene to print as JSON ("" lists the scenes)
  std::vector<std::string> overrides;  ///< --set key=value applied before exporting
};

}  // namespace

void addScenesCommand(CLI::App& app) {
  auto args = std::make_shared<ScenesArgs>();
  auto* command = app.add_subcommand(
      "scenes", "List the built-in scenes, or print one as JSON (--export NAME) to start from");
  command->add_option("--export", args->exportName,
                      "Print this scene (built-in name or .json file) as JSON, every default "
                      "filled in");
  command
      ->add_option("--set", args->overrides,
                   "With --export: override a parameter first, e.g. --set resolution=80")
      ->allow_extra_args(false);
  command->callback([args] {
    if (!args->exportName.empty()) {
      std::cout << loadScene(args->exportName, args->overrides).json << "\n";
      return;
    }
    if (!args->overrides.empty())
      throw CLI::ValidationError("--set", "only applies together with --export NAME");
    const auto scenes = builtInScenes();
    size_t width = 0;
    for (const auto& scene : scenes) width = std::max(width, scene.name.size());
    for (const auto& scene : scenes)
      std::cout << scene.name << std::string(width + 2 - scene.name.size(), ' ')
                << scene.description << "\n";
  });
}

}  // namespace fibremss::cli
