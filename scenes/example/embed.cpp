// Embedding FibreMSS in a Bullet application: one world holding a FibreMSS muscle, the bones
// it is attached to (kinematic rigid bodies driven by the scene's motion) and a btSoftBody
// falling next to them. Usage: fibremss_embed_example [STEPS]
#include <BulletCollision/BroadphaseCollision/btDbvtBroadphase.h>
#include <BulletDynamics/ConstraintSolver/btSequentialImpulseConstraintSolver.h>
#include <BulletSoftBody/btSoftBodyHelpers.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>

#include <cstdio>
#include <cstdlib>
#include <exception>
#include <memory>
#include <vector>

#include "fibremss/BoneBody.h"
#include "fibremss/MuscleWorld.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"

namespace {

btVector3 centroid(std::span<const btVector3> points) {
  btVector3 sum(0, 0, 0);
  for (const btVector3& p : points) sum += p;
  return points.empty() ? sum : sum / btScalar(points.size());
}

/// The rigid transform a fraction t of the way from a to b.
btTransform between(const btTransform& a, const btTransform& b, btScalar t) {
  return btTransform(a.getRotation().slerp(b.getRotation(), t),
                     a.getOrigin().lerp(b.getOrigin(), t));
}

btVector3 centroid(const btSoftBody& body) {
  btVector3 sum(0, 0, 0);
  for (int i = 0; i < body.m_nodes.size(); ++i) sum += body.m_nodes[i].m_x;
  return sum / btScalar(body.m_nodes.size());
}

}  // namespace

int main(int argc, char** argv) try {
  const int steps = argc > 1 ? std::atoi(argv[1]) : 10;

  // 1. A muscle with its bones: the built-in "fusiform" scene, prepared (particles, springs,
  //    radii, bone spheres). A real application would load its own scene file the same way.
  const fibremss::LoadedScene scene = fibremss::loadScene("fusiform", {"resolution=12"});
  const fibremss::PreparedScene prepared =
      fibremss::prepareScene(scene.bones, scene.muscles, scene.simulation.seed);

  // 2. An ordinary Bullet soft-rigid world, as MuscleWorld: it steps the muscles too.
  btSoftBodyRigidBodyCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher(&configuration);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  fibremss::SimulationParameters parameters = scene.simulation;
  parameters.iterations = 20;  // per world step; enough for a small muscle
  fibremss::MuscleWorld world(&dispatcher, &broadphase, &solver, &configuration, parameters);
  world.setGravity(btVector3(0, btScalar(-9.81), 0));
  world.getWorldInfo().m_gravity = world.getGravity();
  world.getWorldInfo().m_sparsesdf.Initialize();

  // 3. Bones: kinematic bodies with the bones' meshes. 4. The muscle, attached to them.
  std::vector<std::unique_ptr<fibremss::BoneBody>> boneBodies;
  std::vector<fibremss::BoneHandle> bones;
  for (const auto& bone : prepared.bones) {
    boneBodies.push_back(std::make_unique<fibremss::BoneBody>(bone));
    bones.push_back(world.addBone(bone, boneBodies.back()->body()));
  }
  const fibremss::MuscleHandle muscle = world.addMuscle(prepared.muscles.front(), bones);

  // 5. A btSoftBody baseline in the same world: a small ball 5 cm beside the muscle.
  const btVector3 muscleCentre = centroid(world.muscleSystem().positions(muscle));
  btSoftBody* ball = btSoftBodyHelpers::CreateEllipsoid(
      world.getWorldInfo(), muscleCentre + btVector3(0, 0, btScalar(0.05)),
      btVector3(btScalar(0.01), btScalar(0.01), btScalar(0.01)), 64);
  ball->setTotalMass(btScalar(0.05));
  ball->getCollisionShape()->setMargin(btScalar(0.002));  // Bullet's default 0.25 m is huge here
  world.addSoftBody(ball);

  // 6. Step: the bones glide from the first to the last pose of the scene's motion, a little
  //    per step; one Bullet step is one FibreMSS step. Print what moved.
  const int lastPose = scene.poseCount - 1;
  for (int step = 0; step < steps; ++step) {
    const btScalar t = steps > 1 ? btScalar(step) / btScalar(steps - 1) : btScalar(1);
    for (size_t b = 0; b < boneBodies.size(); ++b)
      boneBodies[b]->setTransform(between(scene.bonePose(b, 0), scene.bonePose(b, lastPose), t));
    world.stepSimulation(btScalar(1.0 / 60.0), 0);

    const fibremss::StepStats& stats = world.muscleSystem().lastStep();
    const btVector3 m = centroid(world.muscleSystem().positions(muscle));
    const btVector3 s = centroid(*ball);
    std::printf(
        "step %2d: muscle centre (%.4f %.4f %.4f) m, %d iterations, %zu contacts, %.2f ms; "
        "soft ball centre y %.4f m\n",
        step, m.x(), m.y(), m.z(), stats.iterations, stats.contacts, stats.timing.total, s.y());
    if (stats.nan || stats.exploded) {
      std::fprintf(stderr, "the muscle became unstable at step %d\n", step);
      return 1;
    }
  }

  // 7. Tear down in reverse: muscle and bones leave the world before their bodies are freed.
  world.removeMuscle(muscle);
  for (fibremss::BoneHandle bone : bones) world.removeBone(bone);
  world.removeSoftBody(ball);
  delete ball;
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "fibremss_embed_example: %s\n", e.what());
  return 1;
}
