#pragma once
// The integrator families (internal to Integrators*.cpp): each returns its shared instance for a
// kind it implements, or null.
#include "Integrators.h"

namespace fibremss {

/// Verlet, semi-implicit Euler, explicit Euler, RK2, RK4 (IntegratorsExplicit.cpp).
const TimeIntegrator* explicitIntegratorFor(Integrator kind);
/// Implicit Euler, implicit midpoint, BDF2 (IntegratorsImplicit.cpp).
const TimeIntegrator* implicitIntegratorFor(Integrator kind);
/// PBD, XPBD (IntegratorsPositionBased.cpp).
const TimeIntegrator* positionBasedIntegratorFor(Integrator kind);

}  // namespace fibremss
