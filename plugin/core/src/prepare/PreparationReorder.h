#pragma once
// Particle order of a prepared muscle (PreparationReorder.cpp), internal: particles along a
// space-filling curve, so that the springs of the force pass and the leaves of the collision
// trees touch nearby memory.
#include <LinearMath/btVector3.h>

#include <cstdint>
#include <span>
#include <vector>

#include "fibremss/MuscleSettings.h"

namespace fibremss::detail {

/// The points' indices along the Morton (Z-order) curve through their bounding cube, 10 bits
/// per axis; points in one cell keep their order.
std::vector<uint32_t> mortonOrder(std::span<const btVector3> points);

/// Renumbers the particles so that new particle k is old particle order[k] (order must be a
/// permutation of the particles) and remaps every particle index in the muscle: springs (a < b,
/// sorted by (a, b) again, laid out again by layoutSprings), boundary and fixed particles
/// (ascending again), fibres and skin bindings. Nothing else changes: the muscle is the same up
/// to the permutation.
void reorderParticles(MuscleSettings& muscle, std::span<const uint32_t> order);

}  // namespace fibremss::detail
