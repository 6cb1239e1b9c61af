// `--set key=value`: dotted paths into the scene JSON and shorthands a user expects.
#include <algorithm>
#include <filesystem>
#include <map>

#include "SceneFields.h"
#include "fibremss/Error.h"
#include "fibremss/Suggest.h"

namespace fibremss::scene {
namespace {

/// Where a shorthand goes: every muscle, every bone's spheres, every sweep, or one section.
enum class Target { Muscles, BoneSpheres, Sweeps, Section, TopLevel };

struct Shorthand {
  Target target;
  const char* section;  // for Target::Section
};

const std::map<std::string, Shorthand>& shorthands() {
  static const std::map<std::string, Shorthand> table = {
      {"resolution", {Target::Muscles, ""}},
      {"fibre_count", {Target::Muscles, ""}},
      {"attachment_distance", {Target::Muscles, ""}},
      {"skin_neighbours", {Target::Muscles, ""}},
      {"tendon_fraction", {Target::Muscles, ""}},
      {"tendon_stiffness", {Target::Muscles, ""}},
      {"free_end", {Target::Muscles, ""}},
      {"layout", {Target::Section, "model"}},
      {"neighbours", {Target::Section, "model"}},
      {"kappa", {Target::Section, "model"}},
      {"spring_stiffness", {Target::Section, "model"}},
      {"damping", {Target::Section, "model"}},
      {"density", {Target::Section, "model"}},
      {"volume_stiffness", {Target::Section, "model"}},
      {"enclosed_volume_stiffness", {Target::Section, "model"}},
      {"volume_coarsening", {Target::Section, "model"}},
      {"fibre_stiffness_ratio", {Target::Section, "model"}},
      {"strain_limit", {Target::Section, "model"}},
      {"damping_scale", {Target::Section, "model"}},
      {"integrator", {Target::Section, "simulation"}},
      {"time_step", {Target::Section, "simulation"}},
      {"dt", {Target::Section, "simulation"}},
      {"min_dt", {Target::Section, "simulation"}},
      {"stop", {Target::Section, "simulation"}},
      {"iterations", {Target::Section, "simulation"}},
      {"epsilon", {Target::Section, "simulation"}},
      {"tolerance", {Target::Section, "simulation"}},
      {"budget_ms", {Target::Section, "simulation"}},
      {"rebuild_every_step", {Target::Section, "simulation"}},
      {"deviation_epsilon", {Target::Section, "simulation"}},
      {"blended_pretransform", {Target::Section, "simulation"}},
      {"pretransform_blend", {Target::Section, "simulation"}},
      {"motion_fraction", {Target::Section, "simulation"}},
      {"seed", {Target::Section, "simulation"}},
      {"initial_noise", {Target::Section, "simulation"}},
      {"threads", {Target::Section, "simulation"}},
      {"diagonal_jacobian", {Target::Section, "simulation"}},
      {"solver_tolerance", {Target::Section, "simulation"}},
      {"solver_iterations", {Target::Section, "simulation"}},
      {"constraint_iterations", {Target::Section, "simulation"}},
      {"projective_rho", {Target::Section, "simulation"}},
      {"projective_history", {Target::Section, "simulation"}},
      {"projective_contact_weight", {Target::Section, "simulation"}},
      {"persistent_contacts", {Target::Section, "simulation"}},
      {"pair_reactions", {Target::Section, "simulation"}},
      {"on_failure", {Target::Section, "simulation"}},
      {"max_retries", {Target::Section, "simulation"}},
      {"max_step_deg", {Target::Section, "simulation"}},
      {"muscle_muscle", {Target::Section, "collision"}},
      {"bone_collision", {Target::Section, "collision"}},
      {"distance_field_cell", {Target::Section, "collision"}},
      {"penetration_recovery", {Target::Section, "collision"}},
      {"sliding_contacts", {Target::Section, "collision"}},
      {"surface_contact", {Target::Section, "collision"}},
      {"muscle_bone", {Target::Section, "collision"}},
      {"frame_every", {Target::Section, "outputs"}},
      {"surfaces", {Target::Section, "outputs"}},
      {"particles", {Target::Section, "outputs"}},
      {"fibres", {Target::Section, "outputs"}},
      {"thinning", {Target::BoneSpheres, ""}},
      {"max_radius", {Target::BoneSpheres, ""}},
      {"step_deg", {Target::Sweeps, ""}},
      {"start_deg", {Target::Sweeps, ""}},
      {"end_deg", {Target::Sweeps, ""}},
      {"pivot", {Target::Sweeps, ""}},
      {"name", {Target::TopLevel, ""}},
      {"description", {Target::TopLevel, ""}},
      {"units", {Target::TopLevel, ""}},
      {"data_dir", {Target::TopLevel, ""}},
  };
  return table;
}

std::vector<std::string> split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  size_t start = 0;
  for (size_t end; (end = text.find(separator, start)) != std::string::npos; start = end + 1)
    parts.push_back(text.substr(start, end - start));
  parts.push_back(text.substr(start));
  return parts;
}

void setPath(Json& scene, const std::string& key, const Json& value) {
  Json* node = &scene;
  const std::vector<std::string> parts = split(key, '.');
  std::string walked;
  for (size_t i = 0; i < parts.size(); ++i) {
    const std::string& part = parts[i];
    if (part.empty()) throw InputError("--set", key, "empty component in the dotted key");
    const bool last = i + 1 == parts.size();
    if (node->is_array()) {
      // An index, or the name of an element ("muscles.rectus_femoris.resolution").
      Json* element = nullptr;
      if (std::all_of(part.begin(), part.end(), ::isdigit)) {
        // More digits than any array has elements: no stoul overflow.
        const bool tooLong = part.size() > std::to_string(node->size()).size();
        if (tooLong || std::stoul(part) >= node->size())
          throw InputError(
              "--set", key,
              walked + " has " + std::to_string(node->size()) + " elements; no [" + part + "]");
        element = &(*node)[std::stoul(part)];
      } else {
        for (auto& candidate : *node)
          if (candidate.is_object() && candidate.value("name", "") == part) element = &candidate;
        if (!element)
          throw InputError("--set", key, walked + " has no element named \"" + part + "\"");
      }
      if (last) *element = value;
      node = element;
    } else if (node->is_object() || node->is_null()) {
      if (node->is_null()) *node = Json::object();
      if (last) {
        (*node)[part] = value;
      } else {
        Json& child = (*node)[part];
        if (child.is_null()) child = Json::object();
        node = &child;
      }
    } else {
      throw InputError("--set", key,
                       walked + " is " + describe(*node) + ", not an object or array");
    }
    walked = walked.empty() ? part : walked + "." + part;
  }
}

}  // namespace

std::vector<std::string> shorthandKeys() {
  std::vector<std::string> keys;
  for (const auto& entry : shorthands()) keys.push_back(entry.first);
  return keys;
}

void applyOverrides(Json& scene, const std::vector<std::string>& overrides) {
  for (const std::string& override : overrides) {
    const size_t equals = override.find('=');
    if (equals == std::string::npos || equals == 0)
      throw InputError("--set", override, "expected key=value, e.g. --set resolution=40");
    const std::string key = override.substr(0, equals);
    const std::string text = override.substr(equals + 1);
    // JSON when it is JSON (nesting and duplicate keys checked as in a scene file), else text.
    Json value = Json::accept(text) ? parseJson(text, "--set " + key) : Json(text);

    if (key.find('.') != std::string::npos) {
      setPath(scene, key, value);
      continue;
    }
    const auto found = shorthands().find(key);
    if (found == shorthands().end()) {
      std::string list;
      for (const auto& name : shorthandKeys()) list += (list.empty() ? "" : ", ") + name;
      throw InputError("--set", key,
                       "unknown key" + didYouMean(key, shorthandKeys()) +
                           " Use a dotted path into the scene (e.g. model.kappa, "
                           "muscles.0.resolution) or one of: " +
                           list);
    }
    const Shorthand& shorthand = found->second;
    auto each = [&](const char* arrayName, auto&& apply) {
      if (!scene.contains(arrayName) || !scene[arrayName].is_array()) return 0;
      int applied = 0;
      for (auto& element : scene[arrayName])
        if (element.is_object()) applied += apply(element);
      return applied;
    };
    switch (shorthand.target) {
      case Target::TopLevel:
        if (key == "data_dir" && value.is_string() && !value.get<std::string>().empty())
          value = std::filesystem::absolute(value.get<std::string>()).lexically_normal().string();
        scene[key] = value;
        break;
      case Target::Section:
        if (!scene.contains(shorthand.section) || scene[shorthand.section].is_null())
          scene[shorthand.section] = Json::object();
        if (!scene[shorthand.section].is_object())
          throw InputError("--set", key, std::string(shorthand.section) + " is not an object");
        scene[shorthand.section][key] = value;
        break;
      case Target::Muscles:
        if (each("muscles", [&](Json& muscle) { return (muscle[key] = value, 1); }) == 0)
          throw InputError("--set", key, "the scene has no muscles");
        break;
      case Target::BoneSpheres:
        if (each("bones", [&](Json& bone) {
              if (!bone.contains("spheres") || !bone["spheres"].is_object())
                bone["spheres"] = Json::object();
              bone["spheres"][key] = value;
              return 1;
            }) == 0)
          throw InputError("--set", key, "the scene has no bones");
        break;
      case Target::Sweeps:
        if (each("bones", [&](Json& bone) {
              if (!bone.contains("motion") || !bone["motion"].is_object() ||
                  bone["motion"].value("type", "") != "sweep")
                return 0;
              bone["motion"][key] = value;
              return 1;
            }) == 0)
          throw InputError("--set", key, "the scene has no joint sweep (motion type \"sweep\")");
        break;
    }
  }
}

}  // namespace fibremss::scene
