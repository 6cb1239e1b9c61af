#pragma once
// Checks of what an embedder hands the MuscleSystem API (internal): each throws InputError
// naming the call, the body and what was expected, before anything is built from it.
#include <span>
#include <string>

#include "fibremss/Geometry.h"
#include "fibremss/MuscleSettings.h"
#include "fibremss/Parameters.h"

namespace fibremss {

/// Step settings a step can run with: dt finite > 0 (and the adaptive lower clamp too), at least
/// one iteration.
void checkStepSettings(const StepSettings& settings, const char* call);

/// A definition a system can be built with: its step settings (checkStepSettings), a projective
/// history of 0 to kMaxProjectiveHistory pairs, initial noise finite in [0, kMaxCoordinate].
void checkDefinition(const MuscleSystemDef& def, const char* call);

/// Every point finite and within ±kMaxCoordinate (`what`: "particle", "sphere centre", ...).
void checkPoints(std::span<const btVector3> points, const std::string& call,
                 const std::string& what);

/// Every radius finite in [0, kMaxCoordinate].
void checkRadii(std::span<const btScalar> radii, const std::string& call);

/// The local volume terms' fans consistent: fanOffsets from 0 to fanParticles' size with one
/// entry more than fanInverseVolume and fanRestGradient have, each fan 4 to kMaxFanTetrahedra + 3
/// particles of the muscle, the fans sorted by their count (the kernels take them by count).
void checkFans(const MuscleSettings& settings, const std::string& call);

/// Whether the transform's rotation and translation are finite.
bool finiteTransform(const btTransform& transform);

}  // namespace fibremss
