#pragma once
// Procedural geometry for the built-in scenes: closed tubes along smooth centre-lines (muscles,
// long bones), spheres, ellipsoids and boxes, and analytic fibres through tubes and spheres.
// Every generator is deterministic; lengths are in whatever unit the caller uses.
#include <LinearMath/btVector3.h>

#include <array>
#include <vector>

#include "fibremss/Geometry.h"

namespace fibremss {

/// Points of the unit disk where fibres cross a section.
enum class DiskPattern : uint8_t {
  Sunflower,  ///< Vogel's spiral: evenly spread, any count
  Grid,       ///< rows × columns inside the inscribed square (for lattice layouts)
};

/// `count` points of the unit disk, deterministic. For Grid, the points form a row-major
/// rows × columns grid (the most square factorisation, columns >= rows) and `columns` receives
/// the column count; for Sunflower it receives 0.
std::vector<std::array<double, 2>> diskPoints(int count, DiskPattern pattern, int* columns);

/// A closed tube: a Catmull-Rom centre-line through control points, elliptic sections whose
/// half-axes are interpolated (also Catmull-Rom) between the control points' radii.
struct TubeDefinition {
  std::vector<btVector3> points;             ///< centre-line control points (>= 2)
  std::vector<std::array<double, 2>> radii;  ///< half-axes (side, normal) per control point
  btVector3 up{0, 0, 0};   ///< direction of the normal half-axis at the start (0: automatic)
  int slices = 24;         ///< vertices around a section (>= 3)
  int sections = 48;       ///< sections along the centre-line (>= 1)
  bool roundCaps = false;  ///< dome caps (bulbous bone ends) instead of flat caps (muscle ends)
};

/// A tube evaluated by arc length t in [0, 1] with rotation-minimising section frames.
class Tube {
 public:
  explicit Tube(TubeDefinition definition);

  const TubeDefinition& definition() const { return definition_; }
  double length() const { return cumulative_.back(); }

  btVector3 centre(double t) const;             ///< centre-line point
  btVector3 tangent(double t) const;            ///< unit tangent
  btVector3 side(double t) const;               ///< unit direction of the first half-axis
  btVector3 normal(double t) const;             ///< unit direction of the second half-axis
  std::array<double, 2> radii(double t) const;  ///< section half-axes
  /// centre + u·a·side + v·b·normal: (u, v) in the unit disk is inside, on the circle on it.
  btVector3 at(double t, double u, double v) const;
  /// The surface point of the section at t in direction `angle` (radians from side to normal).
  btVector3 surfacePoint(double t, double angle) const;

  /// The closed, outward-oriented triangle surface.
  TriangleMesh mesh() const;
  /// `count` fibres from the start cap to the end cap, each `samples` points, at disk points
  /// scaled by `inset` (< 1 keeps them inside). `columns` receives the grid columns (Grid).
  FibreSet fibres(int count, DiskPattern pattern, double inset, int samples, int* columns) const;

 private:
  struct Sample {
    btVector3 centre, tangent, side, normal;
    std::array<double, 2> radii;
  };
  Sample sample(double t) const;

  TubeDefinition definition_;
  std::vector<Sample> samples_;     ///< dense samples along the centre-line
  std::vector<double> cumulative_;  ///< arc length at each sample
};

/// An ellipsoid (a sphere when all radii are equal): a subdivided icosahedron, closed, outward.
TriangleMesh makeEllipsoid(const btVector3& centre, const btVector3& radii, int subdivisions);

/// A box with `divisions` cells per axis on its faces (welded, closed, outward).
TriangleMesh makeBox(const btVector3& centre, const btVector3& size,
                     const std::array<int, 3>& divisions);

/// Straight fibres through an ellipsoid along `axis` (a unit vector), at disk points scaled by
/// `inset` across and ending `inset` of the way to the surface, `samples` points each.
FibreSet ellipsoidChords(const btVector3& centre, const btVector3& radii, const btVector3& axis,
                         int count, DiskPattern pattern, double inset, int samples, int* columns);

}  // namespace fibremss
