#include "SurfacePush.h"

#include <LinearMath/btAabbUtil2.h>

#include <algorithm>
#include <utility>

#include "kernels/Skin.h"

namespace fibremss {
namespace {

/// A vertex whose free particles hold less of it than this pushes them as if they held this
/// much: a vertex that mostly follows fixed particles does not throw its free ones far.
constexpr btScalar kLeastFreeWeight = btScalar(0.5);

/// Relative slack of a vertex's depth bound from its particle's clearance (insideMesh) [1].
constexpr btScalar kReachSlack = btScalar(1e-3);

/// CSR lists `offsets` / `items` of the pairs (key, item) `forEach` gives, keys below `keys`,
/// items in the order given.
template <typename ForEach>
void buildLists(size_t keys, std::vector<uint32_t>& offsets, std::vector<uint32_t>& items,
                ForEach&& forEach) {
  offsets.assign(keys + 1, 0);
  forEach([&](uint32_t key, uint32_t) { ++offsets[key + 1]; });
  for (size_t k = 0; k < keys; ++k) offsets[k + 1] += offsets[k];
  items.resize(offsets[keys]);
  std::vector<uint32_t> next(offsets.begin(), offsets.end() - 1);
  forEach([&](uint32_t key, uint32_t item) { items[next[key]++] = item; });
}

/// Particle i's F in bone visit `visit`, computed once per visit.
const btMatrix3x3& deformationOf(const MuscleSettings& settings, const ParticleState& particles,
                                 SurfacePushState& surface, uint32_t i, uint32_t visit) {
  btMatrix3x3& deformation = surface.deformations[i];
  if (std::exchange(surface.frameVisits[i], visit) == visit) return deformation;
  const std::span<const uint32_t> springs(surface.particleSprings.data() + surface.springOffsets[i],
                                          surface.springOffsets[i + 1] - surface.springOffsets[i]);
  deformation = particleDeformation(settings, particles.positions, particles.boneTransforms,
                                    surface.blended, surface.blend, particles.skin, i, springs);
  return deformation;
}

/// Vertex v skinned (deformSurface), and its distance from its nearest particle.
btVector3 skinned(const MuscleSettings& settings, const ParticleState& particles,
                  SurfacePushState& surface, size_t v, uint32_t visit, btScalar& nearest) {
  const size_t n = static_cast<size_t>(settings.skinNeighbours);
  for (size_t j = v * n; j < (v + 1) * n; ++j)
    deformationOf(settings, particles, surface, settings.skinParticles[j], visit);
  const btVector3 vertex = skinnedVertex(settings, particles.positions, surface.deformations, v);
  btScalar nearest2 = SIMD_INFINITY;
  for (size_t j = v * n; j < (v + 1) * n; ++j)
    nearest2 = std::min(nearest2, vertex.distance2(particles.positions[settings.skinParticles[j]]));
  nearest = btSqrt(nearest2);
  return vertex;
}

/// Spreads the push `d` of vertex v over its free boundary particles (spreadSurfacePush).
void spread(const MuscleSettings& settings, SurfacePushState& surface, size_t v,
            const btVector3& d) {
  const size_t n = static_cast<size_t>(settings.skinNeighbours);
  const auto pushes = [&](uint32_t p) { return settings.isBoundary(p) && !settings.isFixed(p); };
  btScalar free = 0;
  for (size_t j = v * n; j < (v + 1) * n; ++j)
    if (pushes(settings.skinParticles[j])) free += settings.skinWeights[j];
  if (!(free > 0)) return;
  const btVector3 push = d / std::max(free, kLeastFreeWeight);
  for (size_t j = v * n; j < (v + 1) * n; ++j) {
    const uint32_t p = settings.skinParticles[j];
    const btScalar w = settings.skinWeights[j];
    if (!pushes(p) || !(w > 0)) continue;
    if (surface.spreadWeights[p] == 0) surface.spreadParticles[surface.spreadCount++] = p;
    surface.spread[p] += push * w;
    surface.spreadWeights[p] += w;
  }
}

/// Whether vertex v, which binds found particle p, lies inside the bone's mesh (`toBone`: world
/// to bone frame): `vertex` skinned, `point` the mesh's closest point (world frame). A vertex out
/// of the mesh's bounds is outside without a query.
bool insideMesh(const MuscleSettings& settings, const ParticleState& particles,
                SurfacePushState& surface, const BoneState& bone, const btTransform& toBone,
                uint32_t p, uint32_t v, uint32_t visit, btVector3& vertex, btVector3& point) {
  btScalar reach;
  vertex = skinned(settings, particles, surface, v, visit, reach);
  // From p, clear of the mesh by its clearance, the way to v crosses the surface no nearer v
  // than |v − p| − clearance: no deeper (≤ 0: in the ball round p the mesh leaves free). With a
  // slack for rounding: the bound is exact where v lies straight behind a face p is in front of.
  const btScalar distance = vertex.distance(particles.positions[p]);
  reach = std::min(reach, distance * (1 + kReachSlack) - surface.clearances[p]);
  if (!(reach > 0)) return false;
  const btVector3 local = toBone * vertex;
  if (!TestPointAgainstAabb2(bone.mesh->lower, bone.mesh->upper, local)) return false;
  const MeshDistance::Closest closest = bone.mesh->distance.closest(local, reach);
  if (!closest.inside) return false;
  point = bone.current * closest.point;
  return true;
}

}  // namespace

void prepareSurfacePush(const MuscleSettings& settings, bool blended, PretransformBlend blend,
                        SurfacePushState& surface) {
  const size_t n = settings.particleCount();
  const size_t neighbours = static_cast<size_t>(settings.skinNeighbours);
  const size_t vertices = settings.restSurface.vertices.size();
  buildLists(n, surface.vertexOffsets, surface.particleVertices, [&](auto&& add) {
    for (size_t j = 0; j < vertices * neighbours; ++j)
      add(settings.skinParticles[j], static_cast<uint32_t>(j / neighbours));
  });
  buildLists(n, surface.springOffsets, surface.particleSprings, [&](auto&& add) {
    for (size_t s = 0; s < settings.springs.size(); ++s) {
      const Spring& spring = settings.springs[s];
      add(spring.a, static_cast<uint32_t>(s));
      if (spring.b != spring.a) add(spring.b, static_cast<uint32_t>(s));
    }
  });
  surface.blended = blended;
  surface.blend = blend;
  surface.found.assign(n, 0);
  surface.clearances.assign(n, 0);
  surface.foundCount = 0;
  surface.vertexVisits.assign(vertices, 0);
  surface.frameVisits.assign(n, 0);
  surface.deformations.assign(n, btMatrix3x3::getIdentity());
  surface.spread.assign(n, btVector3(0, 0, 0));
  surface.spreadWeights.assign(n, 0);
  surface.spreadParticles.assign(n, 0);
  surface.spreadCount = 0;
}

void spreadSurfacePush(const MuscleSettings& settings, const ParticleState& particles,
                       SurfacePushState& surface, const BoneState& bone, uint32_t visit,
                       ContactLog& log) {
  surface.spreadCount = 0;
  const btTransform toBone = bone.current.inverse();
  for (size_t k = 0; k < surface.foundCount; ++k) {
    const uint32_t p = surface.found[k];
    for (uint32_t e = surface.vertexOffsets[p]; e < surface.vertexOffsets[p + 1]; ++e) {
      const uint32_t v = surface.particleVertices[e];
      if (std::exchange(surface.vertexVisits[v], visit) == visit) continue;
      btVector3 vertex, point;
      if (!insideMesh(settings, particles, surface, bone, toBone, p, v, visit, vertex, point))
        continue;
      spread(settings, surface, v, point - vertex);
      log.add(vertex, point);
    }
  }
  for (size_t k = 0; k < surface.spreadCount; ++k) {
    const uint32_t p = surface.spreadParticles[k];
    surface.spread[p] /= surface.spreadWeights[p];
  }
}

}  // namespace fibremss
