// A ball dropped on a muscle, with FibreMSS's core alone (fibremss::core, or `pkg-config
// fibremss`): a box-shaped muscle lying on a bone is built from its surface and fibres in code,
// prepared and added to a Bullet world, and a 20 g ball falls 20 mm onto it. Bodies that fall,
// bounce and rest on muscles want MuscleTime::Dynamic with a time integrator (Verlet): muscles
// and bodies share one clock and exchange momentum, the muscle dents, the ball bounces lower
// than it fell and comes to rest on it. Bullet steps at 240 Hz (four substeps a frame), so that
// the ball moves less than a particle's radius a step.
// Usage: fibremss_drop_ball [STEPS] [pose]. `pose` keeps the library's default coupling,
// MuscleTime::QuasiStaticPose with the projective solver: it stops a body, holds its weight by
// the muscle's static reaction and never throws it, but without friction a ball balanced on the
// crest of this narrow muscle may roll off. Exits 1 if the ball leaves faster than it landed, or
// (Dynamic) is not at rest on the muscle.
#include <BulletCollision/BroadphaseCollision/btDbvtBroadphase.h>
#include <BulletCollision/CollisionShapes/btSphereShape.h>
#include <BulletDynamics/ConstraintSolver/btSequentialImpulseConstraintSolver.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <map>
#include <memory>
#include <vector>

#include "fibremss/BoneBody.h"
#include "fibremss/MuscleWorld.h"
#include "fibremss/Preparation.h"

namespace {

/// A closed box from `low` to `high` [m], its faces split into squares of about `cell`, the
/// triangles facing out.
fibremss::TriangleMesh box(const btVector3& low, const btVector3& high, btScalar cell = 0.002f) {
  int cells[3];
  for (int k = 0; k < 3; ++k) cells[k] = std::max(1, int(std::lround((high[k] - low[k]) / cell)));
  fibremss::TriangleMesh mesh;
  std::map<std::array<int, 3>, uint32_t> index;  // lattice point -> vertex
  const auto vertex = [&](std::array<int, 3> at) {
    const auto [it, added] = index.try_emplace(at, uint32_t(mesh.vertices.size()));
    if (added) {
      btVector3 p;
      for (int k = 0; k < 3; ++k) p[k] = low[k] + (high[k] - low[k]) * btScalar(at[k]) / cells[k];
      mesh.vertices.push_back(p);
    }
    return it->second;
  };
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      for (int i = 0; i < cells[u]; ++i)
        for (int j = 0; j < cells[v]; ++j) {
          uint32_t corner[4];  // (i, j), (i+1, j), (i+1, j+1), (i, j+1)
          for (int c = 0; c < 4; ++c) {
            std::array<int, 3> at{};
            at[axis] = side * cells[axis];
            at[u] = i + (c == 1 || c == 2);
            at[v] = j + (c >= 2);
            corner[c] = vertex(at);
          }
          // e_u x e_v = e_axis: counter-clockwise seen from outside on the high side.
          if (side == 1) {
            mesh.triangles.push_back({corner[0], corner[1], corner[2]});
            mesh.triangles.push_back({corner[0], corner[2], corner[3]});
          } else {
            mesh.triangles.push_back({corner[0], corner[2], corner[1]});
            mesh.triangles.push_back({corner[0], corner[3], corner[2]});
          }
        }
    }
  return mesh;
}

/// A muscle 60 mm long along x with a 16 mm square section, its fibres a 4 x 4 grid of straight
/// lines from end to end; the particles of its lowest row lie on the bone and are fixed to it.
fibremss::MuscleInput boxMuscle() {
  fibremss::MuscleInput muscle;
  muscle.name = "box";
  muscle.surface = box({0, 0, 0}, {0.06f, 0.016f, 0.016f});
  for (int row = 0; row < 4; ++row)
    for (int column = 0; column < 4; ++column) {
      const btScalar y = 0.002f + 0.004f * row, z = 0.002f + 0.004f * column;
      const btVector3 ends[] = {{0, y, z}, {0.06f, y, z}};
      muscle.fibres.addFibre(ends);
    }
  muscle.parameters.resolution = 12;
  return muscle;
}

/// The bone the muscle lies on: a plate under it, its top face the muscle's underside.
std::vector<fibremss::BoneInput> plateBone() {
  return {{"plate", box({-0.01f, -0.006f, -0.01f}, {0.07f, 0, 0.026f}), {}}};
}

}  // namespace

int main(int argc, char** argv) try {
  const int steps = argc > 1 ? std::atoi(argv[1]) : 120;
  const fibremss::PreparedScene prepared = fibremss::prepareScene(plateBone(), {boxMuscle()}, 1);

  // A Bullet world as any application makes one; two-way contact with every rigid body is on by
  // default (fibremss/RigidContact.h).
  btSoftBodyRigidBodyCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher(&configuration);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  const bool dynamic = !(argc > 2 && std::strcmp(argv[2], "pose") == 0);
  fibremss::MuscleSystemDef def;
  if (dynamic) def.integrator = fibremss::Integrator::Verlet;
  fibremss::MuscleWorld world(&dispatcher, &broadphase, &solver, &configuration, def);
  fibremss::WorldCoupling coupling;
  if (dynamic) coupling.time = fibremss::MuscleTime::Dynamic;
  world.setCoupling(coupling);
  world.setGravity(btVector3(0, -9.81f, 0));
  std::vector<std::unique_ptr<fibremss::BoneBody>> boneBodies;
  std::vector<fibremss::BoneHandle> bones;
  for (const auto& bone : prepared.bones) {
    boneBodies.push_back(std::make_unique<fibremss::BoneBody>(bone));
    bones.push_back(world.addBone(bone, boneBodies.back()->body()));
  }
  const fibremss::MuscleHandle muscle = world.addMuscle(prepared.muscles.front(), bones);

  // The ball: 8 mm, 20 g, its lowest point 20 mm above the muscle's middle.
  const btScalar radius = 0.008f, mass = 0.02f;
  btSphereShape shape(radius);
  btVector3 inertia(0, 0, 0);
  shape.calculateLocalInertia(mass, inertia);
  btRigidBody ball(mass, nullptr, &shape, inertia);
  ball.setWorldTransform(
      btTransform(btQuaternion::getIdentity(), btVector3(0.03f, 0.016f + radius + 0.02f, 0.008f)));
  ball.setActivationState(DISABLE_DEACTIVATION);
  world.addRigidBody(&ball);

  btScalar impact = 0, fastestAfter = 0;
  for (int step = 0; step < steps; ++step) {
    const btScalar before = ball.getLinearVelocity().length();
    world.stepSimulation(btScalar(1.0 / 60), 4, btScalar(1.0 / 240));
    const fibremss::BodyContact contact = world.bodyContact(&ball);
    if (contact.contacts > 0 && impact == 0) impact = before;
    if (impact > 0) fastestAfter = std::max(fastestAfter, ball.getLinearVelocity().length());
    std::printf("step %3d: ball bottom %6.2f mm, speed %.3f m/s, %2zu muscle contacts\n", step,
                1000 * (ball.getWorldTransform().getOrigin().y() - radius),
                ball.getLinearVelocity().length(), contact.contacts);
  }
  const btScalar bottom = ball.getWorldTransform().getOrigin().y() - radius;
  const bool resting =
      ball.getLinearVelocity().length() < 0.05f && std::abs(bottom - 0.016f) < 0.003f;
  std::printf("landed at %.3f m/s; fastest after landing %.3f m/s; %s\n", impact, fastestAfter,
              resting ? "at rest on the muscle" : "not at rest on the muscle");

  world.removeRigidBody(&ball);
  world.removeMuscle(muscle);
  for (fibremss::BoneHandle bone : bones) world.removeBone(bone);
  return impact > 0 && fastestAfter <= impact && (resting || !dynamic) ? 0 : 1;
} catch (const std::exception& e) {
  std::fprintf(stderr, "fibremss_drop_ball: %s\n", e.what());
  return 1;
}
