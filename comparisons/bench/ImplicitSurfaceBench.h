#pragma once
// The implicit surface's report (ImplicitSurfaceBench.cpp).

namespace fibremss::bench {

/// thigh13 at `resolution`: each muscle's implicit surface at rest against its skinned surface,
/// and the extraction's wall time per frame on 1 and 2 threads over `rounds` alternated rounds.
int implicitSurfaceReport(int resolution, int rounds);

}  // namespace fibremss::bench
