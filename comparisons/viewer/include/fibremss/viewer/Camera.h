#pragma once
// The viewer's camera: orbits a target point (azimuth about the scene's up axis, elevation
// above its horizontal plane), pans the target in the view plane, zooms by distance; a
// perspective projection. Matrices are column-major as OpenGL takes them.
#include <array>
#include <span>

namespace fibremss::viewer {

using Vec3 = std::array<float, 3>;
using Mat4 = std::array<float, 16>;  ///< column-major 4x4

/// Where a projected point lands in an image.
struct Pixel {
  float x = 0;           ///< column from the left [px]
  float y = 0;           ///< row from the top [px]
  bool visible = false;  ///< in front of the camera and inside the image
};

/// A ray from the eye through a pixel [world units]; direction of unit length.
struct Ray {
  Vec3 origin{0, 0, 0};
  Vec3 direction{0, 0, -1};
};

class Camera {
 public:
  /// Looks at `points` from the current angles in an image of `aspect` (width / height): their
  /// projection centred, spanning `fill` of the image's width or height, whichever binds.
  void frame(std::span<const Vec3> points, float aspect, float fill = 0.9f);
  /// Turns about the target [deg]; elevation stays within ±89°.
  void orbit(float azimuthDeg, float elevationDeg);
  /// Moves the target in the view plane by fractions of the view's height (right, up).
  void pan(float right, float up);
  /// Divides the distance by `factor` (> 1 comes closer).
  void zoom(float factor);
  /// Sets the angles [deg] (frame() after it to look at the scene from there).
  void setAngles(float azimuthDeg, float elevationDeg);

  Mat4 view() const;                    ///< world to eye
  Mat4 projection(float aspect) const;  ///< eye to clip (aspect = width / height)
  /// The pixel a world point lands on in a width × height image.
  Pixel project(const Vec3& point, int width, int height) const;

  /// The ray from the eye through pixel (x, y) of a width × height image (the inverse of project).
  Ray ray(float x, float y, int width, int height) const;

  Vec3 eye() const;                        ///< the camera's position [world units]
  Vec3 target() const { return target_; }  ///< the point looked at [world units]
  float azimuthDeg() const { return azimuth_; }
  float elevationDeg() const { return elevation_; }

  float fovYDeg = 35;  ///< vertical field of view [deg]

 private:
  Vec3 target_{0, 0, 0};      ///< the point looked at [world units]
  float distance_ = 1;        ///< eye to target [world units]
  float framedDistance_ = 1;  ///< the distance frame() chose [world units]
  float azimuth_ = 30;        ///< angle about the up axis (y) [deg]
  float elevation_ = 15;      ///< angle above the horizontal plane [deg]
  float extent_ = 1;          ///< half the framed points' bounding-box diagonal [world units]
};

}  // namespace fibremss::viewer
