// `fibremss reference SCENE`: the CalculiX static reference of a scene (cached), its gates,
// and the .inp files it was solved from.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>

#include "Commands.h"
#include "Interrupt.h"
#include "ProgressLog.h"
#include "ReferenceArgs.h"
#include "SceneArgs.h"
#include "fibremss/Error.h"
#include "fibremss/Messages.h"
#include "fibremss/Output.h"
#include "fibremss/ReferenceCache.h"

namespace fibremss::cli {
namespace {

struct ReferenceArgs {
  SceneArgs scene;
  std::string out;  ///< --out DIR (default: reference-<scene>)
  ReferenceOptions options;
  bool listCells = false;  ///< --cells: print the cells and stop
  int cell = -1;           ///< --cell I: solve that cell alone (-1: the whole reference)
  std::string shipDir;     ///< --ship DIR: write its solves there as shipped references
};

/// One line per cell: its number, solve, muscle, cache key and whether it is stored.
void printCells(const std::vector<NamedReferenceCell>& cells) {
  for (size_t c = 0; c < cells.size(); ++c)
    std::printf("%zu\t%s\t%s\t%s\t%s\n", c, cells[c].solve.c_str(), cells[c].muscle.c_str(),
                cells[c].key.c_str(), cells[c].stored ? "stored" : "to solve");
}

/// Solves cell `index` of referenceCells into the cache (a batch engine's task).
void solveCell(const LoadedScene& scene, const PreparedScene& prepared, const ReferenceArgs& args,
               const std::vector<NamedReferenceCell>& cells) {
  if (args.cell >= static_cast<int>(cells.size()))
    throw InputError(
        "--cell", std::to_string(args.cell),
        "expected a cell number below " + std::to_string(cells.size()) + " (--cells lists them)");
  const NamedReferenceCell& cell = cells[static_cast<size_t>(args.cell)];
  const std::string cacheDir = resolvedCacheDir(args.options);
  const bool done =
      cachedCalculixMuscle(scene, prepared, cell.cell.definition, cell.cell.cut, cacheDir,
                           cell.cell.muscle, args.options.progress, args.options.cancel);
  if (!done) {
    std::fprintf(stderr, "interrupted: cell %d not stored\n", args.cell);
    throw CLI::RuntimeError(interruptExitCode());
  }
  std::printf("cell %d (%s, %s, %s): %s in %s\n", args.cell, cell.solve.c_str(),
              cell.muscle.c_str(), cell.key.c_str(), cell.stored ? "was stored" : "solved",
              cacheDir.c_str());
}

void writeOut(const Reference& reference, const std::string& out) {
  std::filesystem::create_directories(out + "/inp");
  for (const std::string& file : reference.solution.inputFiles) {
    std::filesystem::copy_file(file,
                               out + "/inp/" + std::filesystem::path(file).filename().string(),
                               std::filesystem::copy_options::overwrite_existing);
  }
  const std::string path = out + "/reference.json";
  std::ofstream json(path + ".partial");
  json << referenceJson(reference).dump(2) << "\n";
  if (!json) throw std::runtime_error("cannot write " + path);
  json.close();
  std::filesystem::rename(path + ".partial", path);
}

/// `dir/manifest.json` with `entry` in place of the one of the same scene and overrides; the
/// files only that one named are removed.
void updateManifest(const std::string& dir, const nlohmann::ordered_json& entry) {
  const std::string path = dir + "/manifest.json";
  nlohmann::ordered_json manifest = nlohmann::ordered_json::array();
  if (std::ifstream in(path); in) {
    manifest = nlohmann::ordered_json::parse(in, nullptr, false);
    if (!manifest.is_array()) throw InputError(path, "", "expected a JSON array of shipped scenes");
  }
  const auto files = [](const nlohmann::ordered_json& shipped) {
    std::set<std::string> found;
    if (shipped.contains("solves"))
      for (const auto& solve : shipped.at("solves")) {
        const std::string key = solve.value("key", "");
        found.insert(key + ".ref.gz");
        if (solve.contains("retry_of"))
          found.insert(solve.at("retry_of").get<std::string>() + ".ref.gz");
        for (const auto& m : solve.value("parts", nlohmann::ordered_json::array()))
          found.insert(shippedPartName(key, m.get<size_t>()));
      }
    return found;
  };
  std::set<std::string> kept;  // the files of the entry replaced, then those only it named
  nlohmann::ordered_json updated = nlohmann::ordered_json::array();
  for (const auto& other : manifest) {
    if (other.value("scene", std::string()) == entry.at("scene") && other.contains("set") &&
        other.at("set") == entry.at("set"))
      kept.merge(files(other));
    else
      updated.push_back(other);
  }
  updated.push_back(entry);
  for (const auto& other : updated)
    for (const std::string& file : files(other)) kept.erase(file);
  for (const std::string& stale : kept) std::filesystem::remove(dir + "/" + stale);
  std::ofstream out(path + ".partial");
  out << updated.dump(2) << "\n";
  if (!out) throw std::runtime_error("cannot write " + path);
  out.close();
  std::filesystem::rename(path + ".partial", path);
}

/// Says that `path` was shipped, what it holds and its size.
void sayShipped(const std::string& path, const std::string& what) {
  std::printf("shipped %s (%s): %ju bytes\n", path.c_str(), what.c_str(),
              static_cast<uintmax_t>(std::filesystem::file_size(path)));
}

/// Writes `solution` to `dir/<key>.ref.gz` (against `base` where not null) and says so.
void shipStored(const std::string& dir, const std::string& key, const CalculixSolution& solution,
                const std::string& what, const ShippedBase* base = nullptr) {
  const std::string path = dir + "/" + key + ".ref.gz";
  shipSolution(path, solution, base);
  sayShipped(path, what);
}

/// Writes each muscle's part of the solve `key` stored alone (a cell solved into the cache, or
/// shipped before: loadStoredPart) to `dir/<key>.m<M>.ref.gz` (against `base` where not null)
/// and says so; the muscles shipped, as the manifest lists them.
nlohmann::ordered_json shipParts(const PreparedScene& prepared, const std::string& cacheDir,
                                 const std::string& dir, const std::string& key,
                                 const std::string& what, const ShippedBase* base) {
  nlohmann::ordered_json shipped = nlohmann::ordered_json::array();
  for (size_t m = 0; m < prepared.muscles.size(); ++m) {
    MuscleSolution part;
    if (!loadStoredPart(cacheDir, key, m, part) || part.hitMemoryLimit()) continue;
    const std::string path = dir + "/" + shippedPartName(key, m);
    shipPart(path, part, base);
    sayShipped(path, what + ", " + prepared.muscles[m]->name + "'s part");
    shipped.push_back(m);
  }
  return shipped;
}

/// The failed solve a retry replaces, as a fresh machine needs it to find the retry: its
/// failures and counts (its muscles' too: which ones the retry solved again is in its key)
/// without its surfaces (only the retry's are compared).
CalculixSolution failureRecord(CalculixSolution solution) {
  for (std::vector<btVector3>& surface : solution.poseSurfaces) surface.clear();
  solution.returnSurface.clear();
  for (MuscleSolution& part : solution.muscles) part.stepSurfaces.clear();
  return solution;
}

/// The reference's solve as shipped to `dir` under `key`, against which its gates are stored.
ShippedBase shippedBase(const PreparedScene& prepared, const std::string& dir,
                        const std::string& key) {
  ShippedBase base{key, {}, {}};
  if (!loadShippedSolution(dir + "/" + key + ".ref.gz", base.solution))
    throw std::runtime_error("the reference " + key + " was not shipped to " + dir);
  for (const auto& muscle : prepared.muscles)
    base.muscleVertices.push_back(muscle->restSurface.vertices.size());
  return base;
}

/// The manifest entry of a solve not stored whole (`"shipped": false`), with the parts of it
/// that are stored alone shipped to `dir` (shipParts, `"parts"`) and, where it is the retry of a
/// failed solve that is stored, that solve whole (`"retry_of"`). Throws where the reference's
/// solve has no part stored.
nlohmann::ordered_json shipUnsolved(const PreparedScene& prepared, const std::string& cacheDir,
                                    const std::string& dir, const NamedReferenceCell& cell,
                                    const ShippedBase* base) {
  nlohmann::ordered_json unsolved = {{"solve", cell.solve}, {"key", cell.key}, {"shipped", false}};
  const nlohmann::ordered_json parts =
      shipParts(prepared, cacheDir, dir, cell.key, cell.solve, base);
  if (parts.empty() && cell.solve == "reference")
    throw std::runtime_error("the reference solve " + cell.key + " is not stored");
  std::printf("not shipped whole: %s (%s), %zu of %zu muscles' cells shipped\n", cell.key.c_str(),
              cell.solve.c_str(), parts.size(), prepared.muscles.size());
  if (!parts.empty()) unsolved["parts"] = parts;
  CalculixSolution failed;
  if (!cell.retryOf.empty() && loadStoredSolution(cacheDir, cell.retryOf, failed)) {
    // The failed solve whole (the poses before its failure are its figure until the retry is
    // solved), through which a fresh machine reaches the retry's key.
    shipStored(dir, cell.retryOf, failed, cell.solve + ", failed; its retry not solved", base);
    unsolved["retry_of"] = cell.retryOf;
  }
  return unsolved;
}

/// Writes every stored solve of the reference (its own and its gates') to args.shipDir as
/// shipped references (`<key>.ref.gz`; the gates' against the reference's) and records them in
/// its manifest.json. A solve not stored whole is listed with `"shipped": false`, so the
/// manifest still names every key of the scene, and its muscles' parts solved so far are
/// shipped (shipUnsolved).
void ship(const LoadedScene& scene, const PreparedScene& prepared, const ReferenceArgs& args) {
  const std::string cacheDir = resolvedCacheDir(args.options);
  std::filesystem::create_directories(args.shipDir);
  ReferenceOptions withGates = args.options;
  withGates.gates = true;
  nlohmann::ordered_json solves = nlohmann::ordered_json::array();
  std::unique_ptr<ShippedBase> base;  // the reference's, once shipped (its cell comes first)
  for (const NamedReferenceCell& cell : referenceCells(scene, prepared, withGates)) {
    if (cell.cell.muscle != 0) continue;  // a cell per muscle, a file per solve
    CalculixSolution solution;
    if (!loadStoredSolution(cacheDir, cell.key, solution)) {
      solves.push_back(shipUnsolved(prepared, cacheDir, args.shipDir, cell, base.get()));
      continue;
    }
    shipStored(args.shipDir, cell.key, solution, cell.solve, base.get());
    nlohmann::ordered_json shipped = {{"solve", cell.solve}, {"key", cell.key}};
    if (!cell.retryOf.empty()) {
      // The failed solve at default increments: how a fresh machine reaches its retry.
      if (!loadStoredSolution(cacheDir, cell.retryOf, solution))
        throw std::runtime_error("the failed solve " + cell.retryOf + " is not stored");
      shipStored(args.shipDir, cell.retryOf, failureRecord(solution),
                 cell.solve + ", failed at default increments: its failures alone");
      shipped["retry_of"] = cell.retryOf;
    }
    solves.push_back(shipped);
    if (!base) base = std::make_unique<ShippedBase>(shippedBase(prepared, args.shipDir, cell.key));
  }
  updateManifest(args.shipDir,
                 {{"scene", scene.name}, {"set", args.scene.overrides}, {"solves", solves}});
}

void reference(ReferenceArgs& args) {
  const LoadedScene scene = loadScene(args.scene.scene, args.scene.overrides);
  printWarnings(scene.warnings);
  printNotes(scene.notes);
  std::fprintf(stderr, "preparing %s\n", scene.name.c_str());
  const PreparedScene prepared =
      prepareScene(scene.bones, scene.muscles, scene.simulation.seed, scene.simulation.threads);
  printWarnings(prepared.report.warnings);
  printWarnings(attachmentWarnings(scene, prepared));
  ProgressLog progress;
  args.options.log = [&](const std::string& line) { progress.line(line); };
  args.options.progress = [&](const ReferenceProgress& p) {
    progress.update("ccx " + p.muscle + " (" + std::to_string(p.muscleIndex + 1) + "/" +
                        std::to_string(p.muscles) + ")",
                    p.step, p.steps, 0, p.seconds);
  };
  InterruptGuard interrupt;
  args.options.cancel = &interruptRequested;
  if (args.listCells || args.cell >= 0) {
    const std::vector<NamedReferenceCell> cells = referenceCells(scene, prepared, args.options);
    if (args.listCells) return printCells(cells);
    solveCell(scene, prepared, args, cells);
    progress.finish();
    return;
  }
  const std::string out = args.out.empty() ? "reference-" + scene.name : args.out;
  const OutputDirectory locked(out);  // a second writer into it is refused
  const Reference result = computeReference(scene, prepared, args.options);
  progress.finish();
  if (interruptRequested.load()) {
    // Nothing half-written: what was solved before the signal stays in the cache.
    std::fprintf(stderr, "interrupted: nothing written to %s\n", out.c_str());
    throw CLI::RuntimeError(interruptExitCode());
  }
  writeOut(result, out);
  if (!args.shipDir.empty()) ship(scene, prepared, args);
  std::printf("%s\n", result.description.c_str());
  std::printf("poses solved: %d/%d%s\n", result.solution.solvedPoses(),
              static_cast<int>(result.solution.poseSurfaces.size()),
              result.fromCache ? " (from the cache)" : "");
  for (const std::string& line : gateLines(result.gates)) std::printf("gate: %s\n", line.c_str());
  std::printf("wrote %s/reference.json and %zu .inp file(s) in %s/inp (cache entry %s)\n",
              out.c_str(), result.solution.inputFiles.size(), out.c_str(),
              result.cacheEntry.c_str());
}

}  // namespace

void addReferenceCommand(CLI::App& app) {
  auto args = std::make_shared<ReferenceArgs>();
  CLI::App* command = app.add_subcommand(
      "reference",
      "Solve a scene's static CalculiX reference (Neo-Hookean, tetgen mesh of each muscle "
      "surface, attachments moving with their bones), or find it in the cache; print its "
      "gates; write reference.json and the .inp files to --out.");
  addSceneArgs(*command, args->scene);
  command->add_option("--out", args->out, "Output directory (default: reference-<scene>)");
  addReferenceArgs(*command, args->options);
  command->add_flag("--cells", args->listCells,
                    "Print the reference's cells (number, solve, muscle, cache key, stored or to "
                    "solve; one muscle of the reference's or a gate's solve each) and stop");
  command
      ->add_option("--cell", args->cell,
                   "Solve this cell alone into the cache (one task of a batch engine) and stop; "
                   "a later `fibremss reference` merges the cells")
      ->check(nonNegativeInteger())
      ->excludes("--cells");
  command
      ->add_option("--ship", args->shipDir,
                   "Also write the reference's solves (its own and its gates') to this "
                   "directory as shipped references, `<key>.ref.gz`, listed in its "
                   "manifest.json (scenes/references: found by every later run with an "
                   "empty cache); of a solve not stored whole, its cells stored so far, "
                   "`<key>.m<M>.ref.gz`")
      ->excludes("--cells")
      ->excludes("--cell");
  command->callback([args] { reference(*args); });
}

}  // namespace fibremss::cli
