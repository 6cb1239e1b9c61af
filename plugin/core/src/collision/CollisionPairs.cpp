#include "CollisionPairs.h"

#include <LinearMath/btAabbUtil2.h>

#include <algorithm>
#include <cmath>
#include <utility>

#include "SurfacePush.h"
#include "geometry/SurfaceContact.h"

namespace fibremss {
namespace {

/// Steps of the walk back out of a bone along a remembered side before it gives up.
constexpr int kMaxBackOutSteps = 64;

/// Two bones' pushes on one particle oppose when their directions are more than 120° apart.
constexpr btScalar kOpposed = btScalar(-0.5);
/// A caught particle has a way out sideways when the bones' pushes across the gap add up to at
/// least this share of their lengths (an edge or a rounded end of a bone next to it).
constexpr btScalar kWayOut = btScalar(0.05);

void addPush(ContactState& contact, uint32_t i, const btVector3& push) {
  contact.pushes[i] += push;
  ++contact.pushCounts[i];
}

/// addPush of bone `slot`, also summed per bone for the pinch test of applyPushes.
void addBonePush(ContactState& contact, uint32_t i, uint32_t slot, const btVector3& push) {
  addPush(contact, i, push);
  int32_t& first = contact.pinchBones[i];
  if (first < 0) first = static_cast<int32_t>(slot);
  (first == static_cast<int32_t>(slot) ? contact.firstBonePushes[i] : contact.otherBonePushes[i]) +=
      push;
}

/// The response of a particle that bone pushes `a` (first bone) and `b` (the others) press
/// from opposite sides, both overlapping it (no room for its diameter): replaces `push` and
/// returns true; false, `push` unchanged, when they do not oppose. Along the gap's normal it
/// moves half the pushes' sum, which leaves equal overlaps on both sides (the whole sum would
/// swap them, back and forth every iteration); across, it moves out of the gap by their mean
/// depth along what the bones push across (towards a bone's edge or rounded end); muscle pushes
/// count only across the gap, where they cannot drive it into a bone.
bool pinchPush(const btVector3& a, const btVector3& b, btVector3& push) {
  const btScalar la = a.length(), lb = b.length();
  if (la <= 0 || lb <= 0 || a.dot(b) > kOpposed * la * lb) return false;
  const btVector3 normal = (a / la - b / lb).normalized();
  const btVector3 bones = a + b;
  const btScalar along = bones.dot(normal);
  const btVector3 across = bones - normal * along;
  const btVector3 muscles = push - bones;
  push = normal * (along / 2) + (muscles - normal * muscles.dot(normal));
  const btScalar acrossLength = across.length();
  if (acrossLength > kWayOut * (la + lb)) push += across * ((la + lb) / (2 * acrossLength));
  return true;
}

/// What the exact sphere tests read of one muscle, its positions looked up once per pass.
struct PairSpheres {
  const MuscleSettings& settings;  ///< radii [m], fixed particles
  const btVector3* positions;      ///< the muscle's positions [m]

  PairSpheres(const MuscleSettings& muscle, const ParticleState& particles)
      : settings(muscle), positions(particles.positions.data()) {}
};

/// Walks from `local` (bone frame) along the remembered unit `side` until the field clears
/// `radius` with its direction on that side; returns the point reached.
btVector3 backOut(const BoneDistanceField& field, btVector3 local, const btVector3& side,
                  btScalar radius) {
  for (int k = 0; k < kMaxBackOutSteps; ++k) {
    const BoneDistanceField::Sample s = field.sample(local);
    if (s.distance >= radius && s.gradient.dot(side) > 0) break;
    local += side * std::max(std::abs(radius - s.distance), field.cell());
  }
  return local;
}

/// Push (bone frame) of penetration recovery for particle i at `local` with field sample `s`:
/// non-zero only when its side flipped; updates the particle's side memory.
btVector3 recoveryPush(ContactState& contact, uint32_t i, int32_t bone,
                       const BoneDistanceField& field, const btVector3& local,
                       const BoneDistanceField::Sample& s, btScalar radius) {
  int32_t& owner = contact.sideBones[i];
  btVector3& side = contact.boneSides[i];
  uint32_t& stamp = contact.sideStamps[i];
  // Remembered only while the particle stays near the bone from one iteration to the next:
  // away from it (unseen, stale), a particle may go round the bone legitimately.
  const btScalar band = 2 * radius + 2 * field.cell();
  if (owner >= 0 && stamp + 1 < contact.contactRound) owner = -1;
  if (owner == bone) {
    if (s.distance > band) {
      owner = -1;
      return btVector3(0, 0, 0);
    }
    stamp = contact.contactRound;
    if (s.gradient.dot(side) < kFlippedSide) return backOut(field, local, side, radius) - local;
    if (!s.gradient.isZero()) side = s.gradient;
  } else if (owner < 0 && s.distance <= band && !s.gradient.isZero()) {
    owner = bone;
    side = s.gradient;
    stamp = contact.contactRound;
  }
  return btVector3(0, 0, 0);
}

/// collideMuscleBone against the bone's distance field.
void collideWithField(const PairSpheres& muscle, const SphereTree& tree, ContactState& contact,
                      const BoneState& bone, TreeTraversalStack& stack, ContactLog& log) {
  if (tree.empty()) return;
  const MuscleSettings& settings = muscle.settings;
  const btVector3* positions = muscle.positions;
  const BoneDistanceField& field = *bone.field;
  btVector3 lower, upper;
  btTransformAabb(field.lower(), field.upper(), 0, bone.current, lower, upper);
  const btDbvtVolume box = btDbvtVolume::FromMM(lower, upper);
  const btTransform toBone = bone.current.inverse();
  const btMatrix3x3& toWorld = bone.current.getBasis();
  const bool recovery = !contact.sideBones.empty();
  stack.clear();
  stack.push_back({0, -1});
  while (!stack.empty()) {
    const int32_t n = stack.back().first;
    stack.pop_back();
    const btDbvtVolume& bounds = tree.bounds(n);
    if (!boundsOverlap(bounds, box)) continue;
    const SphereTree::Node& node = tree.node(n);
    if (node.sphere < 0) {
      // φ is 1-Lipschitz: a node whose box (spheres included) lies well clear of the bone
      // holds no contact and no particle within its recovery band (twice its radius).
      const btVector3 centre = bounds.Center();
      const btScalar halfDiagonal = bounds.Extents().length();
      if (field.sample(toBone * centre).distance > 3 * halfDiagonal + 2 * field.cell()) continue;
      stack.push_back({node.children[0], -1});
      stack.push_back({node.children[1], -1});
      continue;
    }
    const auto i = static_cast<uint32_t>(node.sphere);
    if (settings.isFixed(i)) continue;
    ++log.candidates;
    const btScalar radius = settings.radii[i];
    const btVector3 local = toBone * positions[i];
    const BoneDistanceField::Sample s = field.sample(local);
    btVector3 push = recovery ? recoveryPush(contact, i, static_cast<int32_t>(bone.slot), field,
                                             local, s, radius)
                              : btVector3(0, 0, 0);
    if (push.isZero() && s.distance < radius) push = s.gradient * (radius - s.distance);
    if (push.isZero()) continue;
    addBonePush(contact, i, bone.slot, toWorld * push);
    log.add(positions[i], positions[i] - toWorld * (s.gradient * s.distance));
  }
}

/// Whether spheres around snapshots `a` and `b` whose radii and reaches add up to `reach` may
/// overlap before either leaves its reach: the fat spheres overlap (a relative 1e-4 more
/// covers the rounding; AABBs alone would list about twice as many pairs).
bool mayMeet(const btVector3& a, const btVector3& b, btScalar reach) {
  reach *= btScalar(1.0001);
  return (a - b).length2() < reach * reach;
}

/// Exact test of particle i of `a` against particle j of `b` (not both fixed): false when apart,
/// else their contact.
bool musclePairContact(const PairSpheres& a, const PairSpheres& b, uint32_t i, uint32_t j,
                       MuscleContact& contact) {
  const MuscleSettings& sa = a.settings;
  const MuscleSettings& sb = b.settings;
  btVector3 direction;
  btScalar depth;
  if (!sphereOverlap(a.positions[i], sa.radii[i], b.positions[j], sb.radii[j], direction, depth))
    return false;
  const bool fixedA = sa.isFixed(i);
  const bool fixedB = sb.isFixed(j);
  const btScalar share = fixedA || fixedB ? 1 : btScalar(0.5);
  contact = {fixedA ? kUnpushed : i, fixedB ? kUnpushed : j, direction * (depth * share)};
  return true;
}

/// Unit normal of `triangle` of `mesh` (outward; zero for a zero-area triangle).
btVector3 faceNormal(const TriangleMesh& mesh, uint32_t triangle) {
  const auto& t = mesh.triangles[triangle];
  const btVector3 normal =
      (mesh.vertices[t[1]] - mesh.vertices[t[0]]).cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]);
  const btScalar length = normal.length();
  return length > 0 ? normal / length : btVector3(0, 0, 0);
}

/// The push (bone frame) that leaves a sphere at `p` (bone frame) with `radius` just touching
/// `mesh`: to the closest mesh point plus the radius along the outward normal, from outside or
/// inside alike; `point` is that closest point. With `sharp` edges, from outside, to the radius in
/// front of the plane of the face at that point that p lies farthest in front of
/// (MeshDistance::frontFace). The closest point is looked for within `reach` first (nothing
/// there: anywhere). False when the sphere clears the mesh. `clearance`: p's distance from the
/// mesh, 0 inside.
bool meshPush(const MeshDistance& mesh, const btVector3& p, btScalar radius, btScalar reach,
              bool sharp, btVector3& push, btVector3& point, btScalar& clearance) {
  MeshDistance::Closest closest = mesh.closest(p, reach);
  if (closest.triangle == UINT32_MAX) closest = mesh.closest(p);
  clearance = closest.inside ? 0 : closest.distance;
  if (closest.triangle == UINT32_MAX || (!closest.inside && closest.distance >= radius))
    return false;
  point = closest.point;
  if (sharp && !closest.inside) {
    const MeshDistance::Plane face = mesh.frontFace(p, closest);
    if (!face.normal.isZero()) {
      if (face.distance >= radius) return false;
      push = face.normal * (radius - face.distance);
      return true;
    }
  }
  btVector3 normal = faceNormal(mesh.mesh(), closest.triangle);
  if (closest.distance > SIMD_EPSILON * radius)
    normal = (p - closest.point) / (closest.inside ? -closest.distance : closest.distance);
  push = point + normal * radius - p;
  return true;
}

/// BoneCollision::Mesh and SharpMesh: pushes free particle i, which a bone sphere found, until its
/// sphere just touches the bone's true mesh; once per bone and iteration
/// (ContactState::meshVisits). `reach`: where the closest point is looked for first [m]. With the
/// surface push, lists i as found and pushes only its centre out (radius 0).
void pushOutOfMesh(const PairSpheres& muscle, ContactState& contact, const BoneState& bone,
                   uint32_t i, btScalar reach, ContactLog& log) {
  if (std::exchange(contact.meshVisits[i], contact.boneVisit) == contact.boneVisit) return;
  SurfacePushState& surface = contact.surfacePush;
  const btVector3& position = muscle.positions[i];
  const btScalar radius = surface.enabled() ? 0 : muscle.settings.radii[i];
  btVector3 push, point;
  btScalar clearance;
  const bool pushed = meshPush(bone.mesh->distance, bone.current.invXform(position), radius, reach,
                               bone.sharpEdges, push, point, clearance);
  if (surface.enabled()) {
    surface.found[surface.foundCount++] = i;
    surface.clearances[i] = clearance;
  }
  if (!pushed) return;
  addBonePush(contact, i, bone.slot, bone.current.getBasis() * push);
  log.add(position, bone.current * point);
}

/// Exact test of free particle i of the muscle against the bone's sphere: a push out of the
/// sphere, or with the bone's mesh contact, pushOutOfMesh.
void testBonePair(const PairSpheres& muscle, ContactState& contact, const BoneState& bone,
                  uint32_t i, uint32_t sphere, ContactLog& log) {
  ++log.candidates;
  const btVector3& centre = bone.tree.centre(static_cast<int32_t>(sphere));
  const btVector3& position = muscle.positions[i];
  const btScalar radius = muscle.settings.radii[i];
  btVector3 direction;
  btScalar depth;
  if (!sphereOverlap(position, radius, centre, bone.settings->sphereRadii[sphere], direction,
                     depth))
    return;
  if (bone.meshContact) {
    // A sphere's centre lies inside its bone: the mesh crosses the way to it.
    pushOutOfMesh(muscle, contact, bone, i, (position - centre).length() + radius, log);
    return;
  }
  addBonePush(contact, i, bone.slot, direction * depth);
  log.add(position, centre);
}

/// The surface push of the bone visit that just found its particles (spreadSurfacePush), added
/// as the bone's pushes.
void pushSurface(const MuscleSettings& settings, const ParticleState& particles,
                 ContactState& contact, const BoneState& bone, ContactLog& log) {
  SurfacePushState& surface = contact.surfacePush;
  spreadSurfacePush(settings, particles, surface, bone, contact.boneVisit, log);
  for (size_t k = 0; k < surface.spreadCount; ++k) {
    const uint32_t p = surface.spreadParticles[k];
    addBonePush(contact, p, bone.slot, surface.spread[p]);
    surface.spread[p].setZero();
    surface.spreadWeights[p] = 0;
  }
  surface.foundCount = 0;
}

/// Calls onPair(i, j) for the leaf pairs of two muscle trees (not both particles fixed; nothing
/// when their roots are apart), listing them into `list` if given; `stack` owns the traversal
/// stack.
template <typename OnPair>
void traverseMuscles(const CollidingMuscle& a, const CollidingMuscle& b, TreeTraversalStack& stack,
                     CandidateList* list, OnPair&& onPair) {
  const MuscleSettings& sa = a.settings;
  const MuscleSettings& sb = b.settings;
  const TreeState& ta = a.trees;
  const TreeState& tb = b.trees;
  collideTrees(stack, ta.tree, tb.tree, [&](int32_t sphereA, int32_t sphereB) {
    const auto i = static_cast<uint32_t>(sphereA), j = static_cast<uint32_t>(sphereB);
    if (sa.isFixed(i) && sb.isFixed(j)) return;
    const btScalar reach = sa.radii[i] + sb.radii[j];
    if (list &&
        mayMeet(ta.treeSnapshot[i], tb.treeSnapshot[j], reach + ta.treeReach + tb.treeReach))
      list->add(i, j);
    onPair(i, j);
  });
}

/// Calls onPair(particle, sphere) for every free boundary particle whose leaf bounds overlap a
/// bone sphere's.
template <typename OnPair>
void forBonePairs(TreeTraversalStack& stack, const MuscleSettings& settings, const TreeState& trees,
                  const BoneState& bone, OnPair&& onPair) {
  collideTrees(stack, trees.tree, bone.tree, [&](int32_t particle, int32_t sphere) {
    const auto i = static_cast<uint32_t>(particle);
    if (!settings.isFixed(i)) onPair(i, static_cast<uint32_t>(sphere));
  });
}

/// mayMeet for particle i of the muscle and a sphere of the bone (placed: it holds still).
bool mayMeetBone(const MuscleSettings& settings, const TreeState& trees, const BoneState& bone,
                 uint32_t i, uint32_t sphere) {
  return mayMeet(trees.treeSnapshot[i], bone.tree.centre(static_cast<int32_t>(sphere)),
                 settings.radii[i] + bone.settings->sphereRadii[sphere] + trees.treeReach);
}

/// The candidate-list protocol of one pair of bodies: test(i, j) over the pairs `list` holds for
/// the two keys; else traverse(listing) finds and tests them, listing into `list` unless a tree
/// is tight (moving faster than its skin: refit next iteration, nothing to list for). Returns
/// whether that listing overflowed.
template <typename Test, typename Traverse>
bool testCandidates(CandidateList* list, uint64_t firstKey, uint64_t secondKey, bool tight,
                    Test&& test, Traverse&& traverse) {
  if (list && list->holds(firstKey, secondKey)) {
    for (size_t k = 0; k < list->count; ++k) test(list->pairs[k].first, list->pairs[k].second);
    return false;
  }
  if (tight) list = nullptr;
  if (list) list->start(firstKey, secondKey);
  traverse(list);
  return list && !list->finish();
}

/// A list with room for `pairs` pairs found when the bodies are added and the slack for
/// `particles` boundary particles (kListSlack).
CandidateList sizedList(size_t pairs, size_t particles) {
  CandidateList list;
  list.pairs.resize(kListSlack * pairs + particles / 2);
  return list;
}

}  // namespace

void buildTree(const MuscleSettings& settings, const ParticleState& particles, TreeState& trees,
               bool rebuildEveryStep) {
  trees.treeSkin = kTreeSkin * particles.meanRadius;
  trees.treeReach = trees.treeSkin / 2;
  trees.treeSnapshot = particles.positions;
  trees.tree.build(settings.boundaryParticles, particles.positions, settings.radii, trees.treeReach,
                   rebuildEveryStep);
}

bool refitTree(const MuscleSettings& settings, const ParticleState& particles, TreeState& trees) {
  const std::vector<uint32_t>& boundary = settings.boundaryParticles;
  const std::vector<btVector3>& positions = particles.positions;
  const btScalar half = trees.treeSkin / 2;
  const bool followed = std::exchange(trees.treeFollowed, false);
  btScalar margin = half;
  if (trees.treeReach > 0) {
    // One pass that stops at the first particle out of its skin (moved2: its squared move).
    const btScalar reach2 = trees.treeReach * trees.treeReach;
    btScalar moved2 = 0;
    size_t k = 0;
    for (; k < boundary.size(); ++k) {
      moved2 = (positions[boundary[k]] - trees.treeSnapshot[boundary[k]]).length2();
      if (!(moved2 <= reach2)) break;
    }
    if (k == boundary.size()) return trees.refitStreak = false;
    // Out in two iterations running, or the first one out already past the whole skin:
    // moving faster than a skin pays for (bones moving), so tight bounds, refit every
    // iteration, until it slows down.
    if (trees.refitStreak || moved2 > 4 * half * half) margin = 0;
  } else if (followed && trees.treeMotion > half * half) {
    // Tight and carried on by its bones (faster than the skin when it went tight): bounds at the
    // particles, but no snapshot or move measured, which would only say "moving fast" again
    // until the bones arrive (that iteration takes the snapshot).
    trees.tree.refit(positions, settings.radii);
    ++trees.snapshotSkips;
    return trees.refitStreak = true;
  } else if (trees.treeMotion > half * half) {
    margin = 0;  // still moving more than the skin holds in one iteration
  }
  trees.treeReach = margin;
  const btScalar motion = trees.tree.refit(positions, settings.radii, margin, trees.treeSnapshot);
  // Per iteration: the bones move at a steady pace, so a move over skipped snapshots divides.
  const auto span = static_cast<btScalar>(1 + std::exchange(trees.snapshotSkips, 0));
  trees.treeMotion = motion / (span * span);
  return trees.refitStreak = true;
}

void rebuildTree(const MuscleSettings& settings, const ParticleState& particles, TreeState& trees) {
  for (uint32_t i : settings.boundaryParticles) trees.treeSnapshot[i] = particles.positions[i];
  trees.treeReach = trees.treeSkin / 2;
  trees.refitStreak = false;
  trees.snapshotSkips = 0;
  trees.tree.rebuild(particles.positions, settings.radii, trees.treeReach);
}

CandidateList muscleList(const CollidingMuscle& a, const CollidingMuscle& b) {
  CandidateList counter;
  TreeTraversalStack stack;
  traverseMuscles(a, b, stack, &counter, [](uint32_t, uint32_t) {});
  return sizedList(counter.count, std::min(a.settings.boundaryParticles.size(),
                                           b.settings.boundaryParticles.size()));
}

CandidateList boneList(const MuscleSettings& settings, const TreeState& trees,
                       const BoneState& bone) {
  if (bone.field) return {};
  size_t count = 0;
  TreeTraversalStack stack;
  forBonePairs(stack, settings, trees, bone, [&](uint32_t i, uint32_t sphere) {
    count += mayMeetBone(settings, trees, bone, i, sphere) ? 1 : 0;
  });
  return sizedList(count, settings.boundaryParticles.size());
}

void collideMuscles(const CollidingMuscle& a, const CollidingMuscle& b, CandidateList* list,
                    TreeTraversalStack& stack, ContactLog& log, MuscleContacts& out) {
  out.count = 0;
  out.listOverflowed = false;
  const PairSpheres sa(a.settings, a.particles), sb(b.settings, b.particles);
  const auto test = [&](uint32_t i, uint32_t j) {
    ++log.candidates;
    MuscleContact contact;
    if (!musclePairContact(sa, sb, i, j, contact)) return;
    log.add(sa.positions[i], sb.positions[j]);
    if (out.count < out.capacity) out.records[out.count] = contact;
    ++out.count;
  };
  const TreeState& ta = a.trees;
  const TreeState& tb = b.trees;
  out.listOverflowed = testCandidates(
      list, ta.tree.epoch(), tb.tree.epoch(), ta.treeReach == 0 || tb.treeReach == 0, test,
      [&](CandidateList* listing) { traverseMuscles(a, b, stack, listing, test); });
}

bool pushMuscleContacts(const CollidingMuscle& a, const CollidingMuscle& b, bool onFirst,
                        ContactState& pushed, TreeTraversalStack& stack,
                        const MuscleContacts& contacts) {
  const auto push = [&](const MuscleContact& contact) {
    const uint32_t i = onFirst ? contact.i : contact.j;
    if (i != kUnpushed) addPush(pushed, i, onFirst ? contact.push : -contact.push);
  };
  const bool overflowed = contacts.count > contacts.capacity;
  if (!overflowed) {
    for (size_t k = 0; k < contacts.count; ++k) push(contacts.records[k]);
    return contacts.listOverflowed;
  }
  // Only a traversal overflows (a list that held fits its records): the same one again.
  const PairSpheres sa(a.settings, a.particles), sb(b.settings, b.particles);
  traverseMuscles(a, b, stack, nullptr, [&](uint32_t i, uint32_t j) {
    MuscleContact contact;
    if (musclePairContact(sa, sb, i, j, contact)) push(contact);
  });
  return true;
}

void collideMuscleBone(const MuscleSettings& settings, const ParticleState& particles,
                       TreeState& trees, ContactState& contact, const BoneState& bone,
                       TreeTraversalStack& stack, ContactLog& log) {
  const PairSpheres muscle(settings, particles);
  if (bone.field) {
    collideWithField(muscle, trees.tree, contact, bone, stack, log);
    return;
  }
  if (bone.meshContact) ++contact.boneVisit;
  const auto test = [&](uint32_t i, uint32_t sphere) {
    testBonePair(muscle, contact, bone, i, sphere, log);
  };
  const auto traverse = [&](CandidateList* listing) {
    forBonePairs(stack, settings, trees, bone, [&](uint32_t i, uint32_t sphere) {
      if (listing && mayMeetBone(settings, trees, bone, i, sphere)) listing->add(i, sphere);
      test(i, sphere);
    });
  };
  if (testCandidates(candidateList(trees.boneLists, bone.slot), trees.tree.epoch(),
                     bone.tree.placement(), trees.treeReach == 0, test, traverse))
    ++trees.candidateOverflows;
  if (bone.meshContact && contact.surfacePush.enabled())
    pushSurface(settings, particles, contact, bone, log);
}

void forgetBoneSides(ContactState& contact) {
  std::fill(contact.sideBones.begin(), contact.sideBones.end(), -1);
}

void applyPushes(const MuscleSettings& settings, ParticleState& particles, ContactState& contact,
                 bool hasVelocities, bool sliding) {
  ++contact.contactRound;
  size_t pinched = 0;
  for (uint32_t i : settings.boundaryParticles) {
    if (contact.pushCounts[i] == 0) continue;
    btVector3 push = contact.pushes[i];
    if (contact.pinchBones[i] >= 0) {
      if (pinchPush(contact.firstBonePushes[i], contact.otherBonePushes[i], push)) ++pinched;
      contact.stepBones[i] = std::exchange(contact.pinchBones[i], -1);
      contact.firstBonePushes[i].setZero();
      contact.otherBonePushes[i].setZero();
    }
    const btScalar depth = push.length();
    btVector3& position = particles.positions[i];
    btVector3& previous = particles.previous[i];
    if (sliding && depth > 0) {
      const btVector3 normal = push / depth;
      const btVector3 moved = withoutInto(position - previous, normal);
      position += push;
      previous = position - moved;
      if (hasVelocities) particles.velocities[i] = withoutInto(particles.velocities[i], normal);
    } else {
      position += push;
      previous = position;
      if (hasVelocities) particles.velocities[i].setZero();
    }
    contact.pushes[i].setZero();
    contact.pushCounts[i] = 0;
    contact.pushedLast[i] = 1;
  }
  contact.pinched = pinched;
  contact.pinchedInStep = std::max(contact.pinchedInStep, pinched);
}

void leaveContactSlop(const MuscleSettings& settings, const ContactState& contact,
                      const ResidualState& residual, ParticleState& particles, btScalar slop) {
  for (uint32_t i : settings.boundaryParticles) {
    if (residual.pushRounds[i] != contact.contactRound) continue;
    const btVector3& push = residual.lastPushes[i];
    const btScalar depth = push.length();
    if (!(depth > 0)) continue;
    const btVector3 back = push * (std::min(depth, slop * settings.radii[i]) / depth);
    particles.positions[i] -= back;
    particles.previous[i] -= back;
  }
}

}  // namespace fibremss
