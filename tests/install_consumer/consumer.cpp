// Links the installed library and prepares a two-fibre muscle: proof that headers, library
// and package configuration are complete.
#include <fibremss/Geometry.h>
#include <fibremss/Parameters.h>

#include <cstdio>

int main() {
  fibremss::TriangleMesh tetra;
  tetra.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  tetra.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  const btScalar volume = fibremss::meshVolume(tetra);
  std::printf("volume %g layout %s\n", double(volume),
              fibremss::toString(fibremss::SpringLayout::NearestNeighbours));
  return volume > btScalar(0.16) && volume < btScalar(0.17) ? 0 : 1;
}
