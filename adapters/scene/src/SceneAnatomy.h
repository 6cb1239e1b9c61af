#pragma once
// Internal to the scene loader: real-anatomy extensions (issue 8) — fibres generated from a
// muscle surface and its attachment areas ({"generator": {"type": "surface", ...}}), static
// anchor plates for origins without a bone, and a sweep pivot fitted to a femoral head.
#include "SceneFields.h"
#include "fibremss/Geometry.h"
#include "fibremss/Scene.h"

namespace fibremss::scene {

/// When `generator` is {"type": "surface", ...}: generates `count` fibres inside `surface`,
/// adds any anchor bones to `scene` (static, appended after the scene's bones), and returns
/// true. Returns false (reading nothing but "type") for other generator types.
bool generateSurfaceFibres(Fields& generator, const std::string& muscleName,
                           const TriangleMesh& surface, int count, double scale, LoadedScene& scene,
                           FibreSet& fibres);

/// A sweep's "pivot": [x, y, z] (scene units), or {"fit": "femoral_head", "up": [0, 0, 1],
/// "depth": 30} — the centre of a sphere fitted to the bone's head (its rest mesh `bone`).
btVector3 readSweepPivot(Fields& motion, const TriangleMesh& bone, double scale);

}  // namespace fibremss::scene
