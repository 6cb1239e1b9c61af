// `fibremss fibres MUSCLE [--origin BONE|LANDMARKS] [--insertion BONE|LANDMARKS] --out F.vtk`:
// fibres from a muscle surface (harmonic field + gradient streamlines), with quality figures.
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <sstream>

#include "Commands.h"
#include "Validators.h"
#include "fibremss/Error.h"
#include "fibremss/FibreGeneration.h"
#include "fibremss/MeshIO.h"

namespace fibremss::cli {
namespace {

struct FibresArgs {
  std::string muscle, origin, insertion, out;
  int count = 64, samples = 64, grid = 48;
  double scale = 0.001;   // metres per file unit
  double distance = 4;    // mm: bone attachment area
  double radius = 10;     // mm: landmark radius
  double coverage = 5;    // mm
  double crossing = 0.5;  // mm
  double endDepth = 0;    // mm: a far end's depth (0: 6 % of the length)
  std::string seeds = "section";
};

/// "x,y,z;x,y,z[@r]" (file units) -> landmarks; false when `text` is not of that form.
bool parseLandmarks(const std::string& text, double scale, double defaultRadiusMm,
                    std::vector<btVector3>& points, btScalar& radius) {
  std::string list = text;
  radius = btScalar(defaultRadiusMm * 0.001);
  if (const size_t at = list.find('@'); at != std::string::npos) {
    try {
      radius = btScalar(std::stod(list.substr(at + 1)) * scale);
    } catch (const std::exception&) {
      return false;
    }
    list = list.substr(0, at);
  }
  std::stringstream groups(list);
  std::string group;
  while (std::getline(groups, group, ';')) {
    double x, y, z;
    char c1, c2;
    std::istringstream in(group);
    if (!(in >> x >> c1 >> y >> c2 >> z) || c1 != ',' || c2 != ',') return false;
    std::string rest;
    if (in >> rest) return false;
    points.push_back(btVector3(btScalar(x * scale), btScalar(y * scale), btScalar(z * scale)));
  }
  return !points.empty();
}

AttachmentArea readArea(const std::string& text, const FibresArgs& args, TriangleMesh& bone,
                        const std::string& option) {
  if (text.empty()) {
    AttachmentArea farEnd;
    farEnd.endDepth = btScalar(args.endDepth * 0.001);
    return farEnd;
  }
  std::vector<btVector3> points;
  btScalar radius;
  if (!std::filesystem::exists(text) &&
      parseLandmarks(text, args.scale, args.radius, points, radius))
    return AttachmentArea::fromLandmarks(std::move(points), radius);
  if (!std::filesystem::exists(text))
    throw InputError(
        option, text,
        "expected a bone mesh file or landmarks \"x,y,z;x,y,z[@radius]\" (file units)");
  bone = loadSurface(text, args.scale);
  return AttachmentArea::fromBone(bone, btScalar(args.distance * 0.001));
}

void run(const FibresArgs& args) {
  MeshReport report;
  const TriangleMesh surface = loadSurface(args.muscle, args.scale, &report);
  for (const auto& warning : report.warnings) std::cout << "warning: " << warning << "\n";
  TriangleMesh originBone, insertionBone;
  const AttachmentArea origin = readArea(args.origin, args, originBone, "--origin");
  const AttachmentArea insertion = readArea(args.insertion, args, insertionBone, "--insertion");
  FibreGenerationOptions options;
  options.count = args.count;
  options.samples = args.samples;
  options.grid = args.grid;
  options.coverageDistance = btScalar(args.coverage * 0.001);
  options.crossingTolerance = btScalar(args.crossing * 0.001);
  options.sectionSeeds = args.seeds == "section";
  const FibreGenerationResult result =
      generateFibres(surface, origin, insertion, options, args.muscle);
  for (const auto& warning : result.warnings) std::cout << "warning: " << warning << "\n";
  saveFibresVtk(args.out, result.fibres, args.scale);
  const FibreQuality& q = result.quality;
  std::cout << std::fixed << std::setprecision(2);
  std::cout << "muscle:        " << args.muscle << " (" << surface.vertices.size() << " vertices, "
            << surface.triangles.size() << " triangles)\n"
            << "areas:         origin " << q.originVertices << " vertices, insertion "
            << q.insertionVertices << " vertices\n"
            << "grid:          " << q.gridCells[0] << " x " << q.gridCells[1] << " x "
            << q.gridCells[2] << ", voxel " << q.voxelSize * 1000 << " mm, " << q.interiorVoxels
            << " interior voxels\n"
            << "fibres:        " << q.generated << " of " << q.requested << " (traced " << q.traced
            << ", left the surface " << q.droppedOutside << ", stopped early " << q.droppedEarly
            << ", within 1 mm of another " << q.crowded << ")\n"
            << "length mm:     min " << q.minLength * 1000 << ", median " << q.medianLength * 1000
            << ", max " << q.maxLength * 1000 << "\n"
            << "coverage:      " << q.coverage * 100 << " % of the interior within "
            << args.coverage << " mm of a fibre\n"
            << "crossings:     " << q.crossingPairs << " fibre pairs closer than " << args.crossing
            << " mm\n"
            << "outside:       " << q.pointsOutside << " fibre points outside the surface\n"
            << "right ends:    " << q.rightEnds * 100 << " % start at the origin and end at the "
            << "insertion\n"
            << "time:          " << q.seconds << " s\n"
            << "wrote:         " << args.out << "\n";
}

}  // namespace

void addFibresCommand(CLI::App& app) {
  auto args = std::make_shared<FibresArgs>();
  CLI::App* command = app.add_subcommand(
      "fibres",
      "Generate fibres inside a muscle surface: a harmonic field from the origin area (0) to the "
      "insertion area (1), streamlines of its gradient. An attachment is a bone mesh (surface "
      "vertices within --distance of it) or landmarks \"x,y,z;x,y,z[@radius]\" in file units; "
      "a missing one is the muscle's end farthest from the other along its main axis.");
  command->add_option("muscle", args->muscle, "closed muscle surface (obj, stl, vtk, ...)")
      ->required();
  command->add_option("--origin", args->origin, "origin bone mesh or landmarks");
  command->add_option("--insertion", args->insertion, "insertion bone mesh or landmarks");
  command->add_option("--count", args->count, "fibres to generate")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  command->add_option("--samples", args->samples, "points per fibre")
      ->check(CLI::Range(2, 100000))
      ->capture_default_str();
  command->add_option("--grid", args->grid, "voxels along the muscle's longest side")
      ->check(CLI::Range(8, 400))
      ->capture_default_str();
  command->add_option("--scale", args->scale, "metres per file unit (0.001: files in mm)")
      ->check(positiveNumber())
      ->capture_default_str();
  command->add_option("--distance", args->distance, "bone attachment area: within this [mm]")
      ->check(nonNegativeNumber())
      ->capture_default_str();
  command->add_option("--radius", args->radius, "landmark radius when not given with @ [mm]")
      ->check(positiveNumber())
      ->capture_default_str();
  command->add_option("--coverage", args->coverage, "coverage distance for the figures [mm]")
      ->check(positiveNumber())
      ->capture_default_str();
  command->add_option("--crossing", args->crossing, "crossing tolerance for the figures [mm]")
      ->check(positiveNumber())
      ->capture_default_str();
  command
      ->add_option("--end-depth", args->endDepth,
                   "a missing attachment: the far end this deep [mm] (0: 6 % of the length)")
      ->check(nonNegativeNumber())
      ->capture_default_str();
  command
      ->add_option("--seeds", args->seeds,
                   "section: seeds over the widest cross-section, traced both ways; origin: "
                   "seeds over the origin area")
      ->check(CLI::IsMember({"section", "origin"}))
      ->capture_default_str();
  command->add_option("--out", args->out, "output legacy VTK LINES file")->required();
  command->callback([args] { run(*args); });
}

}  // namespace fibremss::cli
