#pragma once
// The implicit surface's report (ImplicitSurfaceBench.cpp).

namespace fibremss::bench {

/// thigh13 at `resolution`: each muscle's implicit surface at rest against its skinned surface,
/// and the extraction's wall and CPU time per frame on 1 and 2 threads over `rounds` alternated
/// rounds; then the same after stepping through the first poses, with each pose's frame.
int implicitSurfaceReport(int resolution, int rounds);

}  // namespace fibremss::bench
