#include "Integrators.h"

#include <stdexcept>
#include <string>

#include "IntegratorsInternal.h"
#include "dynamics/TimeStep.h"
#include "fibremss/Error.h"

namespace fibremss {

void TimeIntegrator::prepare(MuscleState& muscle) const {
  muscle.workspace = makeWorkspace(muscle);
  muscle.stableTimeStep = stableTimeStep(*muscle.settings, kind());
  muscle.preparedFor = kind();
  muscle.prepared = true;
}

std::unique_ptr<IntegratorWorkspace> TimeIntegrator::makeWorkspace(const MuscleState&) const {
  return nullptr;
}

const TimeIntegrator& integratorFor(Integrator kind) {
  if (const TimeIntegrator* integrator = explicitIntegratorFor(kind)) return *integrator;
  if (const TimeIntegrator* integrator = implicitIntegratorFor(kind)) return *integrator;
  if (const TimeIntegrator* integrator = positionBasedIntegratorFor(kind)) return *integrator;
  if (const TimeIntegrator* integrator = projectiveIntegratorFor(kind)) return *integrator;
  throw InputError("MuscleSystemDef::integrator", toString(kind), "unknown integrator");
}

}  // namespace fibremss
