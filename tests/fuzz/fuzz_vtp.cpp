// libFuzzer target: the VTK XML PolyData (.vtp) reader on arbitrary bytes (ascii, base64,
// zlib blocks, appended data), then the surface checks and fibre chaining on what it accepted.
#include <cstdint>
#include <string_view>

#include "MeshIOInternal.h"
#include "fibremss/Error.h"
#include "fibremss/MeshIO.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fibremss;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  try {
    meshio::VtkPolyData poly = meshio::readVtkXmlPolyData("fuzz.vtp", bytes, 1.0);
    for (const auto& t : poly.triangles)
      for (uint32_t v : t)
        if (v >= poly.points.size()) __builtin_trap();  // every index checked by the reader
    if (!poly.triangles.empty())
      checkSurface(TriangleMesh{poly.points, poly.triangles}, "fuzz.vtp");
    if (poly.lines.size() > 0)
      meshio::validateFibres(meshio::chainPolylines("fuzz.vtp", poly.points, poly.lines),
                             "fuzz.vtp");
  } catch (const InputError&) {
  }
  return 0;
}
