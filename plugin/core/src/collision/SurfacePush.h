#pragma once
// The surface push (MuscleSystemDef::surfacePush), internal: in a muscle's bone contact, the
// skinned surface vertices near a bone that lie inside its true mesh push their skin particles
// until the vertices reach the mesh's surface (docs/decisions.md, "Bone contact").
#include "CollisionPairs.h"
#include "state/MuscleState.h"

namespace fibremss {

/// Sizes `surface` for `settings` (its skin's vertices and their particles' springs), with the
/// pre-transform rule the skin turns frameless particles by. Allocates.
void prepareSurfacePush(const MuscleSettings& settings, bool blended, PretransformBlend blend,
                        SurfacePushState& surface);

/// After the bone's sphere pairs of one collideMuscleBone call (the bone visit contact.boneVisit;
/// surface.found lists the particles they found): every surface vertex that binds one of them,
/// skinned as deformSurface skins it, that lies inside the bone's true mesh (within its distance
/// from its nearest particle: deeper, that particle is inside and its own push moves it) is to
/// move to the mesh's closest point, d away (world frame). Its free boundary particles, holding
/// weight W of it, each take d / max(W, ½) by their weight w, averaged over the vertices that
/// push them: surface.spread[p] = Σ w·push / Σ w for the surface.spreadCount particles
/// surface.spreadParticles lists (the caller adds them as bone pushes and clears them). Contacts
/// go into `log` (vertex, closest point). No allocation.
void spreadSurfacePush(const MuscleSettings& settings, const ParticleState& particles,
                       SurfacePushState& surface, const BoneState& bone, uint32_t visit,
                       ContactLog& log);

}  // namespace fibremss
