#include "SceneShapes.h"

#include "fibremss/Error.h"

namespace fibremss::scene {
namespace {

Shape tubeShape(Fields& generator, double scale) {
  const Json* points = generator.raw("points");
  const Json* radii = generator.raw("radii");
  if (!points)
    generator.fail("points", "missing: the tube's centre-line control points [[x,y,z], ...]");
  if (!radii)
    generator.fail("radii", "missing: one radius (or [a, b] half-axes) per control point");
  if (!points->is_array() || points->size() < 2)
    generator.fail("points",
                   "expected at least two control points [[x,y,z], ...], got " + describe(*points));
  if (!radii->is_array() || radii->size() != points->size())
    generator.fail("radii", "expected " + std::to_string(points->size()) +
                                " entries (one per control point), got " + describe(*radii));
  TubeDefinition definition;
  for (size_t i = 0; i < points->size(); ++i) {
    const std::string where = generator.pathOf("points") + "[" + std::to_string(i) + "]";
    definition.points.push_back(readVector3((*points)[i], where, generator.source()) *
                                btScalar(scale));
    if (i > 0 && (definition.points[i] - definition.points[i - 1]).length() <= 0)
      throw InputError(generator.source(), where, "repeats the previous control point");
  }
  for (size_t i = 0; i < radii->size(); ++i) {
    const Json& r = (*radii)[i];
    const std::string where = generator.pathOf("radii") + "[" + std::to_string(i) + "]";
    std::array<double, 2> halfAxes{};
    if (r.is_number()) {
      halfAxes = {r.get<double>(), r.get<double>()};
    } else if (r.is_array() && r.size() == 2 && r[0].is_number() && r[1].is_number()) {
      halfAxes = {r[0].get<double>(), r[1].get<double>()};
    } else {
      throw InputError(generator.source(), where,
                       "expected a radius or [a, b] half-axes, got " + describe(r));
    }
    if (!(halfAxes[0] > 0) || !(halfAxes[1] > 0))
      throw InputError(generator.source(), where, "radii must be > 0, got " + describe(r));
    definition.radii.push_back({halfAxes[0] * scale, halfAxes[1] * scale});
  }
  generator.set("points", *points);
  generator.set("radii", *radii);
  definition.up = generator.vector3("up", btVector3(0, 0, 0));
  definition.slices = generator.integer("slices", 24, 3, 4096);
  definition.sections = generator.integer("sections", 48, 1, 100000);
  definition.roundCaps = generator.choice("caps", "flat", {"flat", "round"}) == "round";
  Shape shape;
  shape.tube.emplace(std::move(definition));
  shape.mesh = shape.tube->mesh();
  return shape;
}

DiskPattern pattern(Fields& generator, bool lattice) {
  const std::string name = generator.choice("pattern", "auto", {"auto", "sunflower", "grid"});
  if (name == "auto") return lattice ? DiskPattern::Grid : DiskPattern::Sunflower;
  return name == "grid" ? DiskPattern::Grid : DiskPattern::Sunflower;
}

}  // namespace

Shape generateShape(Fields& generator, double scale) {
  const std::string type = generator.choice("type", "", {"tube", "ellipsoid", "box"});
  if (type == "tube") return tubeShape(generator, scale);
  Shape shape;
  shape.centre = generator.vector3("centre", btVector3(0, 0, 0)) * btScalar(scale);
  if (type == "ellipsoid") {
    if (!generator.has("radii")) generator.fail("radii", "missing: [rx, ry, rz]");
    shape.radii = generator.vector3("radii", btVector3(1, 1, 1)) * btScalar(scale);
    if (!(shape.radii.x() > 0 && shape.radii.y() > 0 && shape.radii.z() > 0))
      generator.fail("radii", "expected three radii > 0");
    shape.ellipsoid = true;
    shape.mesh =
        makeEllipsoid(shape.centre, shape.radii, generator.integer("subdivisions", 3, 0, 7));
    return shape;
  }
  if (!generator.has("size")) generator.fail("size", "missing: the box's edge lengths [x, y, z]");
  const btVector3 size = generator.vector3("size", btVector3(1, 1, 1)) * btScalar(scale);
  if (!(size.x() > 0 && size.y() > 0 && size.z() > 0))
    generator.fail("size", "expected three edge lengths > 0");
  const Json* divisions = generator.raw("divisions");
  std::array<int, 3> cells = {1, 1, 1};
  if (divisions) {
    if (!divisions->is_array() || divisions->size() != 3)
      generator.fail("divisions",
                     "expected [nx, ny, nz] (integers >= 1), got " + describe(*divisions));
    for (int i = 0; i < 3; ++i) {
      if (!(*divisions)[i].is_number_integer() || (*divisions)[i].get<int>() < 1 ||
          (*divisions)[i].get<int>() > 1000)
        generator.fail("divisions", "expected [nx, ny, nz] (integers in [1, 1000]), got " +
                                        describe(*divisions));
      cells[i] = (*divisions)[i].get<int>();
    }
  }
  generator.set("divisions", Json::array({cells[0], cells[1], cells[2]}));
  shape.mesh = makeBox(shape.centre, size, cells);
  return shape;
}

FibreSet generateFibres(Fields& generator, const Shape* surface, int count, bool lattice,
                        int* columns) {
  const std::string type = generator.choice("type", "", {"tube", "chords"});
  const DiskPattern disk = pattern(generator, lattice);
  const double inset = generator.number("inset", 0.8, 0, 1, true);
  const int samples = generator.integer("samples", 64, 2, 100000);
  if (type == "tube") {
    if (!surface || !surface->tube)
      generator.fail("type", "\"tube\" fibres need the muscle surface to be a \"tube\" generator");
    return surface->tube->fibres(count, disk, inset, samples, columns);
  }
  const btVector3 axis = generator.vector3("axis", btVector3(0, 0, 1));
  if (axis.length() <= 0) generator.fail("axis", "expected a non-zero direction");
  if (!surface || !surface->ellipsoid)
    generator.fail("type",
                   "\"chords\" fibres need the muscle surface to be an \"ellipsoid\" generator");
  return ellipsoidChords(surface->centre, surface->radii, axis, count, disk, inset, samples,
                         columns);
}

}  // namespace fibremss::scene
