// libFuzzer target: the OBJ fibre reader (`v` and `l` statements), chaining and validation.
#include <cstdint>
#include <string_view>

#include "MeshIOInternal.h"
#include "fibremss/Error.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fibremss;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  try {
    const meshio::ObjPolylines obj = meshio::readObjPolylines("fuzz.obj", bytes, 1.0);
    const FibreSet fibres = meshio::chainPolylines("fuzz.obj", obj.points, obj.lines);
    meshio::validateFibres(fibres, "fuzz.obj");
    // Every accepted fibre has at least two points inside the point array.
    for (size_t i = 0; i < fibres.fibreCount(); ++i)
      if (fibres.fibre(i).size() < 2 || fibres.offsets[i + 1] > fibres.points.size())
        __builtin_trap();
  } catch (const InputError&) {
  }
  return 0;
}
