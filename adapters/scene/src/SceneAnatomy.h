#pragma once
// Internal to the scene loader: real-anatomy extensions — fibres generated from a
// muscle surface and its attachment areas ({"generator": {"type": "surface", ...}}), static
// anchor plates for origins without a bone, and a sweep pivot fitted to a femoral head.
#include <memory>
#include <optional>

#include "SceneFields.h"
#include "fibremss/FibreGeneration.h"
#include "fibremss/Geometry.h"
#include "fibremss/Scene.h"

namespace fibremss::scene {

/// An attachment area as a scene gives it (scenes/json/REAL-ANATOMY.md): the fibre generator's
/// area, the bones it names, and whether a static anchor plate stands in for a bone.
struct AreaSpec {
  AttachmentArea area;
  std::vector<uint32_t> bones;  ///< "bone" / "bones": indices into the scene's bones
  std::shared_ptr<const TriangleMesh> boneMesh;  ///< the bone form's mesh (the bones joined)
  bool anchor = false;                           ///< add a static plate beyond the area
  btScalar thickness = 0, gap = 0, margin = 0;   ///< the plate's [m]
};

/// Reads the area object `owner[key]`. `declared`: a muscle-level origin/insertion, which may
/// name the bones its particles are fixed to whatever its form.
AreaSpec readArea(Fields& owner, const std::string& key, double scale, const LoadedScene& scene,
                  bool declared);

/// A muscle's declared origin and insertion (muscle-level fields).
struct DeclaredAreas {
  AreaSpec origin, insertion;
};

/// Reads a muscle's "origin" and "insertion" (both or neither): their surface vertices and
/// bones go to `attachments` (anchor plates added to `scene`). Returns nullopt when neither is
/// given (the nearest-bone rule).
std::optional<DeclaredAreas> readDeclaredAttachments(Fields& muscle, const std::string& muscleName,
                                                     const TriangleMesh& surface, double scale,
                                                     LoadedScene& scene,
                                                     std::vector<DeclaredAttachment>& attachments);

/// When `generator` is {"type": "surface", ...}: generates `count` fibres inside `surface`,
/// adds any anchor bones to `scene` (static, appended after the scene's bones), and returns
/// true. Returns false (reading nothing but "type") for other generator types. With `declared`,
/// its areas are the muscle's (the generator must not give its own).
bool generateSurfaceFibres(Fields& generator, const std::string& muscleName,
                           const TriangleMesh& surface, int count, double scale, LoadedScene& scene,
                           FibreSet& fibres, const DeclaredAreas* declared);

/// A sweep's "pivot": [x, y, z] (scene units), or {"fit": "femoral_head", "up": [0, 0, 1],
/// "depth": 30} — the centre of a sphere fitted to the bone's head (its rest mesh `bone`).
btVector3 readSweepPivot(Fields& motion, const TriangleMesh& bone, double scale);

}  // namespace fibremss::scene
