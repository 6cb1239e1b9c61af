#pragma once
// A scene: bones with motions, muscles, model parameters, collision settings and outputs,
// read from JSON (a file or a built-in scene) and resolved into the plugin's inputs.
#include <LinearMath/btTransform.h>

#include <string>
#include <vector>

#include "fibremss/Parameters.h"
#include "fibremss/Preparation.h"

namespace fibremss {

/// Rigid motion of one bone over the scene's poses, relative to its rest pose.
struct BoneMotion {
  std::vector<btTransform> poses;  ///< one transform per pose (empty: the bone stays at rest)
  /// The joint coordinates the poses are given in (an OpenSim motion's columns; empty for the
  /// other motions).
  std::vector<std::string> coordinateNames;
  /// Per pose, the coordinates' values [°] (sub-poses: interpolated linearly).
  std::vector<std::vector<double>> coordinates;
};

/// A blade (MuscleSystem::addBlade): a straight edge moved like a bone, which cuts the muscles
/// where it sweeps through them.
struct BladeInput {
  std::string name;         ///< blade name from the scene
  btVector3 from{0, 0, 0};  ///< one end of its edge at rest [m]
  btVector3 to{0, 0, 0};    ///< the other end [m]
  BoneMotion motion;        ///< its transforms over the scene's poses (none: it stays at rest)
};

/// What a run writes (paths relative to the run's --out directory).
struct OutputSettings {
  int frameEvery = 1;          ///< write a frame every k-th step (0: none)
  bool writeSurfaces = true;   ///< deformed muscle surfaces in frames
  bool writeParticles = true;  ///< particles with radii in frames
  bool writeFibres = true;     ///< deformed fibres in frames
  /// Frame positions and length arrays rounded to multiples of the largest power of two (in
  /// the frames' units) not above this [mm] (0: written exactly).
  double quantiseMm = 0;
  /// Dimensionless frame arrays (stretch, strain, fixed) rounded likewise to a power-of-two
  /// step not above this [—] (0: written exactly).
  double quantiseStrain = 0;
  /// Frames show each muscle's implicit surface (ImplicitSurface.h: the iso-surface of its
  /// particles' field, which opens where it tears) instead of its skinned surface.
  bool implicitSurface = false;
};

/// An exact case the scene reproduces (the analytic tier): a straight cylindrical muscle whose
/// free length (between its attachments) is stretched or twisted by its bones, or a sphere
/// squeezed between two plates (Hertz). `run` and `compare` measure its first muscle beside the
/// exact answer: the cylinders at the last pose, the sphere's contact radius at every pose.
struct AnalyticCase {
  /// "none", "cylinder-stretch", "cylinder-twist" or "sphere-planes"
  std::string type = "none";
  /// Cylinders: the rest axis where the free length starts (the fixed side); sphere-planes: the
  /// sphere's centre [m].
  btVector3 axisStart{0, 0, 0};
  /// Cylinders: the rest axis where the free length ends; sphere-planes: where the plate's face
  /// touches the rest sphere (|axisEnd − axisStart| is the sphere's radius R) [m].
  btVector3 axisEnd{0, 0, 0};
  double stretch = 1;   ///< free length at the last pose / at rest (symmetric about the
                        ///< middle, along the axis)
  double twistDeg = 0;  ///< rotation of the axisEnd side about start → end at the last pose [°]
  double poissonRatio = 0.49;  ///< ν of the continuum the exact stretch answer is for
  /// sphere-planes: the bone (index into LoadedScene::bones) whose face touches the sphere at
  /// axisEnd at rest; its approach towards the centre at a pose is δ (-1: none).
  int plateBone = -1;
};

/// How the scene's CalculiX reference (`fibremss reference`, `compare`) is solved where the
/// scene needs its own choice.
struct ReferenceSettings {
  /// Muscle–bone contact: "finite" sliding (ccx's default) or "small" sliding (each muscle
  /// surface node keeps the bone face it was paired with at the start of an increment through
  /// that increment's Newton iterations), for the reference and all its gates' solves alike.
  std::string contactSliding = "finite";
};

/// A tool a script poses at haptic rate (HapticTool): a sphere whose centre moves along straight
/// segments between waypoints, one pose per tick.
struct ToolScript {
  bool present = false;    ///< the scene has a tool
  double radius = 0;       ///< the sphere's radius [m]
  double tickTime = 1e-3;  ///< simulated time per tick [s]
  /// Every wholeEvery-th tick steps the whole muscles, the ticks between only the particles
  /// near the tool (HapticRegion::wholeEvery) [ticks]
  int wholeEvery = 1;
  double regionMargin = 0.01;  ///< the region's reach beyond the sphere (HapticRegion) [m]
  double regionDrift = 0.002;  ///< the tool's move that gathers the region again (HapticRegion) [m]
  std::vector<double> times;   ///< waypoint times from the start, increasing [s]
  std::vector<btVector3> positions;  ///< the sphere's centre at each waypoint [m]
  /// Per waypoint: what the segment ending there does ("press", "slide", ...; the first's is
  /// the start's).
  std::vector<std::string> phases;

  /// Ticks the script lasts: its last waypoint's time / tickTime, rounded.
  int ticks() const;
  /// Where the centre is after `tick` ticks (held at the ends) [m].
  btVector3 position(int tick) const;
  /// The phase of the segment tick `tick` lies in.
  const std::string& phase(int tick) const;
};

/// A scene resolved into what preparation and simulation take; all SI.
struct LoadedScene {
  std::string name;                   ///< scene name (built-in name or file stem)
  std::string source;                 ///< the file it came from, or "built-in"
  std::string json;                   ///< the complete scene, every default filled in
  std::string description;            ///< one line saying what the scene shows
  double unitScale = 1;               ///< metres per scene unit (0.001 for "mm")
  std::vector<BoneInput> bones;       ///< bones, meshes loaded or generated
  std::vector<MuscleInput> muscles;   ///< muscles, surfaces and fibres loaded or generated
  std::vector<BoneMotion> motions;    ///< one per bone
  std::vector<BladeInput> blades;     ///< blades with their motions (none: nothing cuts)
  int poseCount = 1;                  ///< number of poses (simulation steps) in the motion
  std::vector<double> poseLabels;     ///< per pose, e.g. the sweep angle in degrees
  MuscleSystemDef simulation;         ///< the solver: its definition and first step settings
  OutputSettings outputs;             ///< output settings
  AnalyticCase analytic;              ///< the exact case it reproduces (type "none": none)
  ReferenceSettings reference;        ///< how its CalculiX reference is solved
  ToolScript tool;                    ///< a tool posed at haptic rate (present: `tool`)
  std::vector<std::string> warnings;  ///< things found while loading that a run can live with
  std::vector<std::string> notes;     ///< what loading changed that a user should know
                                      ///< (large jumps split into sub-poses, ...)

  /// Transform of bone b at pose p (identity where the bone has no motion).
  btTransform bonePose(size_t bone, int pose) const;
  /// Transform of blade b at pose p (identity where the blade has no motion).
  btTransform bladePose(size_t blade, int pose) const;
};

/// What pose `pose` is: its coordinates' values where a bone's motion gives them
/// ("hip_flexion_r=30°, hip_adduction_r=-5°"), else its label.
std::string poseName(const LoadedScene& scene, int pose);

/// Warnings about a prepared scene's attachments: a muscle whose fibres end next to a bone that
/// moves relative to a bone the muscle is fixed to, with no particle fixed to the moving bone
/// (it will not follow it; `fibremss check` and `run` print them).
std::vector<std::string> attachmentWarnings(const LoadedScene& scene,
                                            const PreparedScene& prepared);

/// Built-in scene names with a one-line description each.
struct BuiltInScene {
  std::string name;
  std::string description;
};
std::vector<BuiltInScene> builtInScenes();

/// The JSON text of a built-in scene, every default filled in (throws InputError for an
/// unknown name). Loading it again gives the same scene.
std::string exportBuiltInScene(const std::string& name);

/// Every key the scene reader reads, sorted, each once: the keys of every built-in scene with
/// every default filled in, every key `--set` takes without its path and the fields of a surface
/// read from a file (a fuzzer's dictionary of scene field names).
std::vector<std::string> sceneKeys();

/// Loads a scene by built-in name or .json path and applies `key=value` overrides
/// (e.g. "resolution=40", "simulation.iterations=100"). Throws InputError naming the file
/// and field for unknown fields, wrong types and bad values.
LoadedScene loadScene(const std::string& nameOrPath,
                      const std::vector<std::string>& overrides = {});

}  // namespace fibremss
