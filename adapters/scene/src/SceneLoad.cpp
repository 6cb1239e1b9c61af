// Scene JSON -> LoadedScene: validation with defaults, units, files and generators, motions.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>
#include <type_traits>

#include "BuiltInScenes.h"
#include "SceneAnatomy.h"
#include "SceneFields.h"
#include "SceneMotion.h"
#include "SceneSettings.h"
#include "SceneShapes.h"
#include "SceneTool.h"
#include "SceneValidation.h"
#include "fibremss/Error.h"
#include "fibremss/Geometry.h"
#include "fibremss/MeshIO.h"
#include "fibremss/Scene.h"
#include "fibremss/SolverSettings.h"
#include "fibremss/Suggest.h"

namespace fibremss {
namespace {

using scene::Fields;
using scene::Json;
namespace fs = std::filesystem;

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kDegrees = M_PI / 180;
/// The attachment distance of a muscle that declares its areas and gives none, in sample steps
/// ΔL (fibre length over resolution − 1) [1]: a fibre's last particle lies up to one step
/// before the fibre's end, and the half step beyond reaches fibres that end a little short of
/// their bone (real-hip at resolution 30, steps 4.4-6.7 mm: 4 mm left the last particle free in
/// 33-50 of each muscle's 64 fibres ending on the femur, 8 mm in 1-19, 1.5 ΔL in 0-4).
constexpr double kAttachmentSteps = 1.5;
/// The attachment distance of a muscle without declared areas that gives none [m]: every
/// particle this near any bone is fixed, so a reach of steps would fix a belly lying along a
/// bone (example-elbow's flexor: 998 of 1920 particles at 1.5 ΔL = 16 mm, 254 at 4 mm).
constexpr double kAttachmentDistance = 0.004;

/// Every name an enum's toString() knows, in enum order (follows additions to Parameters.h).
template <typename Enum>
std::vector<std::string> namesOf() {
  std::vector<std::string> names;
  for (int value = 0; value < 256; ++value) {
    const std::string name = toString(static_cast<Enum>(value));
    if (name == "unknown") break;
    names.push_back(name);
  }
  return names;
}

/// JSON with two-space indents where arrays of numbers stay on one line ([x, y, z]).
void writePretty(const Json& value, int indent, std::string& out) {
  const std::string pad(size_t(indent + 2), ' ');
  if (value.is_object() && !value.empty()) {
    out += "{\n";
    size_t i = 0;
    for (auto it = value.begin(); it != value.end(); ++it, ++i) {
      out += pad + Json(it.key()).dump() + ": ";
      writePretty(it.value(), indent + 2, out);
      out += i + 1 < value.size() ? ",\n" : "\n";
    }
    out += std::string(size_t(indent), ' ') + "}";
  } else if (value.is_array() && !value.empty()) {
    const bool flat = std::none_of(value.begin(), value.end(),
                                   [](const Json& element) { return element.is_structured(); });
    if (flat) {
      out += "[";
      for (size_t i = 0; i < value.size(); ++i) out += (i ? ", " : "") + value[i].dump();
      out += "]";
      return;
    }
    out += "[\n";
    for (size_t i = 0; i < value.size(); ++i) {
      out += pad;
      writePretty(value[i], indent + 2, out);
      out += i + 1 < value.size() ? ",\n" : "\n";
    }
    out += std::string(size_t(indent), ' ') + "]";
  } else {
    out += value.dump();
  }
}

/// State shared while reading one scene.
struct Reader {
  std::string source;   ///< file path or "built-in scene NAME", for error messages
  fs::path baseDir;     ///< relative file paths start here
  std::string dataDir;  ///< substituted for ${data_dir}
  double scale = 1;     ///< metres per scene unit
  LoadedScene* result = nullptr;

  /// Resolves a file path field: ${data_dir} substitution, then relative to the scene file.
  std::string resolve(Fields& fields, const std::string& key, const std::string& path) const {
    std::string resolved = path;
    const std::string token = "${data_dir}";
    for (size_t at; (at = resolved.find(token)) != std::string::npos;) {
      if (dataDir.empty())
        fields.fail(key, "uses ${data_dir} but data_dir is not set; pass --set data_dir=DIR");
      resolved.replace(at, token.size(), dataDir);
    }
    fs::path file(resolved);
    if (file.is_relative()) file = baseDir / file;
    std::error_code error;
    if (!fs::exists(file, error))
      fields.fail(key, (error ? "cannot open: " + error.message() + ": " : "no such file: ") +
                           file.string());
    return file.lexically_normal().string();
  }
};

btQuaternion readRotation(Fields& fields) {
  if (fields.has("quaternion")) {
    const Json* q = fields.raw("quaternion");
    if (!q->is_array() || q->size() != 4 ||
        !std::all_of(q->begin(), q->end(), [](const Json& v) { return v.is_number(); }))
      fields.fail("quaternion", "expected [x, y, z, w], got " + scene::describe(*q));
    btQuaternion rotation(btScalar((*q)[0].get<double>()), btScalar((*q)[1].get<double>()),
                          btScalar((*q)[2].get<double>()), btScalar((*q)[3].get<double>()));
    if (!(rotation.length() > btScalar(1e-6)))
      fields.fail("quaternion", "expected a non-zero quaternion");
    fields.set("quaternion", *q);
    return rotation.normalized();
  }
  Fields rotation = fields.object("rotation");
  const btVector3 axis = rotation.vector3("axis", btVector3(0, 0, 1));
  const double angle = rotation.number("angle_deg", 0, -kInf, kInf);
  fields.set("rotation", rotation.finish());
  if (axis.length() <= 0) {
    if (angle != 0)
      throw InputError(fields.source(), fields.pathOf("rotation.axis"), "expected a non-zero axis");
    return btQuaternion::getIdentity();
  }
  return btQuaternion(axis.normalized(), btScalar(angle * kDegrees));
}

/// {"translation": [..], "rotation": {"axis", "angle_deg"}} or {.., "quaternion": [x,y,z,w]}.
btTransform readTransform(Fields& fields, double scale) {
  const btVector3 translation = fields.vector3("translation", btVector3(0, 0, 0)) * btScalar(scale);
  return btTransform(readRotation(fields), translation);
}

/// The angles of a sweep from start to end in steps (the last step may be shorter).
std::vector<double> sweepAngles(double start, double end, double step) {
  std::vector<double> angles;
  const double span = std::abs(end - start);
  const double direction = end >= start ? 1 : -1;
  const int steps = int(std::ceil(span / step - 1e-9));
  for (int k = 0; k < steps; ++k) angles.push_back(start + direction * step * k);
  angles.push_back(end);
  return angles;
}

/// Refuses a pose that turns by a non-finite angle or moves the bone beyond kMaxCoordinate.
void requirePosesWithinWorld(const Fields& motion, const std::string& type,
                             const std::vector<btTransform>& poses) {
  const bool keyframes = type == "keyframes";
  for (size_t p = 0; p < poses.size(); ++p) {
    const btQuaternion q = poses[p].getRotation();
    const bool finite = std::isfinite(double(q.x())) && std::isfinite(double(q.y())) &&
                        std::isfinite(double(q.z())) && std::isfinite(double(q.w()));
    if (!finite || !withinWorld(poses[p].getOrigin()))
      motion.fail(keyframes ? "keyframes[" + std::to_string(p) + "]" : "pivot",
                  "pose " + std::to_string(p) +
                      " moves the bone beyond the world: expected finite angles and "
                      "translations within ±1e6 m");
  }
}

/// The fields of a joint sweep (motion type "sweep") that `--set KEY=VALUE` sets on every sweep.
const std::vector<std::string> kSweepShorthands = {"step_deg", "start_deg", "end_deg", "pivot"};

void readMotion(Fields& motion, const Reader& reader, const TriangleMesh& mesh, BoneMotion& result,
                std::vector<double>& labels) {
  const std::string type = motion.choice("type", "none", {"none", "keyframes", "sweep", "opensim"});
  if (type == "opensim") {
    if (!motion.has("file")) motion.fail("file", "missing: the OpenSim motion (.mot / .sto)");
    const std::string file = reader.resolve(motion, "file", motion.text("file", ""));
    const btVector3 pivot = scene::readSweepPivot(motion, mesh, reader.scale);
    scene::readOpenSimMotion(motion, file, pivot, result, labels);
  } else if (type == "sweep") {
    const btVector3 pivot = scene::readSweepPivot(motion, mesh, reader.scale);
    const btVector3 axis = motion.vector3("axis", btVector3(1, 0, 0));
    if (axis.length() <= 0) motion.fail("axis", "expected a non-zero rotation axis");
    const double start = motion.number("start_deg", 0, -3600, 3600);
    const double end = motion.number("end_deg", 90, -3600, 3600);
    const double step = motion.number("step_deg", 10, 0, 3600, true);
    if (std::abs(end - start) / step > double(scene::kMaxPoses))
      motion.fail("step_deg", "gives more than " + std::to_string(scene::kMaxPoses) + " poses");
    labels = sweepAngles(start, end, step);
    for (double angle : labels) {
      const btTransform rotation(btQuaternion(axis.normalized(), btScalar(angle * kDegrees)));
      result.poses.push_back(scene::turnedAbout(rotation, pivot));
    }
  } else if (type == "keyframes") {
    const btVector3 pivot = scene::readSweepPivot(motion, mesh, reader.scale);
    const Json& frames = motion.array("keyframes");
    if (frames.empty()) motion.fail("keyframes", "expected at least one keyframe");
    Json complete = Json::array();
    for (size_t i = 0; i < frames.size(); ++i) {
      Fields frame(frames[i], motion.pathOf("keyframes") + "[" + std::to_string(i) + "]",
                   motion.source());
      labels.push_back(frame.number("label", double(i), -kInf, kInf));
      result.poses.push_back(scene::turnedAbout(readTransform(frame, reader.scale), pivot));
      complete.push_back(frame.finish());
    }
    motion.set("keyframes", std::move(complete));
  }
  requirePosesWithinWorld(motion, type, result.poses);
}

/// A surface file as a scene names it: its path as written, its units and its repair.
struct MeshFile {
  std::string path;      ///< as written (${data_dir} and relative paths unresolved)
  double scale = 1;      ///< metres per file unit
  SurfaceRepair repair;  ///< welding distance [m] and holes to close
};

/// The fields of a surface read from a file (`scale`: metres per scene unit).
MeshFile readMeshFile(Fields& source, double scale) {
  MeshFile file;
  file.path = source.text("file", "");
  const std::string units = source.choice("units", scale == 1.0 ? "m" : "mm", {"m", "mm"});
  file.scale = units == "mm" ? 1e-3 : 1.0;
  file.repair.weld = source.number("weld", 0, 0, kInf) * scale;
  file.repair.fillHoles = source.integer("fill_holes", 0, 0, 1000);
  return file;
}

TriangleMesh readSurface(Fields& owner, const std::string& key, const Reader& reader,
                         std::optional<scene::Shape>& shape) {
  Fields source = owner.object(key);
  const bool hasFile = source.has("file"), hasGenerator = source.has("generator");
  if (hasFile == hasGenerator)
    owner.fail(key, "expected exactly one of {\"file\": PATH} or {\"generator\": {...}}");
  TriangleMesh mesh;
  if (hasFile) {
    const MeshFile file = readMeshFile(source, reader.scale);
    const std::string path = reader.resolve(source, "file", file.path);
    MeshReport report;
    mesh = loadSurface(path, file.scale, &report, file.repair);
    for (const auto& warning : report.warnings) reader.result->warnings.push_back(warning);
    if (report.weldedVertices + report.droppedTriangles + report.filledHoles > 0)
      reader.result->notes.push_back(path + ": repaired: " + std::to_string(report.weldedVertices) +
                                     " vertices welded, " +
                                     std::to_string(report.droppedTriangles) +
                                     " triangles dropped (degenerate or repeated), " +
                                     std::to_string(report.filledHoles) + " holes closed");
  } else {
    Fields generator = source.object("generator");
    shape = scene::generateShape(generator, reader.scale);
    mesh = shape->mesh;
    source.set("generator", generator.finish());
  }
  owner.set(key, source.finish());
  return mesh;
}

/// The median over the fibres of their length over `resolution` − 1: the step between a
/// fibre's sampled particles [m].
double medianSampleStep(const FibreSet& fibres, int resolution) {
  std::vector<double> steps;
  for (size_t f = 0; f < fibres.fibreCount(); ++f) {
    const auto points = fibres.fibre(f);
    double length = 0;
    for (size_t i = 1; i < points.size(); ++i) length += points[i].distance(points[i - 1]);
    steps.push_back(length / (resolution - 1));
  }
  if (steps.empty()) return 0;
  std::nth_element(steps.begin(), steps.begin() + ptrdiff_t(steps.size() / 2), steps.end());
  return steps[steps.size() / 2];
}

/// Evenly spaced subset of `count` fibres.
FibreSet selectFibres(const FibreSet& all, size_t count) {
  FibreSet subset;
  for (size_t i = 0; i < count; ++i) subset.addFibre(all.fibre(i * all.fibreCount() / count));
  return subset;
}

/// A bone's `spheres` (every key of it is a `--set` shorthand for every bone's).
BoneSphereParameters readSpheres(Fields& spheres, double scale) {
  BoneSphereParameters parameters;
  parameters.thinning = btScalar(spheres.number("thinning", 0, 0, 1));
  parameters.maxRadius = btScalar(spheres.number("max_radius", 0, 0, kInf) * scale);
  return parameters;
}

BoneInput readBone(Fields& bone, size_t index, const Reader& reader, BoneMotion& motion,
                   std::vector<double>& labels) {
  BoneInput input;
  input.name = bone.text("name", "bone" + std::to_string(index), scene::kMaxNameBytes);
  std::optional<scene::Shape> shape;
  TriangleMesh mesh = readSurface(bone, "mesh", reader, shape);
  Fields transform = bone.object("transform");
  const btTransform rest = readTransform(transform, reader.scale);
  bone.set("transform", transform.finish());
  input.mesh = transformed(mesh, rest);
  Fields motionFields = bone.object("motion");
  readMotion(motionFields, reader, input.mesh, motion, labels);
  bone.set("motion", motionFields.finish());
  Fields spheres = bone.object("spheres");
  input.spheres = readSpheres(spheres, reader.scale);
  bone.set("spheres", spheres.finish());
  return input;
}

/// `value` as the shortest decimal that reads back as it (0.1, not 0.10000000149011612 for a
/// float): a default as the complete scene writes it.
double shortestDecimal(btScalar value) {
  char text[64];
  char* end = std::to_chars(text, text + sizeof text, value).ptr;
  const double decimal = std::strtod(std::string(text, end).c_str(), nullptr);
  return btScalar(decimal) == value ? decimal : double(value);
}

/// Reads, in place, each setting a visit…Settings function (Parameters.h, SceneSettings.h) lists
/// from one section of a scene in units of `scale` metres; a setting's value before is its
/// default.
class SettingReader {
 public:
  SettingReader(Fields& fields, double scale) : fields_(fields), scale_(scale) {}

  void operator()(const SettingKey& key, btScalar& value) const {
    const double unit = key.length ? scale_ : 1;
    const double fallback = key.length ? value / unit : shortestDecimal(value);
    value = btScalar(fields_.number(key.name, fallback, key.lowest / unit, key.highest / unit,
                                    key.lowestExcluded) *
                     unit);
  }
  void operator()(const SettingKey& key, int& value) const {
    value = fields_.integer(key.name, value, int(key.lowest), int(key.highest));
  }
  void operator()(const SettingKey& key, uint32_t& value) const {
    const Json* given = fields_.raw(key.name);
    const bool integral = given && (given->is_number_unsigned() ||
                                    (given->is_number_integer() && given->get<long long>() >= 0));
    if (given && (!integral || given->get<unsigned long long>() > key.highest))
      fields_.fail(key.name, "expected an integer in [0, " +
                                 std::to_string(static_cast<unsigned long long>(key.highest)) +
                                 "], got " + scene::describe(*given));
    if (given) value = uint32_t(given->get<unsigned long long>());
    fields_.set(key.name, value);
  }
  void operator()(const SettingKey& key, bool& value) const {
    if (!key.trueName) {
      value = fields_.boolean(key.name, value);
      return;
    }
    value = fields_.choice(key.name, value ? key.trueName : key.falseName,
                           {key.trueName, key.falseName}) == key.trueName;
  }
  template <class Enum>
  requires std::is_enum_v<Enum>
  void operator()(const SettingKey& key, Enum& value) const {
    fromString(fields_.choice(key.name, toString(value), namesOf<Enum>()), value);
  }

  void operator()(const SettingKey& key, const scene::OrAuto& setting) const {
    const Json* given = fields_.raw(key.name);
    if (given ? *given == "auto" : setting.value < 0) {
      setting.value = -1;
      fields_.set(key.name, "auto");
    } else if (!given || given->is_number()) {
      (*this)(key, setting.value);
    } else {
      fields_.fail(key.name, std::string("expected \"auto\" (") + setting.meaning + ") or " +
                                 scene::numberRange(key.lowest, key.highest, key.lowestExcluded) +
                                 ", got " + scene::describe(*given));
    }
  }
  void operator()(const SettingKey& key, const scene::Derived& setting) const {
    if (fields_.has(key.name)) return (*this)(key, setting.value);
    fields_.raw(key.name);
    fields_.set(key.name, nullptr);  // its place: the loader records the value it works out
    setting.value = -1;
  }

 private:
  Fields& fields_;  ///< the section
  double scale_;    ///< metres per scene unit
};

/// A muscle's `fibres` (a file or a generator) into input.fibres, fibreGridColumns (when the
/// scene gives none) and mergeConverging; returns the fibre file's path (empty when generated).
std::string readFibres(Fields& muscle, const Reader& reader, int fibreCount, bool lattice,
                       const std::optional<scene::DeclaredAreas>& declared,
                       const std::optional<scene::Shape>& shape, MuscleInput& input) {
  Fields fibres = muscle.object("fibres");
  const bool hasFile = fibres.has("file"), hasGenerator = fibres.has("generator");
  if (hasFile == hasGenerator)
    muscle.fail("fibres", "expected exactly one of {\"file\": PATH} or {\"generator\": {...}}");
  std::string path;  // empty: generated
  if (hasFile) {
    path = reader.resolve(fibres, "file", fibres.text("file", ""));
    FibreSet all = loadFibres(path, reader.scale);
    if (all.fibreCount() > size_t(fibreCount)) {
      reader.result->warnings.push_back(path + ": using " + std::to_string(fibreCount) + " of " +
                                        std::to_string(all.fibreCount()) +
                                        " fibres, evenly spaced (fibre_count)");
      input.fibres = selectFibres(all, size_t(fibreCount));
    } else {
      if (all.fibreCount() < size_t(fibreCount))
        reader.result->warnings.push_back(path + ": has " + std::to_string(all.fibreCount()) +
                                          " fibres, fewer than fibre_count " +
                                          std::to_string(fibreCount) + "; using all");
      input.fibres = std::move(all);
    }
    // Measured fibres converge into tendons as generated ones do (632-1026 pairs
    // closer than 0.5 mm in a real set): near-coincident particles merge whatever the source.
    input.mergeConverging = true;
  } else {
    Fields generator = fibres.object("generator");
    int columns = 0;
    input.mergeConverging =
        scene::generateSurfaceFibres(generator, input.name, input.surface, fibreCount, reader.scale,
                                     *reader.result, input.fibres, declared ? &*declared : nullptr);
    if (!input.mergeConverging)
      input.fibres = scene::generateFibres(generator, shape ? &*shape : nullptr, fibreCount,
                                           lattice, &columns);
    if (input.fibreGridColumns <= 0) input.fibreGridColumns = columns;
    fibres.set("generator", generator.finish());
  }
  muscle.set("fibres", fibres.finish());
  return path;
}

/// The attachment distance of a muscle that gives none [m]: kAttachmentSteps sample steps with
/// declared areas, else kAttachmentDistance.
double fallbackAttachmentDistance(const MuscleInput& input, bool declared) {
  return declared ? kAttachmentSteps * medianSampleStep(input.fibres, input.parameters.resolution)
                  : kAttachmentDistance;
}

/// Refuses fibres that do not form the grid a lattice spring layout needs.
void requireFibreGrid(Fields& muscle, const MuscleInput& input, bool lattice) {
  if (lattice && input.fibreGridColumns <= 0)
    muscle.fail("fibre_grid_columns",
                "the lattice spring layouts need fibres on a grid: set fibre_grid_columns for "
                "fibres from a file, or use a generator");
  if (input.fibreGridColumns > 0 && input.fibres.fibreCount() % input.fibreGridColumns != 0)
    muscle.fail("fibre_grid_columns", std::to_string(input.fibres.fibreCount()) +
                                          " fibres do not form rows of " +
                                          std::to_string(input.fibreGridColumns));
}

MuscleInput readMuscle(Fields& muscle, size_t index, const Reader& reader,
                       const SpringParameters& springs) {
  scene::MuscleSection section;
  MuscleInput& input = section.input;
  input.name = muscle.text("name", "muscle" + std::to_string(index), scene::kMaxNameBytes);
  std::optional<scene::Shape> shape;
  input.surface = readSurface(muscle, "surface", reader, shape);
  scene::visitMuscleSettings(section, SettingReader(muscle, reader.scale));
  const std::optional<scene::DeclaredAreas> declared = scene::readDeclaredAttachments(
      muscle, input.name, input.surface, reader.scale, *reader.result, input.attachments);
  input.parameters.springs = springs;
  const bool lattice =
      springs.layout == SpringLayout::Lattice6 || springs.layout == SpringLayout::Lattice26;

  const std::string path =
      readFibres(muscle, reader, section.fibreCount, lattice, declared, shape, input);
  if (input.parameters.attachmentDistance < 0) {
    const double distance = fallbackAttachmentDistance(input, declared.has_value()) / reader.scale;
    input.parameters.attachmentDistance = btScalar(distance * reader.scale);
    muscle.set("attachment_distance", distance);
  }
  if (!path.empty())
    for (auto& warning : checkFibres(input.fibres, input.surface, path,
                                     std::max<double>(input.parameters.attachmentDistance, 1e-3)))
      reader.result->warnings.push_back(std::move(warning));
  requireFibreGrid(muscle, input, lattice);
  return input;
}

/// The "model" section (lengths in units of `scale` metres).
SpringParameters readModel(Fields& model, double scale) {
  SpringParameters springs;
  scene::visitModelSettings(springs, SettingReader(model, scale));
  scene::checkModelSettings(
      springs, [&](const char* key, const std::string& what) { model.fail(key, what); });
  return springs;
}

/// The "simulation" section into `def`, set anew; returns its max_step_deg (the largest bone turn
/// of one step).
double readSimulation(Fields& simulation, double scale, MuscleSystemDef& def) {
  Integrator integrator = MuscleSystemDef{}.integrator;
  fromString(simulation.choice("integrator", toString(integrator), namesOf<Integrator>()),
             integrator);
  def = defaultMuscleSystemDef(integrator);
  visitSimulationSettings(def, SettingReader(simulation, scale));
  const StepSettings& step = def.stepSettings;
  if (step.minTimeStep > step.timeStep)
    simulation.fail("min_dt", "must not exceed dt (" + std::to_string(step.timeStep) + " s)");
  return simulation.number("max_step_deg", 5, 0, 180);
}

/// The "outputs" section.
void readOutputs(Fields& outputs, OutputSettings& settings) {
  settings.frameEvery = outputs.integer("frame_every", 1, 0, 1000000000);
  settings.writeSurfaces = outputs.boolean("surfaces", true);
  settings.writeParticles = outputs.boolean("particles", true);
  settings.writeFibres = outputs.boolean("fibres", true);
  settings.quantiseMm = outputs.number("quantise_mm", 0, 0, 1000);
  settings.quantiseStrain = outputs.number("quantise_strain", 0, 0, 1);
  settings.implicitSurface =
      outputs.choice("surface", "skinned", {"skinned", "implicit"}) == "implicit";
}

void readCollision(Fields& collision, double scale, MuscleSystemDef& def) {
  visitCollisionSettings(def, SettingReader(collision, scale));
}

/// The top-level "analytic" object: which exact case the scene is, and its geometry (a
/// sphere-planes case names its plate among `bones`).
AnalyticCase readAnalytic(Fields& analytic, double scale, const std::vector<BoneInput>& bones) {
  const AnalyticCase defaults;
  AnalyticCase result;
  result.type = analytic.choice("type", defaults.type,
                                {"none", "cylinder-stretch", "cylinder-twist", "sphere-planes"});
  result.axisStart = analytic.vector3("axis_start", defaults.axisStart) * btScalar(scale);
  result.axisEnd = analytic.vector3("axis_end", defaults.axisEnd) * btScalar(scale);
  result.stretch = analytic.number("stretch", defaults.stretch, 0, kInf, true);
  result.twistDeg = analytic.number("twist_deg", defaults.twistDeg, -3600, 3600);
  result.poissonRatio = analytic.number("poisson_ratio", defaults.poissonRatio, 0, 0.4999);
  if (result.type != "none" && result.axisStart.distance(result.axisEnd) <= 0)
    analytic.fail("axis_end", "must differ from axis_start for an analytic case");
  const std::string plate = analytic.text("plate", "");
  for (size_t b = 0; b < bones.size(); ++b)
    if (bones[b].name == plate) result.plateBone = static_cast<int>(b);
  if (result.type == "sphere-planes" && result.plateBone < 0)
    analytic.fail("plate", "must name the bone whose face touches the sphere at axis_end (\"" +
                               plate + "\" is no bone of the scene)");
  return result;
}

/// The scene's bones and their motions into `result` (its pose count and labels from the first
/// multi-pose motion); returns each bone's completed JSON.
Json readBones(Fields& root, Reader& reader, LoadedScene& result) {
  const Json& bones = root.array("bones");
  Json completeBones = Json::array();
  std::set<std::string> names;
  for (size_t i = 0; i < bones.size(); ++i) {
    Fields bone(bones[i], "bones[" + std::to_string(i) + "]", reader.source);
    BoneMotion motion;
    std::vector<double> labels;
    result.bones.push_back(readBone(bone, i, reader, motion, labels));
    if (!names.insert(result.bones.back().name).second)
      bone.fail("name", "\"" + result.bones.back().name + "\" is used by another bone");
    if (motion.poses.size() > 1) {
      if (result.poseCount > 1 && int(motion.poses.size()) != result.poseCount)
        bone.fail("motion", "has " + std::to_string(motion.poses.size()) +
                                " poses but an earlier bone's motion has " +
                                std::to_string(result.poseCount));
      if (result.poseCount <= 1) result.poseLabels = labels;
      result.poseCount = int(motion.poses.size());
    }
    result.motions.push_back(std::move(motion));
    completeBones.push_back(bone.finish());
  }
  // Scenes without a multi-pose motion have one pose, labelled 0.
  if (result.poseLabels.empty()) result.poseLabels = {0};
  return completeBones;
}

/// The scene's blades and their motions into `result` (its pose count and labels from the first
/// blade's when the bones have one pose); returns each blade's completed JSON.
Json readBlades(Fields& root, Reader& reader, LoadedScene& result) {
  const Json& blades = root.array("blades");
  Json completeBlades = Json::array();
  for (size_t i = 0; i < blades.size(); ++i) {
    Fields blade(blades[i], "blades[" + std::to_string(i) + "]", reader.source);
    BladeInput input;
    input.name = blade.text("name", "blade" + std::to_string(i), scene::kMaxNameBytes);
    input.from = blade.vector3("from", btVector3(0, 0, 0)) * btScalar(reader.scale);
    input.to = blade.vector3("to", btVector3(0, 0, 0)) * btScalar(reader.scale);
    if (input.from == input.to) blade.fail("to", "expected an edge of some length: from ≠ to");
    TriangleMesh edge;
    edge.vertices = {input.from, input.to};
    Fields motion = blade.object("motion");
    std::vector<double> labels;
    readMotion(motion, reader, edge, input.motion, labels);
    blade.set("motion", motion.finish());
    const int poses = int(input.motion.poses.size());
    if (poses > 1 && result.poseCount > 1 && poses != result.poseCount)
      blade.fail("motion", "has " + std::to_string(poses) + " poses but the scene has " +
                               std::to_string(result.poseCount));
    if (poses > 1 && result.poseCount <= 1) {
      result.poseCount = poses;
      result.poseLabels = labels;
    }
    result.blades.push_back(std::move(input));
    completeBlades.push_back(blade.finish());
  }
  return completeBlades;
}

/// The scene's muscles into `result`; returns each muscle's completed JSON.
Json readMuscles(Fields& root, Reader& reader, const SpringParameters& springs,
                 LoadedScene& result) {
  const Json& muscles = root.array("muscles");
  Json completeMuscles = Json::array();
  std::set<std::string> names;
  for (size_t i = 0; i < muscles.size(); ++i) {
    Fields muscle(muscles[i], "muscles[" + std::to_string(i) + "]", reader.source);
    result.muscles.push_back(readMuscle(muscle, i, reader, springs));
    if (!names.insert(result.muscles.back().name).second)
      muscle.fail("name", "\"" + result.muscles.back().name + "\" is used by another muscle");
    completeMuscles.push_back(muscle.finish());
  }
  return completeMuscles;
}

/// The top-level fields `--set KEY=VALUE` takes without a path.
const std::vector<std::string> kTopLevelShorthands = {"name", "description", "units", "data_dir"};

LoadedScene readScene(const Json& raw, const std::string& source, const fs::path& baseDir,
                      const std::string& defaultName) {
  LoadedScene result;
  Reader reader;
  reader.source = source;
  reader.baseDir = baseDir;
  reader.result = &result;
  result.source = source;

  Fields root(raw, "", source);
  result.name = root.text("name", defaultName, scene::kMaxNameBytes);
  result.description = root.text("description", "");
  const std::string units = root.choice("units", "m", {"m", "mm"});
  reader.scale = result.unitScale = units == "mm" ? 1e-3 : 1.0;
  reader.dataDir = root.text("data_dir", "");
  if (!reader.dataDir.empty() && fs::path(reader.dataDir).is_relative())
    reader.dataDir = (baseDir / reader.dataDir).lexically_normal().string();

  // The model first: its spring layout decides the fibre patterns of generated muscles.
  Fields model = root.object("model");
  const SpringParameters springs = readModel(model, reader.scale);

  Json completeBones = readBones(root, reader, result);
  Json completeBlades = readBlades(root, reader, result);
  Json completeMuscles = readMuscles(root, reader, springs, result);

  Fields simulation = root.object("simulation");
  const double maxStepDeg = readSimulation(simulation, reader.scale, result.simulation);
  if (result.simulation.stepSettings.stopRule == StopRule::TimeBudget)
    result.warnings.push_back(
        "simulation.stop = budget: each step iterates until its wall-clock budget is spent, so "
        "the results depend on the machine's load and the thread count and are not "
        "bit-identical between runs (the one exception; see docs/reliability.md)");
  const int poses = result.poseCount;
  scene::splitLargeJumps(result, maxStepDeg);
  if (!result.blades.empty() && result.poseCount != poses)
    root.fail("blades",
              "a bone's turn was split into sub-poses, which blades do not follow: "
              "lower the bones' turn per pose below simulation.max_step_deg");
  Fields collision = root.object("collision");
  readCollision(collision, reader.scale, result.simulation);
  Fields outputs = root.object("outputs");
  readOutputs(outputs, result.outputs);
  Fields analytic = root.object("analytic");
  result.analytic = readAnalytic(analytic, reader.scale, result.bones);
  Fields reference = root.object("reference");
  result.reference.contactSliding =
      reference.choice("contact_sliding", result.reference.contactSliding, {"finite", "small"});

  root.set("bones", std::move(completeBones));
  root.set("muscles", std::move(completeMuscles));
  if (!completeBlades.empty()) root.set("blades", std::move(completeBlades));
  root.set("model", model.finish());
  root.set("simulation", simulation.finish());
  root.set("collision", collision.finish());
  root.set("outputs", outputs.finish());
  root.set("analytic", analytic.finish());
  root.set("reference", reference.finish());
  if (root.has("tool")) {  // only a scene with a tool says so: the others' JSON stays as it was
    Fields tool = root.object("tool");
    result.tool = scene::readTool(tool, reader.scale);
    root.set("tool", tool.finish());
  }
  result.json.clear();
  writePretty(root.finish(), 0, result.json);
  return result;
}

std::vector<std::string> builtInSceneNames() {
  std::vector<std::string> names;
  for (const auto& scene : builtInScenes()) names.push_back(scene.name);
  return names;
}

/// The transform of `motion` at `pose` (its last beyond its end; identity without poses).
btTransform poseOf(const BoneMotion& motion, int pose) {
  if (motion.poses.empty()) return btTransform::getIdentity();
  return motion.poses[size_t(std::clamp(pose, 0, int(motion.poses.size()) - 1))];
}

}  // namespace

btTransform LoadedScene::bonePose(size_t bone, int pose) const {
  return bone < motions.size() ? poseOf(motions[bone], pose) : btTransform::getIdentity();
}

btTransform LoadedScene::bladePose(size_t blade, int pose) const {
  return blade < blades.size() ? poseOf(blades[blade].motion, pose) : btTransform::getIdentity();
}

const std::vector<std::string>& solverSettings() {
  static const std::vector<std::string> keys = [] {
    std::vector<std::string> solver = {"integrator"};
    const auto collect = [&](const SettingKey& key, const auto&) {
      if (key.solver) solver.push_back(key.name);
    };
    SpringParameters springs;
    scene::visitModelSettings(springs, collect);
    MuscleSystemDef def;
    visitSimulationSettings(def, collect);
    return solver;
  }();
  return keys;
}

std::string exportBuiltInScene(const std::string& name) {
  if (builtInSceneDefinition(name).empty())
    throw InputError(
        name, "",
        "not a built-in scene (see `fibremss scenes`)" + didYouMean(name, builtInSceneNames()));
  return loadScene(name).json;
}

LoadedScene loadScene(const std::string& nameOrPath, const std::vector<std::string>& overrides) {
  std::string text = builtInSceneDefinition(nameOrPath);
  std::string source = "built-in scene " + nameOrPath;
  fs::path baseDir = fs::current_path();
  std::string defaultName = nameOrPath;
  if (text.empty()) {
    const fs::path path(nameOrPath);
    if (!fs::is_regular_file(path)) {
      const std::vector<std::string> names = builtInSceneNames();
      std::string list;
      for (const auto& name : names) list += (list.empty() ? "" : ", ") + name;
      throw InputError(nameOrPath, "",
                       "neither a built-in scene (" + list + ") nor a readable scene file" +
                           didYouMean(nameOrPath, names));
    }
    std::ifstream in(path, std::ios::binary);
    std::ostringstream content;
    content << in.rdbuf();
    if (!in && !in.eof()) throw InputError(nameOrPath, "", "cannot read the file");
    text = content.str();
    source = nameOrPath;
    baseDir = fs::absolute(path).parent_path();
    defaultName = path.stem().string();
  }
  Json raw = scene::parseJson(text, source);
  scene::applyOverrides(raw, overrides);
  scene::validateSceneJson(raw, source);
  LoadedScene result = readScene(raw, source, baseDir, defaultName);
  if (source.rfind("built-in", 0) == 0) result.source = "built-in";
  return result;
}

namespace scene {

/// The keys a section reader reads, from an empty section (every key at its default).
template <class Read>
std::vector<std::string> keysRead(const char* section, Read read) {
  const Json empty = Json::object();
  Fields fields(empty, section, "the scene reader");
  read(fields);
  std::vector<std::string> keys;
  const Json complete = fields.finish();
  for (const auto& item : complete.items()) keys.push_back(item.key());
  return keys;
}

/// The keys of a muscle's settings (visitMuscleSettings), in their order.
std::vector<std::string> muscleSettingKeys() {
  MuscleSection muscle;
  std::vector<std::string> keys;
  visitMuscleSettings(muscle,
                      [&](const SettingKey& key, const auto&) { keys.push_back(key.name); });
  return keys;
}

std::vector<SectionKeys> shorthandSections() {
  MuscleSystemDef def;
  OutputSettings outputs;
  const auto section = [](const char* name, std::vector<std::string> keys) {
    return SectionKeys{ShorthandTarget::Section, name, std::move(keys)};
  };
  return {
      {ShorthandTarget::TopLevel, "", kTopLevelShorthands},
      {ShorthandTarget::Muscles, "", muscleSettingKeys()},
      {ShorthandTarget::BoneSpheres, "", keysRead("spheres", [](Fields& f) { readSpheres(f, 1); })},
      {ShorthandTarget::Sweeps, "", kSweepShorthands},
      section("model", keysRead("model", [](Fields& f) { readModel(f, 1); })),
      section("simulation", keysRead("simulation", [&](Fields& f) { readSimulation(f, 1, def); })),
      section("collision", keysRead("collision", [&](Fields& f) { readCollision(f, 1, def); })),
      section("outputs", keysRead("outputs", [&](Fields& f) { readOutputs(f, outputs); }))};
}

/// Every key of `value`'s objects, however deep, into `keys`.
void collectKeys(const Json& value, std::set<std::string>& keys) {
  if (value.is_object())
    for (const auto& item : value.items()) keys.insert(item.key());
  if (value.is_structured())
    for (const Json& element : value) collectKeys(element, keys);
}

}  // namespace scene

std::vector<std::string> sceneKeys() {
  std::set<std::string> keys;
  for (const BuiltInScene& builtIn : builtInScenes())
    scene::collectKeys(scene::parseJson(exportBuiltInScene(builtIn.name), builtIn.name), keys);
  for (const scene::SectionKeys& section : scene::shorthandSections())
    keys.insert(section.keys.begin(), section.keys.end());
  for (const std::string& key :
       scene::keysRead("file", [](scene::Fields& file) { readMeshFile(file, 1); }))
    keys.insert(key);
  return {keys.begin(), keys.end()};
}

}  // namespace fibremss
