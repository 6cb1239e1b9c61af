#pragma once
// Internal to the scene loader: the keys of the `model` section and of each muscle, one row a key
// (its name, the member it sets, the range it takes), as visitSimulationSettings lists the
// `simulation` section's (Parameters.h). The loader reads every row, `--set` takes every row's key
// without its path, and scenes/README.md has a row for each (a test checks that).
#include <iterator>
#include <limits>
#include <string>

#include "fibremss/Parameters.h"
#include "fibremss/Preparation.h"

namespace fibremss {

/// FreeEnds by the names a scene gives them, in enum order ("unknown" past the last, as the
/// core's toString).
inline const char* toString(FreeEnds ends) {
  constexpr const char* kNames[] = {"none", "origin", "insertion", "both"};
  const size_t index = static_cast<size_t>(ends);
  return index < std::size(kNames) ? kNames[index] : "unknown";
}

/// Parses FreeEnds by name (as in toString); false for an unknown name.
inline bool fromString(const std::string& name, FreeEnds& ends) {
  for (FreeEnds value : {FreeEnds::None, FreeEnds::Origin, FreeEnds::Insertion, FreeEnds::Both})
    if (name == toString(value)) {
      ends = value;
      return true;
    }
  return false;
}

namespace scene {

/// A number a scene may give as "auto" instead, kept as −1: the core then works it out.
struct OrAuto {
  btScalar& value;      ///< −1 for "auto"
  const char* meaning;  ///< what "auto" takes, for error messages
};

/// A number whose default the loader works out after the muscle's fibres: absent, it stays −1
/// and the complete scene records the value worked out.
struct Derived {
  btScalar& value;
};

/// Calls visit(key, member) for each key of a scene's `model` section, in the order a scene lists
/// them.
template <class Visit>
void visitModelSettings(SpringParameters& springs, Visit&& visit) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  visit(SettingKey{"layout"}, springs.layout);
  visit(SettingKey{"neighbours", 1, 1000}, springs.neighbours);
  visit(SettingKey{"kappa", 0, kInf}.open(), springs.kappa);
  visit(SettingKey{"spring_stiffness"}, springs.stiffness);
  // Damping slows the muscles' motion but does not move where they settle: a solver's key.
  visit(SettingKey{"damping", 0, kInf}.ofSolver(), OrAuto{springs.damping, "Zeleny's estimate"});
  visit(SettingKey{"damping_scale", 0, kInf}.ofSolver(), springs.dampingScale);
  visit(SettingKey{"density", 0, kInf}.open(), springs.density);
  visit(SettingKey{"poisson_ratio", 0.25, 0.499}, springs.poissonRatio);
  visit(SettingKey{"volume_stiffness", 0, 1e6},
        OrAuto{springs.volumeStiffness, "from poisson_ratio"});
  visit(SettingKey{"enclosed_volume_stiffness", 0, 1e6}, springs.enclosedVolumeStiffness);
  visit(SettingKey{"volume_coarsening", 1, 100}, springs.volumeCoarsening);
  visit(SettingKey{"fibre_stiffness_ratio", 0, 1e3}.open(), springs.fibreStiffnessRatio);
  visit(SettingKey{"strain_limit", 0, 1e3}, springs.strainLimit);
  visit(SettingKey{"break_stretch", 0, 1e3}, springs.breakStretch);
}

/// The `model` section's checks that one key's range cannot state: fail(key, what) throws.
template <class Fail>
void checkModelSettings(const SpringParameters& springs, Fail&& fail) {
  if (springs.strainLimit > 0 && springs.strainLimit <= 1)
    fail("strain_limit", "expected 0 (no limit) or a ratio > 1 of current to rest length");
  if (springs.breakStretch > 0 &&
      (springs.breakStretch <= 1 ||
       (springs.strainLimit > 0 && springs.breakStretch >= springs.strainLimit)))
    fail("break_stretch",
         "expected 0 (no tearing) or a ratio > 1 of current to rest length, below strain_limit "
         "when that is set");
}

/// A muscle as its scene section's settings give it: the input the core prepares, at a scene's
/// defaults where they differ from the core's, and the fibres it takes.
struct MuscleSection {
  MuscleSection() {
    // A scene's muscles have tendons (10 % of each fibre at each attached end) and both ends
    // attached unless they say otherwise.
    input.parameters.tendonFraction = btScalar(0.1);
    input.parameters.freeEnds = FreeEnds::None;
  }
  MuscleInput input;    ///< its fields' members; the springs come from the `model` section
  int fibreCount = 64;  ///< fibres generated; from a file, an evenly spaced subset when it has more
};

/// Calls visit(key, member) for each setting of a scene's muscle (those `--set` gives every
/// muscle), in the order a scene lists them; its name, surface, fibres and declared attachments
/// are read around them.
template <class Visit>
void visitMuscleSettings(MuscleSection& muscle, Visit&& visit) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  MuscleParameters& parameters = muscle.input.parameters;
  visit(SettingKey{"fibre_count", 1, 1000000}, muscle.fibreCount);
  visit(SettingKey{"resolution", 2, 100000}, parameters.resolution);
  visit(SettingKey{"skin_neighbours", 1, 64}, parameters.skinNeighbours);
  visit(SettingKey{"tendon_fraction", 0, 0.5}, parameters.tendonFraction);
  visit(SettingKey{"tendon_stiffness", 1, 1e4}, parameters.tendonStiffness);
  visit(SettingKey{"free_end"}, parameters.freeEnds);
  visit(SettingKey{"fibre_grid_columns", 0, 1000000}, muscle.input.fibreGridColumns);
  visit(SettingKey{"attachment_distance", 0, kInf}.inMetres(),
        Derived{parameters.attachmentDistance});
}

}  // namespace scene
}  // namespace fibremss
