// A ball dropped on a muscle, with FibreMSS's core alone (fibremss::core, or `pkg-config
// fibremss`): a box-shaped muscle lying on a bone is built from its surface and fibres in code,
// prepared and added to a Bullet world, and a 20 g ball falls onto it (20 mm by default). Bodies
// that fall, bounce and rest on muscles want MuscleTime::Dynamic with a time integrator (Verlet):
// muscles and bodies share one clock and exchange momentum, the muscle dents, the contact
// damping takes the impact, the ball bounces lower than it fell and comes to rest on it. Bullet
// steps at 240 Hz (four substeps a frame), so that the ball moves less than a particle's radius a
// step. Usage: fibremss_drop_ball [STEPS] [pose] [--drop MM] [--volume-stiffness V] [--may-leave].
// `pose` keeps the library's default coupling, MuscleTime::QuasiStaticPose with the projective
// solver: it stops a body, holds its weight by the muscle's static reaction and never throws it,
// but without friction a ball balanced on the crest of this narrow muscle may roll off. `--drop`
// is the height of the ball's lowest point above the muscle [mm], `--volume-stiffness` the
// muscle's volume multiple (SpringParameters::volumeStiffness). Exits 1 if the ball never lands,
// passes through the muscle (its lowest point below the muscle's underside while over it), leaves
// with more energy than it was dropped with, or (Dynamic) is not at rest on the muscle at the end
// (with `--may-leave` it may instead have left the muscle over its side: the contact is
// frictionless, and the ball, bouncing on the particles, can be kicked sideways).
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
#include <string>
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

constexpr btScalar kMuscleLength = 0.06f;  ///< the muscle's length along x [m]
constexpr btScalar kMuscleSide = 0.016f;   ///< its width along z and height along y [m]

/// A muscle 60 mm long along x with a 16 mm square section, its fibres a 4 x 4 grid of straight
/// lines from end to end; the particles of its lowest row lie on the bone and are fixed to it.
fibremss::MuscleInput boxMuscle(btScalar volumeStiffness) {
  fibremss::MuscleInput muscle;
  muscle.name = "box";
  muscle.surface = box({0, 0, 0}, {kMuscleLength, kMuscleSide, kMuscleSide});
  for (int row = 0; row < 4; ++row)
    for (int column = 0; column < 4; ++column) {
      const btScalar y = 0.002f + 0.004f * row, z = 0.002f + 0.004f * column;
      const btVector3 ends[] = {{0, y, z}, {kMuscleLength, y, z}};
      muscle.fibres.addFibre(ends);
    }
  muscle.parameters.resolution = 12;
  muscle.parameters.springs.volumeStiffness = volumeStiffness;
  return muscle;
}

/// The bone the muscle lies on: a plate under it, its top face the muscle's underside.
std::vector<fibremss::BoneInput> plateBone() {
  return {{"plate", box({-0.01f, -0.006f, -0.01f}, {0.07f, 0, 0.026f}), {}}};
}

/// What the command line asks for.
struct Options {
  int steps = 120;        ///< frames of 1/60 s
  bool dynamic = true;    ///< MuscleTime::Dynamic with Verlet (else the default coupling)
  btScalar drop = 0.02f;  ///< height of the ball's lowest point above the muscle [m]
  btScalar volumeStiffness = fibremss::SpringParameters{}.volumeStiffness;  ///< multiple [1]
  bool mayLeave = false;  ///< leaving the muscle over its side is no failure
};

Options readOptions(int argc, char** argv) {
  Options options;
  for (int k = 1; k < argc; ++k) {
    const std::string arg = argv[k];
    if (arg == "pose") {
      options.dynamic = false;
    } else if (arg == "--may-leave") {
      options.mayLeave = true;
    } else if ((arg == "--drop" || arg == "--volume-stiffness") && k + 1 < argc) {
      const btScalar value = btScalar(std::atof(argv[++k]));
      (arg == "--drop" ? options.drop : options.volumeStiffness) =
          arg == "--drop" ? value / 1000 : value;
    } else {
      options.steps = std::atoi(argv[k]);
    }
  }
  return options;
}

/// The ball's energy per mass above its rest on the undented muscle (centre at `rest`) that
/// Bullet's integrator (symplectic Euler: v += g·dt, then x += v·dt) conserves exactly in flight:
/// ½·|v − g·dt/2|² − g·(x − rest) [J/kg].
btScalar flightEnergy(const btRigidBody& ball, const btVector3& gravity, btScalar dt,
                      const btVector3& rest) {
  const btVector3 v = ball.getLinearVelocity() - gravity * (dt / 2);
  return v.length2() / 2 - gravity.dot(ball.getWorldTransform().getOrigin() - rest);
}

/// Whether (x, z) of `p` lies over the muscle.
bool overMuscle(const btVector3& p) {
  return p.x() >= 0 && p.x() <= kMuscleLength && p.z() >= 0 && p.z() <= kMuscleSide;
}

}  // namespace

int main(int argc, char** argv) try {
  const Options options = readOptions(argc, argv);
  const fibremss::PreparedScene prepared =
      fibremss::prepareScene(plateBone(), {boxMuscle(options.volumeStiffness)}, 1);

  // A Bullet world as any application makes one; two-way contact with every rigid body is on by
  // default (fibremss/RigidContact.h).
  btSoftBodyRigidBodyCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher(&configuration);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  const bool dynamic = options.dynamic;
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

  // The ball: 8 mm, 20 g, its lowest point `drop` above the muscle's middle.
  const btScalar radius = 0.008f, mass = 0.02f, substep = btScalar(1.0 / 240);
  btSphereShape shape(radius);
  btVector3 inertia(0, 0, 0);
  shape.calculateLocalInertia(mass, inertia);
  btRigidBody ball(mass, nullptr, &shape, inertia);
  const btVector3 rest(kMuscleLength / 2, kMuscleSide + radius, kMuscleSide / 2);
  ball.setWorldTransform(
      btTransform(btQuaternion::getIdentity(), rest + btVector3(0, options.drop, 0)));
  ball.setActivationState(DISABLE_DEACTIVATION);
  world.addRigidBody(&ball);

  const btScalar dropped = flightEnergy(ball, world.getGravity(), substep, rest);
  btScalar impact = 0, fastestAfter = 0, mostEnergy = 0;
  bool through = false;
  for (int step = 0; step < options.steps; ++step) {
    const btScalar before = ball.getLinearVelocity().length();
    world.stepSimulation(btScalar(1.0 / 60), 4, substep);
    const fibremss::BodyContact contact = world.bodyContact(&ball);
    const btVector3& centre = ball.getWorldTransform().getOrigin();
    if (contact.contacts > 0 && impact == 0) impact = before;
    if (impact > 0) {
      fastestAfter = std::max(fastestAfter, ball.getLinearVelocity().length());
      mostEnergy = std::max(mostEnergy, flightEnergy(ball, world.getGravity(), substep, rest));
    }
    through = through || (overMuscle(centre) && centre.y() - radius < 0);
    std::printf("step %3d: ball bottom %6.2f mm, speed %.3f m/s, %2zu muscle contacts\n", step,
                1000 * (centre.y() - radius), ball.getLinearVelocity().length(), contact.contacts);
  }
  const btVector3& centre = ball.getWorldTransform().getOrigin();
  const btScalar bottom = centre.y() - radius;
  const bool resting =
      ball.getLinearVelocity().length() < 0.05f && std::abs(bottom - kMuscleSide) < 0.003f;
  const bool left = !overMuscle(centre);
  // Energy the muscles gave the ball beyond what it fell with: none may (float rounding aside).
  const bool gained = mostEnergy > dropped + 1e-5f * std::abs(dropped);
  const char* outcome = through   ? "passed through the muscle"
                        : resting ? "at rest on the muscle"
                        : left    ? "left the muscle over its side"
                                  : "not at rest on the muscle";
  std::printf(
      "landed at %.3f m/s; fastest after landing %.3f m/s; energy after landing at most %.1f %% of "
      "the drop's; %s%s\n",
      impact, fastestAfter, 100 * mostEnergy / dropped, outcome, gained ? "; gained energy" : "");

  world.removeRigidBody(&ball);
  world.removeMuscle(muscle);
  for (fibremss::BoneHandle bone : bones) world.removeBone(bone);
  const bool landedWell = impact > 0 && !through && !gained;
  if (!dynamic) return landedWell && fastestAfter <= impact ? 0 : 1;
  return landedWell && (resting || (options.mayLeave && left)) ? 0 : 1;
} catch (const std::exception& e) {
  std::fprintf(stderr, "fibremss_drop_ball: %s\n", e.what());
  return 1;
}
