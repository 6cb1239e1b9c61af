// `fibremss fibres MUSCLE [--origin BONE|LANDMARKS] [--insertion BONE|LANDMARKS] --out F.vtk`:
// fibres from a muscle surface (harmonic field + gradient streamlines), with quality figures.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "Commands.h"
#include "Validators.h"
#include "fibremss/Error.h"
#include "fibremss/FibreGeneration.h"
#include "fibremss/InputFiles.h"
#include "fibremss/MeshIO.h"
#include "fibremss/Messages.h"

namespace fibremss::cli {
namespace {

struct FibresArgs {
  std::string muscle, origin, insertion, out;
  int count = 64, samples = 64, grid = 48, maxGrid = 192;
  double minShare = 0.9;  // fewer fibres than this share of --count: an error, no file
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

/// Landmarks from a JSON file: [[x, y, z], ...] or {"landmarks": [[x, y, z], ...], "radius": r}
/// (file units).
AttachmentArea landmarksFromFile(const std::string& path, const FibresArgs& args) {
  nlohmann::json json;
  try {
    json = nlohmann::json::parse(readJsonText(path));
  } catch (const nlohmann::json::exception& e) {
    throw InputError(path, "", std::string("not valid JSON: ") + e.what());
  }
  double radius = args.radius * 0.001 / args.scale;  // file units
  const nlohmann::json* list = &json;
  if (json.is_object()) {
    for (const auto& [key, value] : json.items())
      if (key != "landmarks" && key != "radius")
        throw InputError(path, key, "unknown field; expected \"landmarks\" and \"radius\"");
    if (!json.contains("landmarks")) throw InputError(path, "landmarks", "missing");
    list = &json["landmarks"];
    if (json.contains("radius")) {
      if (!json["radius"].is_number() || !(json["radius"].get<double>() > 0))
        throw InputError(path, "radius", "expected a number > 0 (file units)");
      radius = json["radius"].get<double>();
    }
  }
  if (!list->is_array() || list->empty())
    throw InputError(path, "landmarks", "expected a non-empty array of [x, y, z] (file units)");
  std::vector<btVector3> points;
  for (size_t i = 0; i < list->size(); ++i) {
    const nlohmann::json& p = (*list)[i];
    if (!p.is_array() || p.size() != 3 || !p[0].is_number() || !p[1].is_number() ||
        !p[2].is_number())
      throw InputError(path, "landmarks[" + std::to_string(i) + "]",
                       "expected [x, y, z] (file units), got " + p.dump());
    points.push_back(btVector3(btScalar(p[0].get<double>() * args.scale),
                               btScalar(p[1].get<double>() * args.scale),
                               btScalar(p[2].get<double>() * args.scale)));
  }
  return AttachmentArea::fromLandmarks(std::move(points), btScalar(radius * args.scale));
}

AttachmentArea readArea(const std::string& text, const FibresArgs& args, TriangleMesh& bone,
                        const std::string& option) {
  if (text.empty()) {
    AttachmentArea farEnd;
    farEnd.endDepth = btScalar(args.endDepth * 0.001);
    return farEnd;
  }
  if (text.front() == '@') return landmarksFromFile(text.substr(1), args);
  std::vector<btVector3> points;
  btScalar radius;
  std::error_code error;  // a long landmark list is no file name: no exception for it
  const bool isFile = std::filesystem::is_regular_file(text, error);
  if (!isFile && parseLandmarks(text, args.scale, args.radius, points, radius))
    return AttachmentArea::fromLandmarks(std::move(points), radius);
  if (!isFile)
    throw InputError(option, text.size() > 60 ? text.substr(0, 60) + "..." : text,
                     "expected a bone mesh file, landmarks \"x,y,z;x,y,z[@radius]\" (file units) "
                     "or @FILE.json holding [[x, y, z], ...]");
  bone = loadSurface(text, args.scale);
  return AttachmentArea::fromBone(bone, btScalar(args.distance * 0.001));
}

void run(const FibresArgs& args) {
  MeshReport report;
  const TriangleMesh surface = loadSurface(args.muscle, args.scale, &report);
  printWarnings(report.warnings);
  TriangleMesh originBone, insertionBone;
  const AttachmentArea origin = readArea(args.origin, args, originBone, "--origin");
  const AttachmentArea insertion = readArea(args.insertion, args, insertionBone, "--insertion");
  FibreGenerationOptions options;
  options.count = args.count;
  options.samples = args.samples;
  options.grid = args.grid;
  options.maxGrid = std::max(args.maxGrid, args.grid);
  options.minShare = args.minShare;
  options.coverageDistance = btScalar(args.coverage * 0.001);
  options.crossingTolerance = btScalar(args.crossing * 0.001);
  options.sectionSeeds = args.seeds == "section";
  const FibreGenerationResult result =
      generateFibres(surface, origin, insertion, options, args.muscle);
  printWarnings(result.warnings);
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
            << "right ends:    " << q.rightEnds * 100 << " % start within 1.5 voxels of the "
            << "origin and end within 1.5 voxels of the insertion (worst end "
            << q.worstEndGap * 1000 << " mm from its area)\n"
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
      "a missing one is the muscle's end farthest from the other along its main axis. Fewer fibres "
      "than --min-share of --count: exit 2 and no file.");
  command->add_option("muscle", args->muscle, "closed muscle surface (obj, stl, vtk, ...)")
      ->required();
  command->add_option("--origin", args->origin,
                      "origin bone mesh, landmarks, or @FILE.json with [[x, y, z], ...]");
  command->add_option("--insertion", args->insertion,
                      "insertion bone mesh, landmarks, or @FILE.json with [[x, y, z], ...]");
  command->add_option("--count", args->count, "fibres to generate")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  command->add_option("--samples", args->samples, "points per fibre")
      ->check(CLI::Range(2, 100000))
      ->capture_default_str();
  command->add_option("--grid", args->grid, "voxels along the muscle's longest side")
      ->check(CLI::Range(8, 400))
      ->capture_default_str();
  command
      ->add_option("--max-grid", args->maxGrid,
                   "raise the grid 1.5x at a time up to this when the areas do not connect or "
                   "too few fibres arrive")
      ->check(CLI::Range(8, 400))
      ->capture_default_str();
  command
      ->add_option("--min-share", args->minShare,
                   "fail (exit 2, no file) when fewer than this share of --count can be made")
      ->check(CLI::Range(0.0, 1.0))
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
      ->check(oneOf({"section", "origin"}))
      ->type_name("section|origin")
      ->capture_default_str();
  command->add_option("--out", args->out, "output legacy VTK LINES file")->required();
  command->callback([args] { run(*args); });
}

}  // namespace fibremss::cli
