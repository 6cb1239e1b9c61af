#include "MuscleSystemImpl.h"

namespace fibremss {

void MuscleSystem::debugDraw(btIDebugDraw* drawer, int flags) const {
  if (!drawer) return;
  const btVector3 particleColour(0.8f, 0.2f, 0.2f);
  const btVector3 fixedColour(0.2f, 0.2f, 0.8f);
  const btVector3 springColour(0.6f, 0.6f, 0.6f);
  const btVector3 fibreColour(0.9f, 0.5f, 0.1f);
  const btVector3 boneColour(0.9f, 0.9f, 0.8f);
  const btVector3 contactColour(1, 1, 0);
  for (uint32_t slot : impl_->muscles.order) {
    const MuscleState& state = *impl_->muscles.states[slot];
    const MuscleSettings& s = *state.settings;
    if (flags & kDrawParticles)
      for (uint32_t i : s.boundaryParticles)
        drawer->drawSphere(state.positions[i], s.radii[i],
                           s.isFixed(i) ? fixedColour : particleColour);
    if (flags & kDrawSprings)
      for (const Spring& spring : s.springs)
        drawer->drawLine(state.positions[spring.a], state.positions[spring.b], springColour);
    if (flags & kDrawFibres)
      for (size_t f = 0; f < s.fibreCount(); ++f)
        for (uint32_t k = s.fibreOffsets[f] + 1; k < s.fibreOffsets[f + 1]; ++k)
          drawer->drawLine(state.positions[s.fibreParticles[k - 1]],
                           state.positions[s.fibreParticles[k]], fibreColour);
  }
  if (flags & kDrawBoneSpheres)
    for (uint32_t slot : impl_->bones.order) {
      const BoneState& bone = *impl_->bones.states[slot];
      for (size_t k = 0; k < bone.settings->sphereCentres.size(); ++k)
        drawer->drawSphere(bone.current * bone.settings->sphereCentres[k],
                           bone.settings->sphereRadii[k], boneColour);
    }
  if (flags & kDrawContacts)
    for (size_t c = 0; c < impl_->contacts.stored; ++c)
      drawer->drawLine(impl_->contacts.ends[2 * c], impl_->contacts.ends[2 * c + 1], contactColour);
}

}  // namespace fibremss
