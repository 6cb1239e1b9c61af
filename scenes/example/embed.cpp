// Embedding FibreMSS in a Bullet application: one world holding a FibreMSS muscle, the bones
// it is attached to (kinematic rigid bodies driven by the scene's motion), a btSoftBody
// falling next to them and a rigid ball dropped on the muscle (two-way contact: the muscle dents,
// the ball gets the reaction). Usage: fibremss_embed_example [STEPS] [pose]
// The world runs in MuscleTime::Dynamic: Bullet's dt is the muscles' simulated time, so the ball
// and the muscle share one clock and exchange momentum. `pose` runs the library's default
// instead, the quasi-static pose mode (one muscle pose per Bullet step; see MuscleWorld.h), which
// suits kinematic tools and slow bodies: it stops a thrown ball and holds it, never throws it.
#include <BulletCollision/BroadphaseCollision/btDbvtBroadphase.h>
#include <BulletCollision/CollisionShapes/btSphereShape.h>
#include <BulletDynamics/ConstraintSolver/btSequentialImpulseConstraintSolver.h>
#include <BulletSoftBody/btSoftBodyHelpers.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
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

/// Gravity, the soft-body world info, and what Bullet's dt means to the muscles with two-way
/// contact with the world's rigid bodies (on by default): fibremss/RigidContact.h.
void setUpWorld(fibremss::MuscleWorld& world, bool dynamic) {
  world.setGravity(btVector3(0, btScalar(-9.81), 0));
  world.getWorldInfo().m_gravity = world.getGravity();
  world.getWorldInfo().m_sparsesdf.Initialize();
  fibremss::WorldCoupling coupling;
  coupling.time = dynamic ? fibremss::MuscleTime::Dynamic : fibremss::MuscleTime::QuasiStaticPose;
  world.setCoupling(coupling);
  std::printf("timeStep: %s\n", dynamic ? "dynamic (Bullet's dt is the muscles' simulated time)"
                                        : "quasi-static pose (one muscle step per Bullet step)");
}

/// A btSoftBody ball (1 cm radius, 50 g) at `centre`, added to the world.
btSoftBody* addSoftBall(fibremss::MuscleWorld& world, const btVector3& centre) {
  btSoftBody* ball = btSoftBodyHelpers::CreateEllipsoid(
      world.getWorldInfo(), centre, btVector3(btScalar(0.01), btScalar(0.01), btScalar(0.01)), 64);
  ball->setTotalMass(btScalar(0.05));
  ball->getCollisionShape()->setMargin(btScalar(0.002));  // Bullet's default 0.25 m is huge here
  world.addSoftBody(ball);
  return ball;
}

/// The muscle's belly's half width along z: of the particles within 5 mm of the centre's height
/// [m].
btScalar bellyHalfWidth(std::span<const btVector3> positions, const btVector3& centre) {
  btScalar halfWidth = 0;
  for (const btVector3& p : positions)
    if (std::abs(p.y() - centre.y()) < btScalar(0.005))
      halfWidth = std::max(halfWidth, std::abs(p.z() - centre.z()));
  return halfWidth;
}

/// What moved in a step: the muscle, the soft ball, the rigid ball with what it received in the
/// muscles' step and the haptic query at its pose.
void printStep(int step, fibremss::MuscleWorld& world, fibremss::MuscleHandle muscle,
               const btSoftBody& ball, const btRigidBody& rigidBall) {
  const fibremss::StepStats& stats = world.muscleSystem().lastStep();
  const btVector3 m = centroid(world.muscleSystem().positions(muscle));
  const btVector3 s = centroid(ball);
  const fibremss::BodyContact contact = world.bodyContact(&rigidBall);
  const fibremss::ContactWrench wrench = world.contactWrench(rigidBall);
  std::printf(
      "step %2d: muscle centre (%.4f %.4f %.4f) m, %d iterations, %zu contacts, %.2f ms; "
      "soft ball centre y %.4f m; rigid ball z %.4f m, %zu muscle contacts, force %.4f N, "
      "wrench %.4f N\n",
      step, m.x(), m.y(), m.z(), stats.iterations, stats.contacts, stats.timing.total, s.y(),
      rigidBall.getWorldTransform().getOrigin().z(), contact.contacts, contact.force.z(),
      wrench.force.z());
}

/// Removes the muscle, then its bones, from the world.
void removeMuscleAndBones(fibremss::MuscleWorld& world, fibremss::MuscleHandle muscle,
                          const std::vector<fibremss::BoneHandle>& bones) {
  world.removeMuscle(muscle);
  for (fibremss::BoneHandle bone : bones) world.removeBone(bone);
}

}  // namespace

int main(int argc, char** argv) try {
  const int steps = argc > 1 ? std::atoi(argv[1]) : 10;
  const bool dynamic = !(argc > 2 && std::strcmp(argv[2], "pose") == 0);

  // 1. A muscle with its bones: the built-in "fusiform" scene, prepared (particles, springs,
  //    radii, bone spheres). A real application would load its own scene file the same way.
  //    Springs only, so that 20 iterations per Bullet step suffice: with the volume term (on
  //    by default) a 1/60 s step of the dynamic time mode takes 215 shorter iterations, each
  //    within the term's stable dt.
  const fibremss::LoadedScene scene =
      fibremss::loadScene("fusiform", {"resolution=12", "volume_stiffness=0"});
  const fibremss::PreparedScene prepared = fibremss::prepareScene(
      scene.bones, scene.muscles, scene.simulation.seed, scene.simulation.threads);

  // 2. An ordinary Bullet soft-rigid world, as MuscleWorld: it steps the muscles too.
  btSoftBodyRigidBodyCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher(&configuration);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  fibremss::MuscleSystemDef def = scene.simulation;
  // Dynamic: a time integrator (the default, projective, solves each step's equilibrium).
  if (dynamic) def.integrator = fibremss::Integrator::Verlet;
  def.stepSettings.iterations = 20;  // per world step; enough for a small muscle
  fibremss::MuscleWorld world(&dispatcher, &broadphase, &solver, &configuration, def);
  setUpWorld(world, dynamic);

  // 3. Bones: kinematic bodies with the bones' meshes. 4. The muscle, attached to them. (For a
  //    whole loaded scene, addScene in fibremss/SceneSystem.h does both.)
  std::vector<std::unique_ptr<fibremss::BoneBody>> boneBodies;
  std::vector<fibremss::BoneHandle> bones;
  for (const auto& bone : prepared.bones) {
    boneBodies.push_back(std::make_unique<fibremss::BoneBody>(bone));
    bones.push_back(world.addBone(bone, boneBodies.back()->body()));
  }
  const fibremss::MuscleHandle muscle = world.addMuscle(prepared.muscles.front(), bones);

  // 5. A btSoftBody baseline in the same world: a small ball 5 cm beside the muscle.
  const btVector3 muscleCentre = centroid(world.muscleSystem().positions(muscle));
  btSoftBody* ball = addSoftBall(world, muscleCentre + btVector3(0, 0, btScalar(0.05)));

  // 6. A rigid ball (8 mm, 20 g) thrown at the muscle's belly from 1 cm beside it: it hits the
  //    muscle's particle spheres, dents the muscle and takes the reaction. Any btRigidBody that
  //    is not a bone collides with the muscles: a probe, a hand, a floor.
  const btScalar halfWidth = bellyHalfWidth(world.muscleSystem().positions(muscle), muscleCentre);
  const btScalar ballRadius = btScalar(0.008), ballMass = btScalar(0.02);
  btSphereShape ballShape(ballRadius);
  btVector3 ballInertia(0, 0, 0);
  ballShape.calculateLocalInertia(ballMass, ballInertia);
  btRigidBody rigidBall(ballMass, nullptr, &ballShape, ballInertia);
  rigidBall.setWorldTransform(
      btTransform(btQuaternion::getIdentity(),
                  muscleCentre - btVector3(0, 0, halfWidth + ballRadius + btScalar(0.01))));
  rigidBall.setLinearVelocity(btVector3(0, 0, btScalar(0.6)));
  rigidBall.setActivationState(DISABLE_DEACTIVATION);
  world.addRigidBody(&rigidBall);

  // 7. Step: the bones glide from the first to the last pose of the scene's motion, a little
  //    per step; one Bullet step is one FibreMSS step. Print what moved.
  const int lastPose = scene.poseCount - 1;
  for (int step = 0; step < steps; ++step) {
    const btScalar t = steps > 1 ? btScalar(step) / btScalar(steps - 1) : btScalar(1);
    for (size_t b = 0; b < boneBodies.size(); ++b)
      boneBodies[b]->setTransform(between(scene.bonePose(b, 0), scene.bonePose(b, lastPose), t));
    world.stepSimulation(btScalar(1.0 / 60.0), 0);

    printStep(step, world, muscle, *ball, rigidBall);
    const fibremss::StepStats& stats = world.muscleSystem().lastStep();
    if (stats.nan || stats.exploded) {
      std::fprintf(stderr, "the muscle became unstable at step %d\n", step);
      return 1;
    }
  }

  // 8. Tear down in reverse: bodies, muscle and bones leave the world before they are freed.
  world.removeRigidBody(&rigidBall);
  removeMuscleAndBones(world, muscle, bones);
  world.removeSoftBody(ball);
  delete ball;
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "fibremss_embed_example: %s\n", e.what());
  return 1;
}
