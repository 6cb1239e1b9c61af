// Scene extensions for real anatomy: {"type": "surface"} fibre generators, static anchor
// plates, femoral-head sweep pivots (see SceneAnatomy.h and scenes/README.md).
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>

#include "SceneAnatomy.h"
#include "fibremss/Error.h"
#include "fibremss/FibreGeneration.h"
#include "fibremss/Procedural.h"

namespace fibremss::scene {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

/// A static plate just beyond the area's end along the muscle's main axis, as wide as the
/// area, so that the area's vertices lie within its depth + gap of the plate.
TriangleMesh anchorPlate(const TriangleMesh& surface, const std::vector<uint32_t>& area,
                         btScalar thickness, btScalar gap, btScalar margin) {
  btVector3 centroid(0, 0, 0), areaCentre(0, 0, 0);
  for (const auto& v : surface.vertices) centroid += v;
  centroid /= btScalar(surface.vertices.size());
  for (uint32_t i : area) areaCentre += surface.vertices[i];
  areaCentre /= btScalar(area.size());
  btVector3 axis = areaCentre - centroid;
  axis = axis.length2() > 0 ? axis.normalized() : btVector3(0, 0, 1);
  btScalar far = -std::numeric_limits<btScalar>::infinity();
  for (uint32_t i : area) far = std::max(far, surface.vertices[i].dot(axis));
  // Plate frame: z along the axis.
  btVector3 side = axis.cross(std::abs(axis.x()) < 0.9 ? btVector3(1, 0, 0) : btVector3(0, 1, 0));
  side.normalize();
  const btVector3 up = axis.cross(side);
  btScalar halfSide = 0, halfUp = 0;
  for (uint32_t i : area) {
    const btVector3 d = surface.vertices[i] - areaCentre;
    halfSide = std::max(halfSide, std::abs(d.dot(side)));
    halfUp = std::max(halfUp, std::abs(d.dot(up)));
  }
  const btVector3 centre = areaCentre + axis * (far - areaCentre.dot(axis) + gap + thickness / 2);
  TriangleMesh box =
      makeBox(btVector3(0, 0, 0),
              btVector3(2 * (halfSide + margin), 2 * (halfUp + margin), thickness), {1, 1, 1});
  btMatrix3x3 basis(side.x(), up.x(), axis.x(), side.y(), up.y(), axis.y(), side.z(), up.z(),
                    axis.z());
  return transformed(box, btTransform(basis, centre));
}

/// Index of the bone named `name` in `scene` (bones come before muscles).
uint32_t boneIndex(Fields& fields, const std::string& key, const std::string& name,
                   const LoadedScene& scene) {
  for (size_t b = 0; b < scene.bones.size(); ++b)
    if (scene.bones[b].name == name) return uint32_t(b);
  fields.fail(key, "no bone named \"" + name + "\" (bones come before muscles)");
}

/// The bones an area names: "bone": NAME or "bones": [NAME, ...].
std::vector<uint32_t> readAreaBones(Fields& fields, const LoadedScene& scene) {
  std::vector<uint32_t> bones;
  if (fields.has("bone"))
    bones.push_back(boneIndex(fields, "bone", fields.text("bone", ""), scene));
  if (!fields.has("bones")) return bones;
  if (!bones.empty()) fields.fail("bones", "give \"bone\" or \"bones\", not both");
  const Json& names = fields.array("bones");
  if (names.empty()) fields.fail("bones", "expected at least one bone name");
  for (const Json& name : names) {
    if (!name.is_string()) fields.fail("bones", "expected bone names, got " + describe(name));
    bones.push_back(boneIndex(fields, "bones", name.get<std::string>(), scene));
  }
  fields.set("bones", names);
  return bones;
}

/// The bones' meshes as one mesh (one bone: its mesh).
std::shared_ptr<const TriangleMesh> joinedMeshes(const std::vector<uint32_t>& bones,
                                                 const LoadedScene& scene) {
  auto joined = std::make_shared<TriangleMesh>();
  for (uint32_t b : bones) {
    const TriangleMesh& mesh = scene.bones[b].mesh;
    const auto offset = uint32_t(joined->vertices.size());
    joined->vertices.insert(joined->vertices.end(), mesh.vertices.begin(), mesh.vertices.end());
    for (const auto& t : mesh.triangles)
      joined->triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
  }
  return joined;
}

}  // namespace

AreaSpec readArea(Fields& owner, const std::string& key, double scale, const LoadedScene& scene,
                  bool declared) {
  Fields fields = owner.object(key);
  AreaSpec spec;
  const double mm = 0.001 / scale;  // one millimetre in scene units
  const bool hasLandmarks = fields.has("landmarks"), hasVertices = fields.has("vertices");
  const bool hasEnd = fields.has("end_fraction") || fields.has("end_depth");
  const bool hasBone =
      fields.has("bone") || (fields.has("bones") && !hasLandmarks && !hasVertices && !hasEnd);
  if (int(hasBone) + int(hasLandmarks) + int(hasVertices) > 1)
    fields.fail(hasBone ? "bone" : "landmarks",
                "give one of \"bone\", \"landmarks\" and \"vertices\"");
  spec.bones = readAreaBones(fields, scene);
  if (!declared && !hasBone && !spec.bones.empty())
    fields.fail("bones",
                "only a muscle-level origin or insertion fixes particles to bones; a fibre "
                "generator's area takes bones only as {\"bones\": [...], \"distance\": d}");
  if (hasBone) {
    spec.boneMesh = joinedMeshes(spec.bones, scene);
    spec.area = AttachmentArea::fromBone(
        *spec.boneMesh, btScalar(fields.number("distance", 4 * mm, 0, kInf) * scale));
  } else if (hasLandmarks) {
    const Json& points = fields.array("landmarks");
    if (points.empty()) fields.fail("landmarks", "expected at least one [x, y, z]");
    std::vector<btVector3> landmarks;
    for (size_t i = 0; i < points.size(); ++i)
      landmarks.push_back(readVector3(points[i],
                                      fields.pathOf("landmarks") + "[" + std::to_string(i) + "]",
                                      fields.source()) *
                          btScalar(scale));
    fields.set("landmarks", points);
    spec.area = AttachmentArea::fromLandmarks(
        std::move(landmarks), btScalar(fields.number("radius", 10 * mm, 0, kInf, true) * scale));
  } else if (hasVertices) {
    const Json& indices = fields.array("vertices");
    if (indices.empty()) fields.fail("vertices", "expected at least one surface vertex index");
    std::vector<uint32_t> vertices;
    for (const Json& index : indices) {
      if (!index.is_number_unsigned() || index.get<uint64_t>() > UINT32_MAX)
        fields.fail("vertices",
                    "expected surface vertex indices (integers >= 0), got " + describe(index));
      vertices.push_back(index.get<uint32_t>());
    }
    fields.set("vertices", indices);
    spec.area = AttachmentArea::fromVertices(std::move(vertices));
  } else {
    spec.area.kind = AttachmentArea::Kind::FarEnd;
    spec.area.endFraction = fields.number("end_fraction", 0.06, 0, 1, true);
    spec.area.endDepth = btScalar(fields.number("end_depth", 0, 0, kInf) * scale);
  }
  spec.anchor = fields.boolean("anchor", false);
  if (spec.anchor && !spec.bones.empty())
    fields.fail("anchor",
                "an area on a bone is attached to that bone; anchor needs landmarks, "
                "vertices or the far end");
  if (spec.anchor) {
    spec.thickness = btScalar(fields.number("anchor_thickness", 5 * mm, 0, kInf, true) * scale);
    spec.gap = btScalar(fields.number("anchor_gap", 0.5 * mm, 0, kInf) * scale);
    spec.margin = btScalar(fields.number("anchor_margin", 2 * mm, 0, kInf) * scale);
  }
  owner.set(key, fields.finish());
  return spec;
}

namespace {

uint32_t addAnchor(const AreaSpec& spec, const std::string& name, const TriangleMesh& surface,
                   const std::vector<uint32_t>& area, LoadedScene& scene) {
  BoneInput anchor;
  anchor.name = name;
  anchor.mesh = anchorPlate(surface, area, spec.thickness, spec.gap, spec.margin);
  scene.bones.push_back(std::move(anchor));
  scene.motions.push_back(BoneMotion{});
  return uint32_t(scene.bones.size() - 1);
}

}  // namespace

std::optional<DeclaredAreas> readDeclaredAttachments(Fields& muscle, const std::string& muscleName,
                                                     const TriangleMesh& surface, double scale,
                                                     LoadedScene& scene,
                                                     std::vector<DeclaredAttachment>& attachments) {
  const bool hasOrigin = muscle.has("origin"), hasInsertion = muscle.has("insertion");
  if (!hasOrigin && !hasInsertion) return std::nullopt;
  if (hasOrigin != hasInsertion)
    muscle.fail(hasOrigin ? "insertion" : "origin",
                "declare both origin and insertion (a muscle fixed at one end only would hang)");
  DeclaredAreas areas{readArea(muscle, "origin", scale, scene, true),
                      readArea(muscle, "insertion", scale, scene, true)};
  std::vector<uint32_t> vertices[2];
  resolveAttachmentAreas(surface, areas.origin.area, areas.insertion.area,
                         muscle.source() + ": " + muscle.path(), vertices[0], vertices[1],
                         scene.warnings);
  const char* names[2] = {"origin", "insertion"};
  AreaSpec* specs[2] = {&areas.origin, &areas.insertion};
  for (int a = 0; a < 2; ++a) {
    if (vertices[a].empty()) muscle.fail(names[a], "the area holds no surface vertex");
    std::vector<uint32_t> bones = specs[a]->bones;
    if (specs[a]->anchor)
      bones = {addAnchor(*specs[a], muscleName + "-" + names[a] + "-anchor", surface, vertices[a],
                         scene)};
    if (bones.empty())
      muscle.fail(names[a],
                  "name the bones its particles are fixed to: \"bones\": [NAME, ...] (or "
                  "\"anchor\": true for a static plate)");
    attachments.push_back({names[a], std::move(vertices[a]), std::move(bones)});
    specs[a]->anchor = false;  // the plate exists; the fibre generator must not add another
  }
  return areas;
}

bool generateSurfaceFibres(Fields& generator, const std::string& muscleName,
                           const TriangleMesh& surface, int count, double scale, LoadedScene& scene,
                           FibreSet& fibres, const DeclaredAreas* declared) {
  const Json* type = generator.raw("type");
  if (!type || !type->is_string() || type->get<std::string>() != "surface") return false;
  generator.set("type", "surface");
  auto area = [&](const char* key, const AreaSpec* muscleLevel) {
    if (!muscleLevel) return readArea(generator, key, scale, scene, false);
    if (generator.has(key))
      generator.fail(key, std::string("the muscle declares its ") + key +
                              "; the generator uses it (remove this one)");
    return *muscleLevel;
  };
  const AreaSpec origin = area("origin", declared ? &declared->origin : nullptr);
  const AreaSpec insertion = area("insertion", declared ? &declared->insertion : nullptr);
  FibreGenerationOptions options;
  options.count = count;
  options.grid = generator.integer("grid", options.grid, 8, 400);
  options.maxGrid = generator.integer("max_grid", std::max(options.maxGrid, options.grid), 8, 400);
  options.minShare = generator.number("min_share", options.minShare, 0, 1);
  options.samples = generator.integer("samples", options.samples, 2, 100000);
  FibreGenerationResult result;
  try {
    result = generateFibres(surface, origin.area, insertion.area, options,
                            generator.source() + ": " + generator.path());
  } catch (const InputError& e) {
    generator.fail("type", e.problem());
  }
  for (auto& warning : result.warnings) scene.warnings.push_back(std::move(warning));
  fibres = std::move(result.fibres);
  const std::pair<const AreaSpec*, const std::vector<uint32_t>*> areas[2] = {
      {&origin, &result.originArea}, {&insertion, &result.insertionArea}};
  const char* names[2] = {"origin", "insertion"};
  for (int a = 0; a < 2; ++a)
    if (areas[a].first->anchor)
      addAnchor(*areas[a].first, muscleName + "-" + names[a] + "-anchor", surface, *areas[a].second,
                scene);
  return true;
}

btVector3 readSweepPivot(Fields& motion, const TriangleMesh& bone, double scale) {
  const Json* raw = motion.raw("pivot");
  if (!raw || !raw->is_object())
    return motion.vector3("pivot", btVector3(0, 0, 0)) * btScalar(scale);
  Fields fit(*raw, motion.pathOf("pivot"), motion.source());
  fit.choice("fit", "femoral_head", {"femoral_head"});
  const btVector3 up = fit.vector3("up", btVector3(0, 0, 1));
  const double depth = fit.number("depth", 0.03 / scale, 0, kInf, true);
  if (up.length() <= 0) fit.fail("up", "expected a non-zero direction");
  btVector3 centre;
  btScalar radius;
  if (!fitFemoralHead(bone, up, btScalar(depth * scale), centre, radius))
    fit.fail("fit", "the sphere fit to the bone's head failed (too few vertices within depth)");
  motion.set("pivot", fit.finish());
  return centre;
}

}  // namespace fibremss::scene
