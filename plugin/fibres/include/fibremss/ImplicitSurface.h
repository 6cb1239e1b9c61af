#pragma once
// A muscle's surface as the iso-surface of its particles' field: it follows tears and cuts
// without a rebuild, where the skinned surface (each vertex bound to its nearest particles)
// cannot open. Field at a point x, over the particles j within the kernel radius h:
//   w_j = (1 − |x − p_j|² / h²)³,  X_j = P_j + F_j⁻¹ (x − p_j)   (x mapped back to rest by j)
//   f(x) = min( D(X̄) − λ·σ,  h·(W / κ − 1) ) − dents
// X̄ the w-weighted mean of the X_j and σ their spread, W = Σ w_j, D the signed distance to the
// rest surface (positive inside), F_j the deformation of particle j's springs (as the skin's),
// κ half the smallest W on the rest surface, λ 0 while no spring of the muscle is broken. At rest
// every X_j is x, so the surface is the rest surface; where particles part (a tear, a cut) their
// rest positions disagree (σ) and the particles' cover thins (W), and the surface opens; where
// they only deform, σ is the error of their affine maps, which opens nothing. Extracted by
// marching tetrahedra on a sparse grid, from seeds beside the boundary particles across every
// cell face the surface crosses: a closed surface (every edge shared by two triangles), less the
// pieces but the largest that enclose under two grid cells (beads of a part thinner than a cell).
// The sums over the particles (X̄, σ, W) are taken at every second grid point and interpolated
// between them (X̄ exactly where the particles share one affine map back to rest, as at rest); D
// at every grid point. h is widened where the rest surface reaches farther from the particles
// (coverMargin), so that W > 0 on all of it. Beside the fixed particles, where the tendons end in
// points thinner than a cell, D is thickened (tipThickening) so that the grid's points meet them,
// and each vertex made there is moved onto the rest surface (its rest point's nearest rest
// surface point, mapped back to now through the derivative of the interpolated map); so are
// the vertices where the surface extracted at rest erred (snapTolerance). The rest surface's
// vertices that the surface so extracted at rest still misses (pits, which no vertex moved to its
// nearest rest surface point reaches) are anchors: each takes the moved vertex whose rest point
// lies nearest it (within a cell), mapped back to now likewise.
#include <LinearMath/btMatrix3x3.h>
#include <LinearMath/btVector3.h>

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "fibremss/Geometry.h"
#include "fibremss/MuscleSettings.h"
#include "fibremss/TaskPool.h"

namespace fibremss {

/// How an implicit surface is sampled.
struct ImplicitSurfaceSettings {
  /// Grid spacing [m]; 0: the muscle's median spring rest length times voxelFactor.
  btScalar voxel = 0;
  btScalar voxelFactor = btScalar(0.5);  ///< voxel per median spring rest length [1]
  /// The rest distance grid's spacing per voxel [1]: finer than the extraction grid, as a
  /// muscle thinner than a few of its cells loses its distance between them.
  btScalar restVoxelRatio = btScalar(0.5);
  btScalar kernelFactor = btScalar(2);  ///< h per median spring rest length [1]
  /// h at least this times the rest surface's largest distance to its nearest rest particle, so
  /// that the particles cover the whole rest surface (W > 0 on it) [1]; 0: kernelFactor alone.
  btScalar coverMargin = btScalar(1.2);
  /// The rest surface thickened by this many grid spacings beside the attachments' fixed
  /// particles, so that the grid's points meet the tendons' pointed ends (thinner than a cell);
  /// the vertices made there are moved back onto the rest surface [1]. 0: none.
  btScalar tipThickening = btScalar(0.75);
  /// How far from a fixed particle the thickening is whole, then fades out over as far again
  /// [grid spacings].
  btScalar tipReach = 1;
  /// Where the surface extracted at rest lies farther than this many grid spacings from the
  /// rest surface, its vertices are moved onto it as at the tips, and the rest surface's vertices
  /// it then still misses by more are anchors, each pinning its nearest moved vertex [1]; 0: only
  /// at the tips, no anchors.
  btScalar snapTolerance = btScalar(0.25);
  /// λ: how much the X_j's spread opens the surface of a muscle with broken springs [1]
  btScalar spreadWeight = btScalar(2);
};

/// A local negative field, such as a tool pressing on the surface: the field drops by
/// depth·(1 − |x − centre|² / radius²)³ within radius of the centre.
struct SurfaceDent {
  btVector3 centre{0, 0, 0};  ///< [m]
  btScalar radius = 0;        ///< [m]
  btScalar depth = 0;         ///< the drop at the centre [m]
};

/// One muscle's implicit surface: prepared once from its rest state, extracted from its
/// particles on demand. Not thread-safe per object; different objects extract concurrently.
class ImplicitSurface {
 public:
  explicit ImplicitSurface(std::shared_ptr<const MuscleSettings> muscle,
                           const ImplicitSurfaceSettings& settings = {});
  ~ImplicitSurface();
  ImplicitSurface(ImplicitSurface&&) noexcept;
  ImplicitSurface& operator=(ImplicitSurface&&) noexcept;

  /// The surface of the particles at `positions` (one per particle of the muscle) [m], into
  /// mesh(): triangles counter-clockwise seen from outside. `springs`: the muscle's springs as
  /// they stand (MuscleSystem::settings, where a broken one has a = b); empty: the rest settings'.
  void extract(std::span<const btVector3> positions, std::span<const Spring> springs = {});
  /// The last extract()'s surface.
  const TriangleMesh& mesh() const;
  /// Per vertex of mesh(): the particle nearest to it among those within the kernel radius.
  std::vector<uint32_t> nearestParticles() const;
  /// The dents the next extract() applies (replacing earlier ones).
  void setDents(std::span<const SurfaceDent> dents);
  btScalar voxel() const;         ///< grid spacing [m]
  btScalar kernelRadius() const;  ///< h [m]

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// The order extractSurfaces hands the surfaces out in: largest first, by the triangles of each
/// surface's last mesh, then by its particles (before a first extraction, by particles alone),
/// so that the threads finish close together; ties in the given order.
std::vector<size_t> extractionOrder(std::span<ImplicitSurface* const> surfaces,
                                    std::span<const std::span<const btVector3>> positions);

/// extract() of every surface, surfaces[i] from positions[i] and springs[i], as tasks of
/// `pool` (its own threads or the host's scheduler it was made with), in extractionOrder; each
/// surface one task, so the result is the same for any thread count. The surfaces must be
/// distinct objects (a surface's state is its task's alone): InputError otherwise, or when
/// the spans' sizes differ.
void extractSurfaces(std::span<ImplicitSurface* const> surfaces,
                     std::span<const std::span<const btVector3>> positions,
                     std::span<const std::span<const Spring>> springs, TaskPool& pool);

/// The edges of `mesh` not shared by exactly two triangles, and its connected components
/// (triangles joined by an edge).
struct MeshTopology {
  size_t openEdges = 0;   ///< edges with one triangle or more than two
  size_t components = 0;  ///< connected pieces
};
MeshTopology meshTopology(const TriangleMesh& mesh);

}  // namespace fibremss
