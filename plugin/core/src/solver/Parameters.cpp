#include "fibremss/Parameters.h"

#include <array>
#include <utility>

#include "integrators/Integrators.h"

namespace fibremss {
namespace {

template <typename Enum, size_t N>
const char* nameOf(const std::array<std::pair<Enum, const char*>, N>& names, Enum value) {
  for (const auto& [candidate, name] : names)
    if (candidate == value) return name;
  return "unknown";
}

template <typename Enum, size_t N>
bool valueOf(const std::array<std::pair<Enum, const char*>, N>& names, const std::string& name,
             Enum& value) {
  for (const auto& [candidate, candidateName] : names)
    if (name == candidateName) {
      value = candidate;
      return true;
    }
  return false;
}

constexpr std::array<std::pair<SpringLayout, const char*>, 4> kLayouts{{
    {SpringLayout::NearestNeighbours, "nearest"},
    {SpringLayout::Delaunay, "delaunay"},
    {SpringLayout::Lattice6, "lattice6"},
    {SpringLayout::Lattice26, "lattice26"},
}};
constexpr std::array<std::pair<SpringStiffness, const char*>, 2> kStiffnessRules{{
    {SpringStiffness::Volume, "volume"},
    {SpringStiffness::Length, "length"},
}};
constexpr std::array<std::pair<StopRule, const char*>, 6> kStopRules{{
    {StopRule::Iterations, "iterations"},
    {StopRule::Converged, "converged"},
    {StopRule::TimeBudget, "budget"},
    {StopRule::SpringDeviation, "spring-deviation"},
    {StopRule::Equilibrium, "equilibrium"},
    {StopRule::Residual, "residual"},
}};
constexpr std::array<std::pair<BoneCollision, const char*>, 3> kBoneCollisions{{
    {BoneCollision::Spheres, "spheres"},
    {BoneCollision::DistanceField, "distance-field"},
    {BoneCollision::Mesh, "mesh"},
}};
constexpr std::array<std::pair<FailurePolicy, const char*>, 3> kFailurePolicies{{
    {FailurePolicy::Retry, "retry"},
    {FailurePolicy::StopBody, "stop-body"},
    {FailurePolicy::Report, "report"},
}};
constexpr std::array<std::pair<PretransformBlend, const char*>, 2> kPretransformBlends{{
    {PretransformBlend::Linear, "linear"},
    {PretransformBlend::DualQuaternion, "dual_quaternion"},
}};

}  // namespace

const char* toString(SpringLayout layout) {
  return nameOf(kLayouts, layout);
}
const char* toString(SpringStiffness rule) {
  return nameOf(kStiffnessRules, rule);
}
const char* toString(Integrator integrator) {
  const char* name = registeredIntegratorName(integrator);  // each integrator's source names it
  return name ? name : "unknown";
}
const char* toString(StopRule rule) {
  return nameOf(kStopRules, rule);
}
const char* toString(BoneCollision mode) {
  return nameOf(kBoneCollisions, mode);
}
const char* toString(FailurePolicy policy) {
  return nameOf(kFailurePolicies, policy);
}
const char* toString(PretransformBlend blend) {
  return nameOf(kPretransformBlends, blend);
}
bool fromString(const std::string& name, PretransformBlend& blend) {
  return valueOf(kPretransformBlends, name, blend);
}
bool fromString(const std::string& name, BoneCollision& mode) {
  return valueOf(kBoneCollisions, name, mode);
}
bool fromString(const std::string& name, FailurePolicy& policy) {
  return valueOf(kFailurePolicies, name, policy);
}
bool fromString(const std::string& name, SpringLayout& layout) {
  return valueOf(kLayouts, name, layout);
}
bool fromString(const std::string& name, SpringStiffness& rule) {
  return valueOf(kStiffnessRules, name, rule);
}
bool fromString(const std::string& name, Integrator& integrator) {
  return registeredIntegratorNamed(name, integrator);
}
bool fromString(const std::string& name, StopRule& rule) {
  return valueOf(kStopRules, name, rule);
}

}  // namespace fibremss
