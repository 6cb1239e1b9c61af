#pragma once
// The CalculiX reference's options, shared by `reference` and `compare`.
#include <CLI/CLI.hpp>
#include <map>
#include <string>
#include <vector>

#include "Validators.h"
#include "fibremss/Reference.h"

namespace fibremss::cli {

/// An enum option given by name (case ignored): "expected one of C3D10, C3D4, got C3D8"; the
/// help names the choices in the option's type.
template <typename Enum>
CLI::Validator choices(const std::map<std::string, Enum>& names) {
  std::vector<std::string> list;
  std::vector<Enum> values;
  for (const auto& [name, value] : names) {
    list.push_back(name);
    values.push_back(value);
  }
  return namedChoice(list, [values](size_t i) {
    return std::to_string(static_cast<int>(values[i]));  // CLI11 reads enums as numbers
  });
}

inline void addReferenceArgs(CLI::App& command, ReferenceOptions& options) {
  command.add_option("--cache", options.cacheDir,
                     "Reference cache directory (default $FIBREMSS_CACHE/reference, else "
                     "~/.cache/fibremss/reference)");
  command
      .add_option("--ccx-element", options.definition.element,
                  "Reference element: C3D4 (linear tetrahedra; the refinement gate solves C3D10) "
                  "or C3D10 (quadratic; the gate solves the next mesh level); sphere-planes "
                  "defaults to C3D10")
      ->transform(choices(std::map<std::string, CalculixElement>{{"C3D10", CalculixElement::C3D10},
                                                                 {"C3D4", CalculixElement::C3D4}}))
      ->type_name("C3D4|C3D10")
      ->each([&options](const std::string&) { options.elementGiven = true; })
      ->default_str("C3D4");
  command
      .add_option("--ccx-poisson", options.definition.material.poissonRatio,
                  "Reference Poisson ratio (muscle is nearly incompressible)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 0.4999));
  command
      .add_option("--ccx-refine", options.definition.mesher.refinement,
                  "Reference mesh level (each level splits the surface triangles in four and "
                  "bounds the tetrahedron volume by 1/8)")
      ->capture_default_str()
      ->check(CLI::Range(0, 3));
  command
      .add_option("--ccx-contact", options.definition.contactPenalty,
                  "Reference muscle-bone contact: penalty slope K = this x E [1/m] (frictionless, "
                  "node to surface, every bone a rigid obstacle); 0: no contact; sphere-planes "
                  "defaults to 5e6")
      ->each([&options](const std::string&) { options.contactPenaltyGiven = true; })
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1e9));
  command
      .add_option("--ccx-sliding", options.definition.contactSliding,
                  "Reference muscle-bone contact tracking: finite (ccx's default) or small "
                  "(SMALL SLIDING: each node keeps its bone face through an increment's "
                  "iterations); "
                  "default: the scene's reference.contact_sliding")
      ->transform(choices(std::map<std::string, ContactSliding>{{"finite", ContactSliding::Finite},
                                                                {"small", ContactSliding::Small}}))
      ->type_name("finite|small")
      ->each([&options](const std::string&) { options.contactSlidingGiven = true; })
      ->default_str("the scene's");
  command
      .add_option("--ccx-increments", options.definition.incrementRule,
                  "What the 1 mm bound on an attached node's move per increment applies to: "
                  "bone-frame (its move beyond the rigid motion of the bone, or the world, in "
                  "whose frame the muscle's attachments move least) or world (its whole move, "
                  "the rule before; its cache entries keep their keys)")
      ->transform(choices(std::map<std::string, IncrementRule>{
          {"bone-frame", IncrementRule::BoneFrame}, {"world", IncrementRule::World}}))
      ->type_name("bone-frame|world")
      ->default_str("bone-frame");
  command
      .add_option("--ccx-memory", options.definition.memoryLimitGiB,
                  "Memory limit of each ccx run [GiB] (its address space); a run that exceeds "
                  "it fails with a message per pose instead of taking the machine's memory; 0: "
                  "no limit")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1e6));
  command
      .add_option("--jobs", options.jobs,
                  "Reference cells (one muscle of the reference's or a gate's solve) solved at "
                  "once, each a ccx process of its own; the cache ends with the same entries as "
                  "one at a time")
      ->capture_default_str()
      ->check(positiveInteger());
  command.add_flag("--reference-cached-only", options.cachedOnly,
                   "Use the reference (and each gate's solve) only if it is in the cache; what is "
                   "not there is reported missing, not computed");
  addOffFlag(command, "--no-gates", options.gates,
             "Skip the reference's gate solves (attachment distance x0.5 and x1.5, "
             "increments halved, one level finer); the comparison then reports no "
             "ranking");
}

}  // namespace fibremss::cli
