// libFuzzer target: the checks every surface goes through after assimp or the VTK reader
// (checkSurface, orientConsistently, checkFibres) on meshes built from arbitrary bytes.
#include <cstdint>
#include <string_view>

#include "FuzzInputs.h"
#include "MeshIOInternal.h"
#include "fibremss/Error.h"
#include "fibremss/MeshIO.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fibremss;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  TriangleMesh mesh = fuzz::meshFromBytes(bytes);
  try {
    checkSurface(mesh, "fuzz");
    size_t nonOrientable = 0;
    meshio::orientConsistently(mesh, nonOrientable);
    const MeshReport after = checkSurface(mesh, "fuzz");
    if (nonOrientable == 0 && after.nonManifoldEdges == 0 && after.inconsistentEdges != 0)
      __builtin_trap();
    // Fibres through the first vertices, checked against the surface they came with.
    FibreSet fibres;
    if (mesh.vertices.size() >= 2) fibres.addFibre({mesh.vertices.data(), 2});
    checkFibres(fibres, mesh, "fuzz", 1e-3);
  } catch (const InputError&) {
  }
  return 0;
}
