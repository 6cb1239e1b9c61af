#pragma once
// Time integrators (method.md §4; docs/integrators.md), internal. One step of an integrator moves
// the free particles of one muscle by dt from the spring forces already in state.forces (computed
// at state.positions before dt was chosen); fixed particles are skipped. Every integrator leaves
// x(t) in `previous`, so eq 5.1 and the collision response (which removes velocity by moving
// `previous`) work for all of them. Multi-stage (RK) and implicit ones evaluate forces at other
// positions with springForces(settings, positions, forces) (SpringForces.h) into buffers of
// their IntegratorWorkspace, made by prepare(); advance() never allocates.
#include <LinearMath/btScalar.h>

#include <memory>
#include <string>

#include "fibremss/Parameters.h"
#include "state/MuscleState.h"

namespace fibremss {

/// What one integration pass measured.
struct IntegrationResult {
  double displacement = 0;    ///< Σ |x_new − x| over free particles [m]
  bool finite = true;         ///< no NaN or inf appeared
  int solverIterations = 0;   ///< implicit integrators: conjugate-gradient iterations run
  double solverResidual = 0;  ///< implicit integrators: final CG residual |r| / |b|
};

class TimeIntegrator {
 public:
  virtual ~TimeIntegrator() = default;
  /// Advances the free particles of `muscle` by dt; `previousDt` is the step that led from
  /// `previous` to `positions`. `def`: the step's solver settings (implicit solves,
  /// constraint passes).
  virtual IntegrationResult advance(const IntegratedMuscle& muscle, const MuscleSystemDef& def,
                                    btScalar dt, btScalar previousDt) const = 0;
  /// Makes the per-muscle scratch (IntegratorState::workspace) this integrator needs for a
  /// muscle's `settings` and `particles` and sets the muscle's stability bound for it
  /// (ParticleState::stableTimeStep); called when the muscle is added and when the integrator
  /// changes, never inside the iterations.
  void prepare(const MuscleSettings& settings, ParticleState& particles,
               IntegratorState& integration) const;
  /// The kind this integrator implements.
  virtual Integrator kind() const = 0;
  /// Whether the integrator keeps explicit velocities (they are rotated by the pre-transform
  /// and zeroed on contact).
  virtual bool usesVelocities() const = 0;
  /// Whether the integrator holds contacts as constraints with `def`
  /// (MuscleSystemDef::persistentContacts; advance() takes a pushed particle's force into its
  /// push out, contactNormal): the response then records its pushes in every iteration and
  /// leaves each contact a slop deep so that it persists (leaveContactSlop).
  virtual bool holdsContacts(const MuscleSystemDef&) const { return false; }
  /// Brings a muscle's `workspace` up to date, without allocating, after springs or volume terms
  /// of its `settings` broke (Tearing.h); an integrator that reads them every iteration needs
  /// nothing.
  virtual void springsChanged(const MuscleSettings&, const ParticleState&,
                              IntegratorWorkspace*) const {}

 protected:
  /// The workspace advance() needs for a muscle (its settings, its particles), or null when it
  /// needs none.
  virtual std::unique_ptr<IntegratorWorkspace> makeWorkspace(const MuscleSettings& settings,
                                                             const ParticleState& particles) const;
};

/// The integrator for a kind (one shared stateless instance per kind; thread-safe: all
/// per-muscle data lives in the muscle's state); InputError for a kind no source registered.
const TimeIntegrator& integratorFor(Integrator kind);

/// The name of a registered kind in scene files and on the command line, or null.
const char* registeredIntegratorName(Integrator kind);

/// The registered kind named `name`; false when none is.
bool registeredIntegratorNamed(const std::string& name, Integrator& kind);

/// Makes `integrator` the one integratorFor returns for its kind, under `name` (toString and
/// fromString of Parameters.h read it). Each integrator's source registers its shared instances
/// with namespace-scope registrations as the library loads, so that adding an integrator is its
/// source and its value in `enum class Integrator`. A kind registered twice stops the program
/// as it loads.
class IntegratorRegistration {
 public:
  IntegratorRegistration(const TimeIntegrator& integrator, const char* name);
};

/// Prepares a muscle for `integrator` unless it already is (TimeIntegrator::prepare).
inline void ensurePrepared(const TimeIntegrator& integrator, const MuscleSettings& settings,
                           ParticleState& particles, IntegratorState& integration) {
  if (!integration.prepared || integration.preparedFor != integrator.kind())
    integrator.prepare(settings, particles, integration);
}

}  // namespace fibremss
