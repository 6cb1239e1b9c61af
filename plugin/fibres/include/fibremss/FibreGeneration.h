#pragma once
// Fibres from a closed muscle surface and its attachment areas: a harmonic field
// inside the muscle (Laplace on a voxel grid, 0 at the origin area, 1 at the insertion area),
// streamlines of its gradient traced from seeds spread over the origin area, resampled.
#include <cstdint>
#include <string>
#include <vector>

#include "fibremss/Geometry.h"

namespace fibremss {

/// Where a muscle attaches: surface vertices near a bone, near landmark points, given by index,
/// or (when none is given) the muscle's extreme end along its main axis away from the other
/// area.
struct AttachmentArea {
  enum class Kind { Bone, Landmarks, Vertices, FarEnd };
  Kind kind = Kind::FarEnd;
  const TriangleMesh* bone = nullptr;   ///< Kind::Bone: the bone mesh (same frame, metres)
  btScalar distance = btScalar(0.004);  ///< Kind::Bone: vertices within this of the bone [m]
  std::vector<btVector3> landmarks;     ///< Kind::Landmarks: points [m]
  btScalar radius = btScalar(0.01);     ///< Kind::Landmarks: vertices within this of a point [m]
  std::vector<uint32_t> vertices;       ///< Kind::Vertices: surface vertex indices
  double endFraction = 0.06;  ///< Kind::FarEnd: the end's depth as a fraction of the length
  btScalar endDepth = 0;      ///< Kind::FarEnd: the end's depth [m] (> 0: used instead of
                              ///< endFraction)

  static AttachmentArea fromBone(const TriangleMesh& mesh, btScalar distance) {
    AttachmentArea area;
    area.kind = Kind::Bone;
    area.bone = &mesh;
    area.distance = distance;
    return area;
  }
  static AttachmentArea fromVertices(std::vector<uint32_t> indices) {
    AttachmentArea area;
    area.kind = Kind::Vertices;
    area.vertices = std::move(indices);
    return area;
  }
  static AttachmentArea fromLandmarks(std::vector<btVector3> points, btScalar radius) {
    AttachmentArea area;
    area.kind = Kind::Landmarks;
    area.landmarks = std::move(points);
    area.radius = radius;
    return area;
  }
};

struct FibreGenerationOptions {
  int count = 64;     ///< fibres wanted
  int samples = 64;   ///< points per fibre (arc-length resampled)
  int grid = 48;      ///< voxels along the longest side of the muscle's bounding box (first try)
  int maxGrid = 192;  ///< when the areas do not connect or too few fibres arrive, the grid is
                      ///< raised 1.5 times at a time up to this
  double minShare = 0.9;  ///< fewer fibres than this share of `count` is an InputError
  btScalar coverageDistance = btScalar(0.005);  ///< quality: voxels within this of a fibre [m]
  btScalar crossingTolerance = btScalar(5e-4);  ///< quality: segments closer than this cross [m]
  btScalar minSeparation = btScalar(1e-3);      ///< fibres closer than this to an earlier one are
                                                ///< used only when seeds run out [m] (0: off)
  /// Seeds spread over the muscle's widest cross-section (a level set of the field), each
  /// traced back to the origin and on to the insertion; false: over the origin area.
  bool sectionSeeds = true;
  btScalar insideTolerance = btScalar(0);  ///< a point farther outside than this is "outside";
                                           ///< 0: a quarter voxel
};

/// Quality figures of a generated fibre set.
struct FibreQuality {
  int requested = 0;             ///< fibres asked for
  int generated = 0;             ///< fibres returned
  int traced = 0;                ///< streamlines traced (seeds tried)
  int droppedOutside = 0;        ///< streamlines that left the surface
  int droppedEarly = 0;          ///< streamlines that stopped before the insertion area
  int crowded = 0;               ///< good streamlines closer than minSeparation to an earlier fibre
  size_t originVertices = 0;     ///< surface vertices in the origin area
  size_t insertionVertices = 0;  ///< surface vertices in the insertion area
  int gridCells[3] = {0, 0, 0};  ///< voxel grid size
  btScalar voxelSize = 0;        ///< [m]
  size_t interiorVoxels = 0;     ///< voxels inside the muscle (the Laplace domain)
  double coverage = 0;           ///< fraction of interior voxels within coverageDistance of a fibre
  btScalar minLength = 0, medianLength = 0, maxLength = 0;  ///< fibre lengths [m]
  int crossingPairs = 0;     ///< pairs of fibres with segments closer than crossingTolerance
  int pointsOutside = 0;     ///< fibre points outside the surface beyond the tolerance
  double rightEnds = 0;      ///< share of fibres whose ends both lie within 1.5 voxels of their
                             ///< area (its triangles; origin first, insertion last)
  btScalar worstEndGap = 0;  ///< the largest distance of a fibre end from its area [m]
  double seconds = 0;        ///< wall time
};

struct FibreGenerationResult {
  FibreSet fibres;  ///< each from origin to insertion [m]
  FibreQuality quality;
  std::vector<std::string> warnings;    ///< fewer fibres than asked, empty areas widened, ...
  std::vector<uint32_t> originArea;     ///< surface vertices of the origin area
  std::vector<uint32_t> insertionArea;  ///< surface vertices of the insertion area
};

/// The surface vertices of both areas as generateFibres() uses them (a far end resolved against
/// the other area; a vertex in both areas left out of both, with a warning). Throws InputError
/// (source `source`) for vertex indices out of range or an area with no surface vertex.
void resolveAttachmentAreas(const TriangleMesh& surface, const AttachmentArea& origin,
                            const AttachmentArea& insertion, const std::string& source,
                            std::vector<uint32_t>& originIds, std::vector<uint32_t>& insertionIds,
                            std::vector<std::string>& warnings);

/// Generates fibres inside `surface` (closed, outward, metres). A bone area keeps only its
/// patches at an end of the muscle (not where the muscle passes over the bone). Throws
/// InputError (source `source`) when the surface or the areas make it impossible (e.g. both
/// areas empty), when no grid up to options.maxGrid connects the areas, or when fewer than
/// options.minShare of the fibres asked for can be made (saying what to change).
FibreGenerationResult generateFibres(const TriangleMesh& surface, const AttachmentArea& origin,
                                     const AttachmentArea& insertion,
                                     const FibreGenerationOptions& options,
                                     const std::string& source = "muscle");

/// Least-squares sphere through points (algebraic fit, Eigen); returns false if degenerate.
bool fitSphere(const std::vector<btVector3>& points, btVector3& centre, btScalar& radius);

/// The femoral head's centre: a sphere fitted to the femur's vertices within `depth` of its
/// extreme end along +`up` (the proximal end), refined once with the vertices near the sphere.
bool fitFemoralHead(const TriangleMesh& femur, const btVector3& up, btScalar depth,
                    btVector3& centre, btScalar& radius);

}  // namespace fibremss
