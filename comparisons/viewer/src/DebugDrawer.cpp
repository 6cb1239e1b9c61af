#include "DebugDrawer.h"

#include <cstdio>

#include "fibremss/Messages.h"

namespace fibremss::viewer {
namespace {

void append(std::vector<float>& to, const btVector3& v) {
  to.insert(to.end(), {float(v.x()), float(v.y()), float(v.z())});
}

}  // namespace

void DebugDrawer::clear() {
  geometry_.lineVertices.clear();
  geometry_.lineColours.clear();
  geometry_.points.clear();
  geometry_.pointColours.clear();
}

void DebugDrawer::drawLine(const btVector3& from, const btVector3& to, const btVector3& colour) {
  append(geometry_.lineVertices, from);
  append(geometry_.lineVertices, to);
  append(geometry_.lineColours, colour);
  append(geometry_.lineColours, colour);
}

void DebugDrawer::drawSphere(const btVector3& centre, btScalar radius, const btVector3& colour) {
  append(geometry_.points, centre);
  append(geometry_.pointColours, colour);
}

void DebugDrawer::drawContactPoint(const btVector3& point, const btVector3& normal,
                                   btScalar distance, int lifeTime, const btVector3& colour) {
  drawLine(point, point + normal * distance, colour);
}

void DebugDrawer::reportErrorWarning(const char* warning) {
  printWarning(std::string("Bullet: ") + warning);
}

}  // namespace fibremss::viewer
