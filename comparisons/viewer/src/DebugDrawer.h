#pragma once
// The viewer's btIDebugDraw: collects what a world's debugDrawWorld draws (lines; spheres as
// points, e.g. particles and bone spheres) for the renderer; its debug mode gates what Bullet
// itself draws.
#include <LinearMath/btIDebugDraw.h>

#include <vector>

namespace fibremss::viewer {

/// Lines and points as drawn, ready for OpenGL's vertex arrays.
struct DebugGeometry {
  std::vector<float> lineVertices;  ///< xyz, two vertices per line [m]
  std::vector<float> lineColours;   ///< rgb per line vertex, 0..1
  std::vector<float> points;        ///< xyz per point [m]
  std::vector<float> pointColours;  ///< rgb per point, 0..1
};

class DebugDrawer : public btIDebugDraw {
 public:
  /// Forgets what was drawn.
  void clear();

  void drawLine(const btVector3& from, const btVector3& to, const btVector3& colour) override;
  using btIDebugDraw::drawSphere;
  /// A sphere becomes one point (its centre, its colour); radii are not drawn.
  void drawSphere(const btVector3& centre, btScalar radius, const btVector3& colour) override;
  void drawContactPoint(const btVector3& point, const btVector3& normal, btScalar distance,
                        int lifeTime, const btVector3& colour) override;
  void reportErrorWarning(const char* warning) override;
  void draw3dText(const btVector3& location, const char* text) override {}
  void setDebugMode(int mode) override { mode_ = mode; }
  int getDebugMode() const override { return mode_; }

  const DebugGeometry& geometry() const { return geometry_; }  ///< what was drawn

 private:
  int mode_ = DBG_NoDebug;  ///< btIDebugDraw::DebugDrawModes bits
  DebugGeometry geometry_;  ///< what was drawn since clear()
};

}  // namespace fibremss::viewer
