#pragma once
// Time integrators (method.md §4), internal. One step of an integrator moves the free particles of
// one muscle by dt from the spring forces already in state.forces (computed at state.positions
// before dt was chosen); fixed particles are skipped. Every integrator leaves x(t) in `previous`,
// so eq 5.1 and the collision response (which zeroes velocity by previous = positions) work for
// all of them. The integrator issue adds more kinds here: multi-stage ones (RK2/4) and implicit
// ones evaluate forces at other positions with springForces(settings, positions, forces, ...)
// (SpringForces.h) into buffers added to MuscleState and allocated when the muscle is added.
#include <LinearMath/btScalar.h>

#include "MuscleState.h"
#include "fibremss/Parameters.h"

namespace fibremss {

/// What one integration pass measured.
struct IntegrationResult {
  double displacement = 0;  ///< Σ |x_new − x| over free particles [m]
  bool finite = true;       ///< no NaN or inf appeared
};

class TimeIntegrator {
 public:
  virtual ~TimeIntegrator() = default;
  /// Advances the free particles of `muscle` by dt; `previousDt` is the step that led from
  /// `previous` to `positions`.
  virtual IntegrationResult advance(MuscleState& muscle, btScalar dt,
                                    btScalar previousDt) const = 0;
  /// Makes the per-muscle scratch (MuscleState::workspace) this integrator needs; called when
  /// the muscle is added and when the integrator changes, never inside the iterations.
  virtual void prepare(MuscleState& muscle) const {
    muscle.workspace.reset();
    muscle.preparedFor = kind();
    muscle.prepared = true;
  }
  /// The kind this integrator implements.
  virtual Integrator kind() const = 0;
  /// Whether the integrator keeps explicit velocities (they are rotated by the pre-transform
  /// and zeroed on contact).
  virtual bool usesVelocities() const = 0;
};

/// The integrator for a kind (one shared stateless instance per kind; thread-safe: all
/// per-muscle data lives in MuscleState).
const TimeIntegrator& integratorFor(Integrator kind);

/// Prepares `muscle` for `integrator` unless it already is.
inline void ensurePrepared(const TimeIntegrator& integrator, MuscleState& muscle) {
  if (!muscle.prepared || muscle.preparedFor != integrator.kind()) integrator.prepare(muscle);
}

}  // namespace fibremss
