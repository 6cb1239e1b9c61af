// libFuzzer target: the scene loader (JSON parse, fields, defaults, generators, motions) on
// arbitrary bytes written to a scene file next to the scene test meshes.
#include <cstdint>
#include <filesystem>
#include <string_view>

#include "FuzzInputs.h"
#include "fibremss/Error.h"
#include "fibremss/Scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fibremss;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  const std::filesystem::path scene = fuzz::writeScratchScene(bytes, FIBREMSS_SCENE_MESHES);
  try {
    loadScene(scene.string());
  } catch (const InputError&) {
  }
  return 0;
}
