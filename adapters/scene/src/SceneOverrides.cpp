// `--set key=value`: dotted paths into the scene JSON and shorthands a user expects.
#include <algorithm>
#include <filesystem>
#include <map>

#include "SceneFields.h"
#include "fibremss/Error.h"
#include "fibremss/Suggest.h"

namespace fibremss::scene {
namespace {

using Target = ShorthandTarget;

/// Where a shorthand goes: every muscle, every bone's spheres, every sweep, or one section.
struct Shorthand {
  Target target;
  std::string section;  ///< Target::Section: the section's name
};

/// The shorthands, from the scene reader's list (shorthandSections).
std::map<std::string, Shorthand> makeShorthands() {
  std::map<std::string, Shorthand> table;
  for (const SectionKeys& section : shorthandSections())
    for (const std::string& key : section.keys)
      table.emplace(key, Shorthand{section.target, section.section});
  return table;
}

const std::map<std::string, Shorthand>& shorthands() {
  static const std::map<std::string, Shorthand> table = makeShorthands();
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
          throw InputError("--set", key, shorthand.section + " is not an object");
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
