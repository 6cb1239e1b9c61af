// The reactions of the last response's contacts (MuscleSystem::Impl::addContactReactions): what
// frictionless contacts hold of the particles' forces, per contact pair for two muscles (equal
// and opposite along the pair's normal, Newton's third law) and per particle for a bone (any push
// out of it). Their sizes λ ≥ 0 minimise Σ (|r_i|/k_i)² over the contact particles, r_i the force
// with the reactions added and k_i the force residual's stiffness: projected Gauss–Seidel over
// the contacts in a fixed order, a fixed number of sweeps. Any λ ≥ 0 is a set of forces the
// contacts can supply, so the residual after them bounds the residual of the best set from above.
#include <algorithm>

#include "MuscleSystemImpl.h"

namespace fibremss {
namespace {

/// Sweeps over every contact [1]. An isolated pair or bone contact is exact after one; a particle
/// several contacts press needs more (measured on thigh13 R=20: docs/performance.md,
/// "Distance to equilibrium").
constexpr int kReactionSweeps = 16;

/// 1/k_i² of the residual's equivalent displacement [m²/N²]; 0 for a particle in no term.
btScalar weight(const ResidualState& muscle, uint32_t i) {
  const btScalar k = muscle.residualStiffness[i];
  return k > 0 ? 1 / (k * k) : 0;
}

/// Whether pair task `pair` holds the contacts the muscles' last responses applied (and not a
/// stale collision's).
bool current(const MusclePairTask& pair, const ContactState& a, const ContactState& b) {
  return a.contactRound == pair.roundA && b.contactRound == pair.roundB;
}

/// One Gauss–Seidel update of the reaction λ of muscle contact `c` (i of `a` pushed along +n, j
/// of `b` along −n; kUnpushed: fixed, it takes any force), the forces `fa`, `fb` kept current.
void relaxPair(const MuscleContact& c, const ResidualState& a, const ResidualState& b,
               std::vector<btVector3>& fa, std::vector<btVector3>& fb, btScalar& lambda) {
  const btVector3 n = unitOrZero(c.push);
  if (n.isZero()) return;
  const btScalar wi = c.i == kUnpushed ? 0 : weight(a, c.i);
  const btScalar wj = c.j == kUnpushed ? 0 : weight(b, c.j);
  if (!(wi + wj > 0)) return;
  const btScalar into =
      (c.i == kUnpushed ? 0 : wi * fa[c.i].dot(n)) - (c.j == kUnpushed ? 0 : wj * fb[c.j].dot(n));
  const btScalar next = std::max<btScalar>(0, lambda - into / (wi + wj));
  const btVector3 change = n * (next - lambda);
  lambda = next;
  if (c.i != kUnpushed) fa[c.i] += change;
  if (c.j != kUnpushed) fb[c.j] -= change;
}

/// One Gauss–Seidel update of particle i's bone reaction (along its bone push `push`).
void relaxBone(const btVector3& push, btVector3& force, btScalar& lambda) {
  const btVector3 n = unitOrZero(push);
  if (n.isZero()) return;
  const btScalar next = std::max<btScalar>(0, lambda - force.dot(n));
  force += n * (next - lambda);
  lambda = next;
}

}  // namespace

void MuscleSystem::Impl::addContactReactions(std::vector<btVector3> MuscleState::*forces,
                                             std::span<const uint32_t> slots) {
  boneContacts.clear();
  for (uint32_t slot : slots) {
    MuscleState& muscle = *muscles.states[slot];
    for (uint32_t i : muscle.settings->boundaryParticles) {
      if (muscle.pushRounds[i] != muscle.contactRound || muscle.contactRound == 0 ||
          muscle.lastBonePushes[i].isZero())
        continue;
      if (boneContacts.size() < boneContacts.capacity()) boneContacts.push_back({slot, i, 0});
    }
  }
  std::fill(pairReactions.begin(), pairReactions.end(), btScalar(0));
  for (int sweep = 0; sweep < kReactionSweeps; ++sweep) {
    for (const MusclePairTask& pair : pairTasks) {
      MuscleState& a = *muscles.states[pair.a];
      MuscleState& b = *muscles.states[pair.b];
      if (!current(pair, a, b)) continue;
      const size_t count = std::min(pair.contacts.count, pair.contacts.capacity);
      btScalar* lambda = pairReactions.data() + (pair.contacts.records - pairContacts.data());
      for (size_t k = 0; k < count; ++k)
        relaxPair(pair.contacts.records[k], a, b, a.*forces, b.*forces, lambda[k]);
    }
    for (BoneContact& contact : boneContacts) {
      MuscleState& muscle = *muscles.states[contact.slot];
      relaxBone(muscle.lastBonePushes[contact.particle], (muscle.*forces)[contact.particle],
                contact.reaction);
    }
  }
}

}  // namespace fibremss
