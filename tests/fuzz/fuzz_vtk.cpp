// libFuzzer target: the legacy VTK reader (ASCII and BINARY) on arbitrary bytes, then the
// surface checks, orientation and fibre chaining on whatever it accepted.
#include <cstdint>
#include <string_view>

#include "MeshIOInternal.h"
#include "fibremss/Error.h"
#include "fibremss/MeshIO.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fibremss;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  try {
    meshio::VtkPolyData poly = meshio::readLegacyVtk("fuzz.vtk", bytes, 1.0);
    if (!poly.triangles.empty()) {
      TriangleMesh mesh{poly.points, poly.triangles};
      checkSurface(mesh, "fuzz.vtk");
      size_t nonOrientable = 0;
      meshio::orientConsistently(mesh, nonOrientable);
      const MeshReport after = checkSurface(mesh, "fuzz.vtk");
      // After orientation a manifold, orientable surface has no edge run twice the same way.
      if (nonOrientable == 0 && after.nonManifoldEdges == 0 && after.inconsistentEdges != 0)
        __builtin_trap();
    }
    if (poly.lines.size() > 0)
      meshio::validateFibres(meshio::chainPolylines("fuzz.vtk", poly.points, poly.lines),
                             "fuzz.vtk");
  } catch (const InputError&) {
  }
  return 0;
}
