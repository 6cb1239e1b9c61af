#include "fibremss/ToolRun.h"

#include <BulletCollision/CollisionShapes/btSphereShape.h>
#include <BulletDynamics/Dynamics/btRigidBody.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>

#include "fibremss/HapticTool.h"
#include "fibremss/SceneSystem.h"

namespace fibremss {
namespace {

/// The scene's definition with `threads` (≥ 0) in place of its own.
MuscleSystemDef definitionWith(const LoadedScene& scene, int threads) {
  MuscleSystemDef def = scene.simulation;
  if (threads >= 0) def.threads = threads;
  return def;
}

/// A kinematic body of `shape` at `position`.
btRigidBody::btRigidBodyConstructionInfo kinematicInfo(btCollisionShape& shape,
                                                       const btVector3& position) {
  btRigidBody::btRigidBodyConstructionInfo info(0, nullptr, &shape);
  info.m_startWorldTransform.setOrigin(position);
  return info;
}

/// The peak force, the slide's largest jump and the first contact of the recorded ticks.
void measureTicks(const ToolScript& script, ToolRunResult& result) {
  for (size_t t = 0; t < result.ticks.size(); ++t) {
    const btScalar force = result.ticks[t].force.length();
    result.peakForce = std::max(result.peakForce, double(force));
    if (force > 0 && result.firstContact < 0) result.firstContact = int(t) + 1;
    const int tick = int(t) + 1;
    if (t > 0 && script.phase(tick) == "slide" && script.phase(tick - 1) == "slide")
      result.slideJump = std::max(
          result.slideJump, double(result.ticks[t].force.distance(result.ticks[t - 1].force)));
  }
}

}  // namespace

ToolRunResult runTool(const LoadedScene& scene, const PreparedScene& prepared, int threads) {
  const ToolScript& script = scene.tool;
  MuscleSystem system(definitionWith(scene, threads));
  addScene(system, prepared);
  btSphereShape shape(btScalar(script.radius));
  btRigidBody body(kinematicInfo(shape, script.position(0)));
  body.setCollisionFlags(body.getCollisionFlags() | btCollisionObject::CF_KINEMATIC_OBJECT);
  HapticTool tool(system, body, btScalar(script.tickTime),
                  {script.wholeEvery, btScalar(script.regionMargin), btScalar(script.regionDrift)});

  ToolRunResult result;
  result.threads = static_cast<int>(system.threads());
  result.ticks.resize(size_t(script.ticks()));
  btTransform pose = btTransform::getIdentity();
  const auto start = std::chrono::steady_clock::now();
  const std::clock_t cpuStart = std::clock();
  for (size_t t = 0; t < result.ticks.size(); ++t) {
    const int tick = int(t) + 1;
    pose.setOrigin(script.position(tick));
    const ContactWrench wrench = tool.tick(pose);
    result.failed = result.failed || system.lastStep().failed;
    result.ticks[t] = {tick * script.tickTime, pose.getOrigin(), wrench.force, wrench.contacts};
  }
  result.cpuSeconds = double(std::clock() - cpuStart) / CLOCKS_PER_SEC;
  result.wholeTicks = tool.wholeTicks();
  result.iterations = tool.iterations();
  result.wallSeconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  result.ticksPerSecond =
      result.wallSeconds > 0 ? double(result.ticks.size()) / result.wallSeconds : 0;
  measureTicks(script, result);
  return result;
}

std::string ticksCsv(const LoadedScene& scene, const ToolRunResult& result) {
  std::string csv = "tick,time_s,phase,x,y,z,force_x_n,force_y_n,force_z_n,force_n,contacts\n";
  char line[320];
  for (size_t t = 0; t < result.ticks.size(); ++t) {
    const ToolTickRecord& r = result.ticks[t];
    const btVector3 p = r.position / btScalar(scene.unitScale);
    std::snprintf(line, sizeof line, "%zu,%.6g,%s,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%zu\n", t + 1,
                  r.time, scene.tool.phase(int(t) + 1).c_str(), p.x(), p.y(), p.z(), r.force.x(),
                  r.force.y(), r.force.z(), r.force.length(), r.contacts);
    csv += line;
  }
  return csv;
}

}  // namespace fibremss
