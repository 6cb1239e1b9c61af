// libFuzzer target: the OpenSim motion reader (.mot / .sto header, column names, rows of
// numbers) on arbitrary bytes, through a scene whose bone follows it, splitting its jumps.
#include <cstdint>
#include <string_view>

#include "FuzzInputs.h"
#include "fibremss/Error.h"
#include "fibremss/Scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fibremss;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  const auto motion = fuzz::writeScratchFile("motion.mot", bytes);
  const auto scene =
      fuzz::writeScratchFile("motion-scene.json", fuzz::motionSceneJson(motion.string()));
  try {
    loadScene(scene.string());
  } catch (const InputError&) {
  }
  return 0;
}
