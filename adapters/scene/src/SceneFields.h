#pragma once
// Internal to the scene loader: a reader for one JSON object that validates each field, fills in
// its default, records it in the complete scene, and rejects fields nobody asked for.
#include <LinearMath/btVector3.h>

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "fibremss/InputFiles.h"

namespace fibremss::scene {

using Json = nlohmann::ordered_json;

/// The longest text field (a path's length, PATH_MAX) and the longest name [bytes].
constexpr size_t kMaxTextBytes = 4096;
constexpr size_t kMaxNameBytes = 256;

/// The numbers in a range as an error message says it expects them ("a number in [0, 1]").
std::string numberRange(double lowest, double highest, bool lowestExcluded);

/// "muscles[2]" + "resolution" -> "muscles[2].resolution".
std::string joinPath(const std::string& path, const std::string& key);

/// Reads fields of one JSON object at `path` of scene file `source`. Every accessor validates
/// the field, returns it (or its default) and records the value in complete(); finish()
/// throws InputError for fields that were never read (unknown fields).
class Fields {
 public:
  Fields(const Json& node, std::string path, std::string source);

  double number(const std::string& key, double fallback, double lowest, double highest,
                bool lowestExcluded = false);
  int integer(const std::string& key, int fallback, int lowest, int highest);
  bool boolean(const std::string& key, bool fallback);
  /// A string of valid UTF-8 of at most `maxBytes` (a path's length by default).
  std::string text(const std::string& key, const std::string& fallback,
                   size_t maxBytes = kMaxTextBytes);
  std::string choice(const std::string& key, const std::string& fallback,
                     const std::vector<std::string>& allowed);
  btVector3 vector3(const std::string& key, const btVector3& fallback);
  /// The raw field (nullptr when absent); marks it known. Record it with set().
  const Json* raw(const std::string& key);
  bool has(const std::string& key) const { return node_->contains(key); }
  /// A nested object (an empty one when absent; an error when not an object).
  Fields object(const std::string& key);
  /// Elements of an array field (empty when absent; an error when not an array).
  const Json& array(const std::string& key);
  /// Records a value (e.g. a nested object's complete()) in the complete scene.
  void set(const std::string& key, Json value);

  /// Throws for unknown fields; returns the complete object, every default filled in.
  Json finish();

  std::string pathOf(const std::string& key) const { return joinPath(path_, key); }
  const std::string& path() const { return path_; }
  const std::string& source() const { return source_; }
  [[noreturn]] void fail(const std::string& key, const std::string& what) const;

 private:
  const Json* node_;
  std::string path_;
  std::string source_;
  std::vector<std::string> known_;
  Json complete_ = Json::object();
};

/// A JSON value as a user reads it in an error message (at most 60 characters, however large
/// or deep the value).
std::string describe(const Json& value);

/// Parses scene JSON from `source`; InputError for invalid JSON, nesting beyond kMaxJsonDepth and
/// duplicate keys, naming where.
Json parseJson(const std::string& text, const std::string& source);

/// Reads [x, y, z] at `path` (error naming the path otherwise).
btVector3 readVector3(const Json& value, const std::string& path, const std::string& source);

/// Applies `key=value` overrides to a raw scene: dotted paths ("model.kappa=2",
/// "muscles.0.resolution=20", "muscles.rectus.resolution=20") and shorthands ("resolution=40"
/// for every muscle, "kappa=2" for the model, "step_deg=5" for every sweep, ...). Values are
/// parsed as JSON when they parse, else taken as strings. Throws InputError for unknown keys.
void applyOverrides(Json& scene, const std::vector<std::string>& overrides);

/// Where `--set KEY=VALUE` without a path puts the value.
enum class ShorthandTarget { TopLevel, Muscles, BoneSpheres, Sweeps, Section };

/// Keys `--set` takes without their path, and where they go.
struct SectionKeys {
  ShorthandTarget target;         ///< the scene's top level, every muscle, ... or a section
  std::string section;            ///< ShorthandTarget::Section: "model", "simulation", ...
  std::vector<std::string> keys;  ///< in the order the reader reads them
};

/// Every key `--set` takes without its path, stated beside the scene's readers (SceneLoad.cpp):
/// the top level's, every muscle's, every bone's spheres' and every joint sweep's listed there,
/// then every key of the settings sections (model, simulation, collision, outputs) as their
/// readers read them. A key listed twice goes where it is listed first.
std::vector<SectionKeys> shorthandSections();

/// The shorthand keys `--set` accepts and what each applies to (for help and error messages).
std::vector<std::string> shorthandKeys();

}  // namespace fibremss::scene
