// MuscleSystem's contact bodies, duration steps and external forces (fibremss/RigidContact.h):
// the stages the step calls (MuscleSystemStep.cpp) and the public calls behind them.
#include <BulletCollision/CollisionDispatch/btCollisionObject.h>

#include <cmath>
#include <string>

#include "MuscleSystemChecks.h"
#include "MuscleSystemImpl.h"
#include "contact/BodyContacts.h"
#include "fibremss/Error.h"
#include "integrators/Integrators.h"

namespace fibremss {
namespace {

/// Traversal stack entries reserved for the wrench query (deeper trees grow it once).
constexpr size_t kQueryStack = 256;

bool finite(const btVector3& v) {
  return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z());
}

}  // namespace

void MuscleSystem::Impl::beginBodyContacts() {
  contactBodies.clear();
  for (const btCollisionObject* body : contactSources) {
    contactBodies.push_back(readContactBody(*body));
    if (duration > 0) moveContactBody(contactBodies.back(), -duration);
  }
  for (uint32_t slot : active) {
    MuscleState& state = *muscles.states[slot];
    prepareInteraction(*state.settings, state, contactBodies.size());
  }
}

void MuscleSystem::Impl::collideBodies(btScalar dt) {
  if (contactBodies.empty()) return;
  // Without muscle or bone collision, collide() refitted no tree.
  if (!definition.muscleMuscle && !definition.muscleBone)
    forEachMuscle("refit", [](MuscleState& state, uint32_t, unsigned) {
      refitTree(*state.settings, state, state);
    });
  if (duration > 0)
    for (ContactBodyState& body : contactBodies) moveContactBody(body, dt);
  const bool velocities = integratorFor(definition.integrator).usesVelocities();
  forEachMuscle("contact bodies", [&](MuscleState& state, uint32_t, unsigned thread) {
    fibremss::collideBodies(*state.settings, state, state, state, state, contactBodies, dt,
                            velocities, definition.contactDamping, scratch[thread].stack);
  });
  // In insertion order: the same sums for every thread count.
  for (size_t k = 0; k < contactBodies.size(); ++k) {
    BodyImpulse sum;
    for (uint32_t slot : muscles.order) {
      const MuscleState& state = *muscles.states[slot];
      if (state.frozen) continue;
      sum.linear += state.bodyImpulses[k].linear;
      sum.angular += state.bodyImpulses[k].angular;
      sum.contacts += state.bodyImpulses[k].contacts;
      sum.support += state.bodyImpulses[k].support;
      sum.stiffness += state.bodyImpulses[k].stiffness;
    }
    ContactBodyState& body = contactBodies[k];
    body.linear += sum.linear * body.inverseMass;
    body.angular += body.inverseInertia * sum.angular;
    body.total.linear += sum.linear;
    body.total.angular += sum.angular;
    body.total.contacts = sum.contacts;
    body.total.support = sum.support;
    body.total.stiffness = sum.stiffness;
  }
}

void MuscleSystem::Impl::endBodyContacts() {
  bodyResults.resize(contactBodies.size());
  const auto time = static_cast<btScalar>(stats.simulatedTime);
  for (size_t k = 0; k < contactBodies.size(); ++k) {
    const BodyImpulse& total = contactBodies[k].total;
    BodyContact& result = bodyResults[k];
    result.impulse = total.linear;
    result.angularImpulse = total.angular;
    result.force = time > 0 ? total.linear / time : btVector3(0, 0, 0);
    result.torque = time > 0 ? total.angular / time : btVector3(0, 0, 0);
    result.contacts = total.contacts;
    result.support = total.support;
    result.supportStiffness = total.stiffness;
    result.transform = contactBodies[k].transform;
  }
}

void MuscleSystem::step(btScalar duration) {
  if (!(duration > 0) || !std::isfinite(duration))
    throw InputError("MuscleSystem::step", "duration",
                     "expected a finite simulated time > 0 s, got " + std::to_string(duration));
  impl_->duration = duration;
  impl_->guardedStep();
  impl_->duration = 0;
}

void MuscleSystem::setContactBodies(std::span<const btCollisionObject* const> bodies) {
  for (size_t k = 0; k < bodies.size(); ++k)
    if (!bodies[k])
      throw InputError("MuscleSystem::setContactBodies", "bodies[" + std::to_string(k) + "]",
                       "expected a collision object, got null");
  Impl& impl = *impl_;
  impl.contactSources.assign(bodies.begin(), bodies.end());
  impl.contactBodies.reserve(bodies.size());
  impl.bodyResults.reserve(bodies.size());
  impl.queryStack.reserve(kQueryStack);
  for (uint32_t slot : impl.muscles.order)
    prepareInteraction(*impl.muscles.states[slot]->settings, *impl.muscles.states[slot],
                       bodies.size());
}

BodyContact MuscleSystem::bodyContact(const btCollisionObject* body) const {
  const Impl& impl = *impl_;
  for (size_t k = 0; k < impl.bodyResults.size(); ++k)
    if (impl.contactBodies[k].body == body) return impl.bodyResults[k];
  return {};
}

ContactWrench MuscleSystem::contactWrench(const btCollisionObject& body,
                                          const btTransform& transform) const {
  if (!finiteTransform(transform))
    throw InputError("MuscleSystem::contactWrench", "transform",
                     "expected a finite transform (the body's pose has NaN or inf)");
  const Impl& impl = *impl_;
  ContactWrench wrench;
  const BodyContact last = bodyContact(&body);
  wrench.force = last.force;
  wrench.torque = last.torque;
  for (uint32_t slot : impl.muscles.order) {
    const MuscleState& state = *impl.muscles.states[slot];
    if (!state.frozen)
      addHookeWrench(state.colliding(), state, body, transform, transform.getOrigin(),
                     impl.queryStack, wrench);
  }
  return wrench;
}

void MuscleSystem::setExternalForce(MuscleHandle muscle, uint32_t particle,
                                    const btVector3& force) {
  MuscleState& state = impl_->muscle(muscle);
  const size_t n = state.settings->particleCount();
  if (particle >= n)
    throw InputError("MuscleSystem::setExternalForce", "particle " + std::to_string(particle),
                     "expected an index below the muscle's " + std::to_string(n) + " particles");
  if (!finite(force))
    throw InputError("MuscleSystem::setExternalForce", "force", "expected finite components");
  if (state.externalForces.empty()) state.externalForces.assign(n, btVector3(0, 0, 0));
  state.externalForces[particle] = force;
}

void MuscleSystem::clearExternalForces(MuscleHandle muscle) {
  MuscleState& state = impl_->muscle(muscle);
  state.externalForces.clear();
  state.externalForces.shrink_to_fit();
}

}  // namespace fibremss
