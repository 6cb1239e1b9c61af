#include "fibremss/viewer/Camera.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace fibremss::viewer {
namespace {

constexpr float kPi = 3.14159265358979f;

float radians(float degrees) {
  return degrees * kPi / 180;
}
Vec3 add(const Vec3& a, const Vec3& b) {
  return {a[0] + b[0], a[1] + b[1], a[2] + b[2]};
}
Vec3 sub(const Vec3& a, const Vec3& b) {
  return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}
Vec3 scale(const Vec3& a, float s) {
  return {a[0] * s, a[1] * s, a[2] * s};
}
float dot(const Vec3& a, const Vec3& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
Vec3 normalised(const Vec3& a) {
  return scale(a, 1 / std::sqrt(dot(a, a)));
}

/// From the target towards the eye, unit length (y up).
Vec3 backward(float azimuthDeg, float elevationDeg) {
  const float az = radians(azimuthDeg), el = radians(elevationDeg);
  return {std::cos(el) * std::sin(az), std::sin(el), std::cos(el) * std::cos(az)};
}

/// The camera's right and up directions in world coordinates.
void basis(float azimuthDeg, float elevationDeg, Vec3& right, Vec3& up) {
  const Vec3 back = backward(azimuthDeg, elevationDeg);
  right = normalised(cross({0, 1, 0}, back));
  up = cross(back, right);
}

/// A point in the view's frame: along its right and up axes and towards the eye.
using ViewPoint = std::array<float, 3>;

/// The least distance at which the points fit within ±tanHalf of the view axis along image axis
/// `axis` (0 right, 1 up), the target moved along it as it needs: a point at x, z (towards the
/// eye) fits when |x - t| <= tanHalf * (d - z), so d * tanHalf is at least the mean of the two
/// sides' largest z * tanHalf ± x.
float fitDistance(const std::vector<ViewPoint>& points, int axis, float tanHalf) {
  float positive = std::numeric_limits<float>::lowest(), negative = positive;
  for (const ViewPoint& p : points) {
    positive = std::max(positive, p[2] * tanHalf + p[axis]);
    negative = std::max(negative, p[2] * tanHalf - p[axis]);
  }
  return (positive + negative) / (2 * tanHalf);
}

/// The target's offset along image axis `axis` that puts the points' projections, seen from
/// `distance`, as far past the centre on one side as on the other (by bisection: the sum of
/// the two extremes falls as the offset grows).
float centring(const std::vector<ViewPoint>& points, int axis, float distance) {
  float low = std::numeric_limits<float>::max(), high = std::numeric_limits<float>::lowest();
  for (const ViewPoint& p : points) {
    low = std::min(low, p[axis]);
    high = std::max(high, p[axis]);
  }
  for (int i = 0; i < 40; ++i) {
    const float t = 0.5f * (low + high);
    float first = std::numeric_limits<float>::max(), last = std::numeric_limits<float>::lowest();
    for (const ViewPoint& p : points) {
      const float projected = (p[axis] - t) / (distance - p[2]);
      first = std::min(first, projected);
      last = std::max(last, projected);
    }
    (first + last > 0 ? low : high) = t;
  }
  return 0.5f * (low + high);
}

}  // namespace

void Camera::frame(std::span<const Vec3> points, float aspect, float fill) {
  if (points.empty()) return;
  Vec3 lower = points.front(), upper = points.front();
  for (const Vec3& p : points)
    for (int k = 0; k < 3; ++k) {
      lower[k] = std::min(lower[k], p[k]);
      upper[k] = std::max(upper[k], p[k]);
    }
  const Vec3 centre = scale(add(lower, upper), 0.5f), diagonal = sub(upper, lower);
  extent_ = std::max(0.5f * std::sqrt(dot(diagonal, diagonal)), 1e-6f);
  Vec3 right, up;
  basis(azimuth_, elevation_, right, up);
  const Vec3 back = backward(azimuth_, elevation_);
  std::vector<ViewPoint> view;  // from the centre: along right, up, towards the eye
  view.reserve(points.size());
  for (const Vec3& p : points) {
    const Vec3 q = sub(p, centre);
    view.push_back({dot(q, right), dot(q, up), dot(q, back)});
  }
  const float tanY = fill * std::tan(radians(fovYDeg / 2)), tanX = tanY * aspect;
  framedDistance_ = distance_ =
      std::max({fitDistance(view, 0, tanX), fitDistance(view, 1, tanY), 2 * extent_});
  target_ = add(centre, add(scale(right, centring(view, 0, distance_)),
                            scale(up, centring(view, 1, distance_))));
}

void Camera::orbit(float azimuthDeg, float elevationDeg) {
  azimuth_ = std::remainder(azimuth_ + azimuthDeg, 360.0f);
  elevation_ = std::clamp(elevation_ + elevationDeg, -89.0f, 89.0f);
}

void Camera::pan(float right, float up) {
  Vec3 r, u;
  basis(azimuth_, elevation_, r, u);
  const float height = 2 * distance_ * std::tan(radians(fovYDeg / 2));
  target_ = add(target_, add(scale(r, right * height), scale(u, up * height)));
}

void Camera::zoom(float factor) {
  distance_ = std::clamp(distance_ / factor, 1e-3f * extent_, 100 * framedDistance_);
}

void Camera::setAngles(float azimuthDeg, float elevationDeg) {
  azimuth_ = 0;
  elevation_ = 0;
  orbit(azimuthDeg, elevationDeg);
}

Vec3 Camera::eye() const {
  return add(target_, scale(backward(azimuth_, elevation_), distance_));
}

Ray Camera::ray(float x, float y, int width, int height) const {
  const float tanY = std::tan(radians(fovYDeg / 2)), tanX = tanY * float(width) / float(height);
  Vec3 r, u;
  basis(azimuth_, elevation_, r, u);
  const float right = (2 * x / float(width) - 1) * tanX, up = (1 - 2 * y / float(height)) * tanY;
  const Vec3 direction =
      add(scale(backward(azimuth_, elevation_), -1), add(scale(r, right), scale(u, up)));
  return {eye(), normalised(direction)};
}

Mat4 Camera::view() const {
  const Vec3 back = backward(azimuth_, elevation_);
  Vec3 r, u;
  basis(azimuth_, elevation_, r, u);
  const Vec3 e = eye();
  return {r[0], u[0], back[0], 0, r[1],       u[1],       back[1],       0,
          r[2], u[2], back[2], 0, -dot(r, e), -dot(u, e), -dot(back, e), 1};
}

Mat4 Camera::projection(float aspect) const {
  const float near = std::max(distance_ - 2 * extent_, distance_ / 100);
  const float far = distance_ + 2 * extent_;
  const float f = 1 / std::tan(radians(fovYDeg / 2));
  return {f / aspect,
          0,
          0,
          0,
          0,
          f,
          0,
          0,
          0,
          0,
          (far + near) / (near - far),
          -1,
          0,
          0,
          2 * far * near / (near - far),
          0};
}

Pixel Camera::project(const Vec3& point, int width, int height) const {
  const Mat4 v = view(), p = projection(float(width) / float(height));
  auto apply = [](const Mat4& m, const std::array<float, 4>& x) {
    std::array<float, 4> y{};
    for (int row = 0; row < 4; ++row)
      for (int col = 0; col < 4; ++col) y[row] += m[col * 4 + row] * x[col];
    return y;
  };
  const std::array<float, 4> clip = apply(p, apply(v, {point[0], point[1], point[2], 1}));
  Pixel pixel;
  if (clip[3] <= 0) return pixel;
  pixel.x = (clip[0] / clip[3] + 1) / 2 * float(width);
  pixel.y = (1 - clip[1] / clip[3]) / 2 * float(height);
  pixel.visible = pixel.x >= 0 && pixel.y >= 0 && pixel.x < float(width) && pixel.y < float(height);
  return pixel;
}

}  // namespace fibremss::viewer
