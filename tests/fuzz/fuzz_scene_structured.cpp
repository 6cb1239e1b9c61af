// libFuzzer target, structure-aware: bytes drive a writer of scene JSON (FuzzInputs.h
// sceneJsonFromBytes: scene field names as keys, the scene's words, numbers up to 1e±508,
// nesting as deep as the input is long), loaded as a scene file next to the scene test meshes
// and, as --set overrides, on top of a built-in scene. Either loads or fails with InputError.
#include <cstdint>
#include <filesystem>
#include <string_view>

#include "FuzzInputs.h"
#include "fibremss/Error.h"
#include "fibremss/Scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fibremss;
  const std::string json =
      fuzz::sceneJsonFromBytes(std::string_view(reinterpret_cast<const char*>(data), size));
  const std::filesystem::path scene = fuzz::writeScratchScene(json, FIBREMSS_SCENE_MESHES);
  try {
    loadScene(scene.string());
  } catch (const InputError&) {
  }
  try {
    loadScene("fusiform", {"model=" + json, "muscles.0=" + json});
  } catch (const InputError&) {
  }
  return 0;
}
