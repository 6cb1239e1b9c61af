#pragma once
// Internal to FibreRun: the frames of a run (muscle surfaces and particles with the arrays to
// colour by, bones written only when they moved, run.pvd) and the per-particle fields they
// carry.
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "fibremss/Gltf.h"
#include "fibremss/ImplicitSurface.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Output.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"

namespace fibremss {

/// A name usable in a file name: letters, digits, '-' and '_' kept, anything else '_'.
std::string fileSafe(const std::string& name);

/// Per particle: current / rest length of the fibre segments it belongs to (their lengths
/// summed, so a particle between two segments averages them; 1 off every fibre).
void particleFibreStretch(const MuscleSettings& muscle, std::span<const btVector3> positions,
                          std::vector<float>& stretch);

/// Per particle: Σ(l − L0) / Σ L0 over its springs, the engineering strain of its neighbourhood
/// (> 0 stretched, < 0 compressed; 0 without springs).
void particleSpringStrain(const MuscleSettings& muscle, std::span<const btVector3> positions,
                          std::vector<float>& strain);

/// What a frame shows: which step and pose, and when.
struct FrameInfo {
  int step = 0;          ///< solver step the frame follows (0: the first)
  int pose = 0;          ///< pose of the motion at that step
  double poseLabel = 0;  ///< the pose's label (LoadedScene::poseLabels, e.g. a joint angle)
  double time = 0;       ///< simulated time at the end of the step [s]
};

/// The formats a frame is written in.
struct FrameFormats {
  bool vtk = true;    ///< frames/*.vtp and run.pvd (ParaView), in the scene's units
  bool gltf = false;  ///< gltf/frame_NNNNN.glb: muscle surfaces and bones, in metres
};

/// Writes the frames of a run. VTK in the scene's units: per muscle its deformed surface and its
/// particles (fibres as lines), per bone its mesh where it is, again only once it moved, and
/// run.pvd listing them all at their simulated times. glTF: one .glb per frame with every
/// muscle's deformed surface and every bone where it is, and run.glb animating them all. With
/// OutputSettings::implicitSurface the muscle surface is the implicit one, extracted at each
/// frame on the writer's task pool, with the system's threads or on its host scheduler (its
/// topology changes from frame to frame: no run.glb).
class FrameWriter {
 public:
  FrameWriter(const std::string& outDir, const OutputSettings& settings, double unitScale,
              FrameFormats formats = {});

  /// One frame. `surfaceDepthsMm[m]`: depth of muscle m's surface vertices in the bones [mm].
  void write(const FrameInfo& info, const MuscleSystem& system,
             std::span<const MuscleHandle> muscles, const PreparedScene& prepared,
             std::span<const btTransform> boneTransforms,
             std::span<const std::vector<float>> surfaceDepthsMm);

  /// After the last frame: writes gltf/run.glb, every glTF frame in one animated file.
  void finish() const;

  int frames() const { return frames_; }
  /// Wall time of extracting the implicit surfaces, per frame [ms] (empty without them).
  std::span<const double> implicitSurfaceMs() const { return implicitMs_; }

 private:
  void writeMuscle(const FrameInfo& info, size_t m, const MuscleSystem& system, MuscleHandle handle,
                   std::span<const float> depthsMm, int& part);
  void writeBones(const FrameInfo& info, const PreparedScene& prepared,
                  std::span<const btTransform> boneTransforms, int& part);
  void writeGltf(const FrameInfo& info, const MuscleSystem& system,
                 std::span<const MuscleHandle> muscles, const PreparedScene& prepared,
                 std::span<const btTransform> boneTransforms);
  std::vector<DataArray> frameFields(const FrameInfo& info) const;
  /// Every muscle's implicit surface from its particles now (prepared at the first frame).
  void extractImplicit(const MuscleSystem& system, std::span<const MuscleHandle> muscles,
                       const PreparedScene& prepared);
  /// The surface a frame shows of muscle m: its implicit surface or its skinned one.
  TriangleMesh frameSurface(size_t m, const MuscleSystem& system, MuscleHandle handle) const;
  /// Muscle m's arrays on the implicit surface's vertices: each its nearest particle's.
  std::vector<DataArray> implicitArrays(size_t m, const MuscleSystem& system, MuscleHandle handle,
                                        std::span<const float> fixed) const;
  /// Rounds `data`'s points and float arrays to the steps and records them in its field data.
  void quantise(PolyData& data) const;
  void add(double time, const std::string& file, PolyData& data, int part, const std::string& name);

  std::string outDir_;
  const OutputSettings& settings_;
  FrameFormats formats_;
  btScalar sceneUnitsPerMetre_;
  double lengthStep_;  ///< positions and length arrays rounded to it [scene units] (0: exact)
  double strainStep_;  ///< dimensionless arrays rounded to it [—] (0: exact)
  PvdCollection pvd_;
  GltfAnimation animation_;                 ///< the glTF frames so far
  std::vector<std::string> boneFiles_;      ///< per bone, the file of its latest placement
  std::vector<btTransform> boneWrittenAt_;  ///< per bone, the transform that file shows
  std::vector<float> stretch_, strain_;     ///< per particle (scratch)
  std::unique_ptr<TaskPool> pool_;          ///< extracts the implicit surfaces (first frame on)
  std::vector<ImplicitSurface> implicit_;   ///< per muscle, with implicitSurface
  std::vector<double> implicitMs_;          ///< per frame: their extraction's wall time [ms]
  int frames_ = 0;
};

}  // namespace fibremss
