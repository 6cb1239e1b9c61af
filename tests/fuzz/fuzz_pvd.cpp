// libFuzzer target: the ParaView collection reader (a run's run.pvd, as `view` reads it) on
// arbitrary bytes.
#include <cstdint>
#include <string_view>

#include "FuzzInputs.h"
#include "fibremss/Error.h"
#include "fibremss/VtkFiles.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fibremss;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  try {
    for (const PvdDataSet& set : readPvd(fuzz::writeScratchFile("run.pvd", bytes).string()))
      if (set.file.empty()) __builtin_trap();  // every data set names its file
  } catch (const InputError&) {
  }
  return 0;
}
