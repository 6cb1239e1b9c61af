// Large jumps between poses split into sub-poses along each bone's screw motion (SceneMotion.h).
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "SceneMotion.h"
#include "fibremss/Error.h"

namespace fibremss::scene {
namespace {

constexpr double kDegrees = M_PI / 180;
constexpr size_t kNotedJumps = 5;  ///< jumps described one by one; the rest are counted

/// The angle of the rotation that takes `from` to `to` [°], in [0, 180].
double turnDegrees(const btTransform& from, const btTransform& to) {
  const btQuaternion q = (to * from.inverse()).getRotation();
  const double w = std::min(1.0, std::abs(double(q.w())));
  return 2 * std::acos(w) / kDegrees;
}

std::string formatNumber(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.4g", value);
  return text;
}

/// Coordinates `fraction` of the way from `from` (empty: rest, all 0) to `to`.
std::vector<double> interpolateCoordinates(const std::vector<double>* from,
                                           const std::vector<double>& to, double fraction) {
  std::vector<double> values(to.size());
  for (size_t c = 0; c < to.size(); ++c) {
    const double start = from ? (*from)[c] : 0.0;
    values[c] = start + (to[c] - start) * fraction;
  }
  return values;
}

/// The largest turn of any moving bone into pose `p` (from rest for the first), the bone, and
/// the sub-poses it is split into.
struct Jump {
  double largest = 0;
  size_t turning = 0;
  size_t parts = 1;
};

Jump largestJump(const LoadedScene& scene, const std::vector<size_t>& moving, int p,
                 double maxStepDeg) {
  Jump jump{0, moving.front(), 1};
  for (size_t b : moving) {
    const double turn = turnDegrees(p == 0 ? btTransform::getIdentity() : scene.bonePose(b, p - 1),
                                    scene.bonePose(b, p));
    if (turn > jump.largest) jump.largest = turn, jump.turning = b;
  }
  // 0.001° of slack: a float rotation of exactly 40° reads back as 40.0001°. Beyond
  // kMaxPoses parts the count only needs to say "too many".
  const double parts = std::ceil((jump.largest - 1e-3) / maxStepDeg);
  jump.parts = size_t(std::clamp(parts, 1.0, double(kMaxPoses + 1)));
  return jump;
}

}  // namespace

btTransform turnedAbout(const btTransform& motion, const btVector3& pivot) {
  return btTransform(btQuaternion::getIdentity(), pivot) * motion *
         btTransform(btQuaternion::getIdentity(), -pivot);
}

btTransform screwInterpolate(const btTransform& from, const btTransform& to, double fraction) {
  const btTransform delta = to * from.inverse();
  btQuaternion q = delta.getRotation();
  if (q.w() < 0) q = -q;  // the shorter way round
  const btVector3 t = delta.getOrigin();
  btVector3 axis(q.x(), q.y(), q.z());
  const double sinHalf = double(axis.length());
  const double angle = 2 * std::atan2(sinHalf, double(q.w()));
  if (sinHalf < 1e-9 || angle < 1e-9)
    return btTransform(btQuaternion::getIdentity(), t * btScalar(fraction)) * from;
  axis /= btScalar(sinHalf);
  // Chasles: the motion is a turn about an axis through `centre` (the point of that axis
  // nearest the origin) plus a slide `along` it; both are taken in proportion.
  const btVector3 along = axis * axis.dot(t);
  const btVector3 across = t - along;
  const btVector3 centre = (across + axis.cross(across) * btScalar(1 / std::tan(angle / 2))) / 2;
  const btQuaternion turn(axis, btScalar(angle * fraction));
  const btTransform step(turn, centre - quatRotate(turn, centre) + along * btScalar(fraction));
  return step * from;
}

void splitLargeJumps(LoadedScene& scene, double maxStepDeg) {
  if (maxStepDeg <= 0) return;
  std::vector<size_t> moving;
  for (size_t b = 0; b < scene.motions.size(); ++b)
    if (!scene.motions[b].poses.empty()) moving.push_back(b);
  if (moving.empty()) return;
  const int poses = std::max(scene.poseCount, 1);
  std::vector<Jump> jumpsTo(static_cast<size_t>(poses));
  size_t total = 0;
  for (int p = 0; p < poses; ++p) {
    jumpsTo[size_t(p)] = largestJump(scene, moving, p, maxStepDeg);
    total += jumpsTo[size_t(p)].parts;
  }
  if (total > kMaxPoses)
    throw InputError(scene.source, "simulation.max_step_deg",
                     "splitting the motion's jumps into turns of at most " +
                         formatNumber(maxStepDeg) + "° gives " + std::to_string(total) +
                         " poses; expected at most " + std::to_string(kMaxPoses) +
                         " (raise max_step_deg, or give fewer poses)");
  std::vector<std::vector<btTransform>> split(scene.motions.size());
  std::vector<std::vector<std::vector<double>>> coordinates(scene.motions.size());
  std::vector<double> labels;
  std::vector<std::string> described;
  size_t jumps = 0, added = 0;
  for (int p = 0; p < poses; ++p) {
    const auto [largest, turning, partCount] = jumpsTo[size_t(p)];
    const int parts = int(partCount);
    const double label = scene.poseLabels[size_t(p)];
    const double previousLabel = scene.poseLabels[size_t(std::max(p - 1, 0))];
    for (int j = 1; j <= parts; ++j) {
      const double fraction = double(j) / parts;
      for (size_t b : moving) {
        const btTransform from = p == 0 ? btTransform::getIdentity() : scene.bonePose(b, p - 1);
        split[b].push_back(j == parts ? scene.bonePose(b, p)
                                      : screwInterpolate(from, scene.bonePose(b, p), fraction));
        const auto& values = scene.motions[b].coordinates;
        if (!values.empty())
          coordinates[b].push_back(interpolateCoordinates(p == 0 ? nullptr : &values[size_t(p - 1)],
                                                          values[size_t(p)], fraction));
      }
      labels.push_back(previousLabel + (label - previousLabel) * fraction);
    }
    if (parts == 1) continue;
    ++jumps;
    added += size_t(parts - 1);
    if (described.size() < kNotedJumps)
      described.push_back("pose " + std::to_string(p) + " (" + poseName(scene, p) + "): bone \"" +
                          scene.bones[turning].name + "\" turns " + formatNumber(largest) +
                          "° from " + (p == 0 ? std::string("rest") : "the previous pose") +
                          ", split into " + std::to_string(parts) + " sub-poses of at most " +
                          formatNumber(maxStepDeg) + "° (simulation.max_step_deg)");
  }
  if (jumps == 0) return;
  for (size_t b : moving) {
    scene.motions[b].poses = std::move(split[b]);
    if (!scene.motions[b].coordinates.empty())
      scene.motions[b].coordinates = std::move(coordinates[b]);
  }
  scene.poseCount = int(labels.size());
  scene.poseLabels = std::move(labels);
  for (auto& note : described) scene.notes.push_back(std::move(note));
  if (jumps > described.size())
    scene.notes.push_back(std::to_string(jumps - described.size()) +
                          " more jumps split the same way");
  scene.notes.push_back(std::to_string(added) +
                        " sub-poses added: " + std::to_string(scene.poseCount) +
                        " poses (simulation steps) in all, so that no bone turns more than " +
                        formatNumber(maxStepDeg) +
                        "° per step (simulation.max_step_deg; 0 keeps the poses as given)");
}

}  // namespace fibremss::scene

namespace fibremss {

std::string poseName(const LoadedScene& scene, int pose) {
  for (const BoneMotion& motion : scene.motions) {
    if (motion.coordinates.size() <= size_t(pose)) continue;
    std::string name;
    for (size_t c = 0; c < motion.coordinateNames.size(); ++c)
      name += (c ? ", " : "") + motion.coordinateNames[c] + "=" +
              scene::formatNumber(motion.coordinates[size_t(pose)][c]) + "°";
    return name;
  }
  const bool labelled = pose >= 0 && size_t(pose) < scene.poseLabels.size();
  return "label " + scene::formatNumber(labelled ? scene.poseLabels[size_t(pose)] : pose);
}

}  // namespace fibremss
