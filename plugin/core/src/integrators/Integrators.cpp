#include "Integrators.h"

#include <array>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <stdexcept>
#include <string>

#include "dynamics/TimeStep.h"
#include "fibremss/Error.h"

namespace fibremss {

void TimeIntegrator::prepare(const MuscleSettings& settings, ParticleState& particles,
                             IntegratorState& integration) const {
  integration.workspace = makeWorkspace(settings, particles);
  particles.stableTimeStep = stableTimeStep(settings, kind());
  integration.preparedFor = kind();
  integration.prepared = true;
}

std::unique_ptr<IntegratorWorkspace> TimeIntegrator::makeWorkspace(const MuscleSettings&,
                                                                   const ParticleState&) const {
  return nullptr;
}

namespace {

/// A registered integrator and its name.
struct Registered {
  const TimeIntegrator* integrator = nullptr;  ///< null: no integrator of this kind
  const char* name = nullptr;                  ///< in scene files and on the command line
};

/// Every kind's registration, indexed by kind (an Integrator's every value).
using IntegratorTable = std::array<Registered, std::numeric_limits<uint8_t>::max() + 1>;

/// The table, made on first use (registrations run as the library loads, in any order).
IntegratorTable& registered() {
  static IntegratorTable table{};
  return table;
}

}  // namespace

IntegratorRegistration::IntegratorRegistration(const TimeIntegrator& integrator, const char* name) {
  Registered& entry = registered()[static_cast<size_t>(integrator.kind())];
  if (entry.integrator) {
    std::fprintf(stderr, "fibremss: integrators %s and %s register the same kind\n", entry.name,
                 name);
    std::abort();
  }
  entry = {&integrator, name};
}

const TimeIntegrator& integratorFor(Integrator kind) {
  const Registered& entry = registered()[static_cast<size_t>(kind)];
  if (!entry.integrator)
    throw InputError("MuscleSystemDef::integrator", toString(kind), "unknown integrator");
  return *entry.integrator;
}

const char* registeredIntegratorName(Integrator kind) {
  return registered()[static_cast<size_t>(kind)].name;
}

bool registeredIntegratorNamed(const std::string& name, Integrator& kind) {
  for (const Registered& entry : registered())
    if (entry.integrator && name == entry.name) {
      kind = entry.integrator->kind();
      return true;
    }
  return false;
}

}  // namespace fibremss
