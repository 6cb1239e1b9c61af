#pragma once
// The CalculiX reference's cache: a solve is stored under a key hashed from everything it
// depends on (the bones' rest meshes and every pose of their motion, the prepared rest
// surfaces, the attachment rule, the material, element, mesher settings, the ccx version), in
// its own directory beside the .inp files it was solved from.
#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "fibremss/CalculixReference.h"

namespace fibremss {

/// 16 hex digits (FNV-1a, 64 bits) of the reference's inputs (above). The scene's solver
/// settings (iterations, dt, resolution's springs) are not part of it: they do not change the
/// static reference.
/// `cut`: findContinuumCut at the definition's attachment scale (hashed only where there is
/// one, so that scenes without a cut keep their keys).
std::string referenceCacheKey(const LoadedScene& scene, const PreparedScene& prepared,
                              const CalculixDefinition& definition, const ContinuumCut& cut);

/// $FIBREMSS_CACHE, else $XDG_CACHE_HOME/fibremss, else $HOME/.cache/fibremss; then
/// "/reference".
std::string defaultReferenceCacheDir();

/// Writes the solution (binary, all poses, failures and counts; its muscles' parts where it
/// keeps them, as version 2, else version 1) to `path` atomically (a temporary file renamed).
/// Throws std::runtime_error when it cannot be written.
void saveSolution(const std::string& path, const CalculixSolution& solution);

/// Reads what saveSolution wrote; false when `path` does not exist. Throws InputError when it
/// is not such a file (truncated, other format).
bool loadSolution(const std::string& path, CalculixSolution& solution);

/// The quantum of a shipped gate's surfaces where they are stored in quanta (shipSolution) [m]:
/// 1 µm, far below the gates' 0.1 mm.
constexpr double kShippedGateQuantum = 1e-6;

/// The solve a shipped gate is stored against: its reference's, shipped in the same directory.
struct ShippedBase {
  std::string key;                       ///< its key: `<key>.ref.gz` beside the gate
  CalculixSolution solution;             ///< as loadShippedSolution reads that file back
  std::vector<uint64_t> muscleVertices;  ///< each muscle's surface vertex count, in muscle order
};

/// Writes `solution` as a shipped reference to `path` (`<key>.ref.gz` in a directory of
/// shippedReferenceDirs): gzip-compressed, without the names of its .inp files; its muscles'
/// parts where it keeps them (as version 2, as saveSolution); atomically. Positions as floats
/// (about 10⁻⁵ mm on a muscle of 0.5 m); with a `base` (a gate's, version 3), each surface as
/// its difference from the nearest surface of its size the reader already has (the base's,
/// whole or one muscle's part, or one before it in the file): in float ulps, exactly as the
/// floats, where it lies within a quantum of it, else in quanta of kShippedGateQuantum (within half
/// a quantum and a float's rounding). Throws std::runtime_error when it cannot be written.
void shipSolution(const std::string& path, const CalculixSolution& solution,
                  const ShippedBase* base = nullptr);

/// Reads what shipSolution wrote (a gate's base from the same directory); false when `path`
/// does not exist. Throws InputError when it is not such a file (not gzip, truncated, other
/// format, a gate whose base is not beside it).
bool loadShippedSolution(const std::string& path, CalculixSolution& solution);

/// Writes muscle `m`'s part of a solve (a cell stored alone, cachedCalculixMuscle) as a shipped
/// file to `path` (`<key>.m<m>.ref.gz`, shippedPartName): as shipSolution writes a solve, its
/// step surfaces as floats or against `base`, without the name of its .inp file (its ccx files
/// stay on the machine that solved it). Throws std::runtime_error when it cannot be written.
void shipPart(const std::string& path, const MuscleSolution& part,
              const ShippedBase* base = nullptr);

/// Reads what shipPart wrote (its base from the same directory); false when `path` does not
/// exist. Throws InputError when it is not such a file.
bool loadShippedPart(const std::string& path, MuscleSolution& part);

/// The name of muscle `m`'s part of the solve `key` shipped alone: `<key>.m<m>.ref.gz`.
std::string shippedPartName(const std::string& key, size_t m);

/// Where shipped references (solves computed once and kept with FibreMSS, scenes/references)
/// are looked for, in this order: $FIBREMSS_REFERENCES, the source tree's scenes/references,
/// share/fibremss/references of the install the library was loaded from.
std::vector<std::string> shippedReferenceDirs();

/// `<dir>/<key>.ref.gz` in the first of shippedReferenceDirs that holds it; "" when none does.
std::string shippedReferencePath(const std::string& key);

/// The solution stored under `key`: the cache's `cacheDir/<key>/surfaces.bin`, else a shipped
/// reference (shippedReferencePath); false when neither exists. `shippedFrom` (may be null): the
/// shipped file it was read from, "" when it came from the cache.
bool loadStoredSolution(const std::string& cacheDir, const std::string& key,
                        CalculixSolution& solution, std::string* shippedFrom = nullptr);

/// The solution stored under the key in `cacheDir/<key>/` or shipped (loadStoredSolution); else,
/// where muscles of it were solved as parts (cachedCalculixMuscle; or shipped, shipPart) or
/// `jobs` > 1, its parts, the missing ones solved `jobs` at a time, merged into `<key>/`
/// (mergeCalculixParts); else solved (solveCalculixReference) in `cacheDir/<key>.solving-<pid>/`,
/// which becomes `<key>/` once stored (removed when interrupted), so that processes solving the
/// same key at once never share ccx's files; when another one stored it first, its solution is
/// returned. Either way the entry holds the same files and solution. `fromCache` (may be null)
/// tells whether it came from the cache. A definition with per-muscle increments is solved as parts
/// (so that muscles at other increments are taken as cachedCalculixMuscle says).
CalculixSolution cachedCalculixReference(
    const LoadedScene& scene, const PreparedScene& prepared, const CalculixDefinition& definition,
    const ContinuumCut& cut, const std::string& cacheDir,
    const std::function<void(const ReferenceProgress&)>& progress, const std::atomic<bool>* cancel,
    bool* fromCache, int jobs = 1);

/// Where muscle `m`'s part of the solve `key` is kept: `cacheDir/<key>.parts/muscle<m>/`.
std::string referencePartDir(const std::string& cacheDir, const std::string& key, size_t m);

/// Whether the solve `key` is stored whole (`<key>/surfaces.bin`, or shipped) or muscle `m`'s part
/// of it (in the cache, or shipped: loadStoredPart).
bool referencePartStored(const std::string& cacheDir, const std::string& key, size_t m);

/// Muscle `m`'s part of the solve `key` stored alone: the cache's (referencePartDir), else shipped
/// (shippedPartName in shippedReferenceDirs, without input file); false when neither exists.
bool loadStoredPart(const std::string& cacheDir, const std::string& key, size_t m,
                    MuscleSolution& part);

/// Muscle `m`'s part of the solve `key` stored whole (loadStoredSolution) where that solve keeps
/// its muscles' parts (CalculixSolution::muscles) and muscle `m` solved every step; else false.
bool loadSolvedPart(const std::string& cacheDir, const std::string& key, size_t m,
                    MuscleSolution& part);

/// Where the solve of `definition` is stored in the cache (with its ccx files) with a pose or
/// return step ccx failed but without its muscles' parts (stored before they were kept): reads
/// them from its ccx files (readSolvedMuscle: tetgen, no ccx), into `solution` and its entry's
/// surfaces.bin, so that its retry solves again only the muscles ccx failed. False (nothing
/// changed) where it keeps its parts already, is not such a solve, is shipped, or its files do
/// not give back the solution it stored.
bool recoverCalculixParts(const LoadedScene& scene, const PreparedScene& prepared,
                          const CalculixDefinition& definition, const ContinuumCut& cut,
                          const std::string& cacheDir, CalculixSolution& solution);

/// Where muscle `m` of `definition` is at other increments than the solve's own
/// (CalculixDefinition::muscleIncrementScales): the key of the solve of every muscle at its
/// (muscleDefinition), from which cachedCalculixMuscle takes its part; else "".
std::string keptPartKey(const LoadedScene& scene, const PreparedScene& prepared,
                        const CalculixDefinition& definition, const ContinuumCut& cut, size_t m);

/// Solves muscle `m` of the solve (solveCalculixMuscle) into its part directory (through
/// `<part>.solving-<pid>/`, as a whole solve), unless the solve or that part is stored already
/// (in the cache or shipped: true, nothing to do) or it was interrupted (false; nothing kept).
/// A part that hit the memory limit is solved again. A muscle at other increments than the
/// solve's is taken, without ccx, from the solve keptPartKey names where that keeps it solved
/// (loadSolvedPart; its files too where they are in the cache). One cell of a reference for a
/// batch engine.
bool cachedCalculixMuscle(const LoadedScene& scene, const PreparedScene& prepared,
                          const CalculixDefinition& definition, const ContinuumCut& cut,
                          const std::string& cacheDir, size_t m,
                          const std::function<void(const ReferenceProgress&)>& progress,
                          const std::atomic<bool>* cancel);

/// A cell of a reference: one muscle of one solve (the reference's or a gate's).
struct ReferenceCell {
  CalculixDefinition definition;  ///< the solve's
  ContinuumCut cut;               ///< its continuum cut (findContinuumCut at its attachment scale)
  size_t muscle = 0;              ///< index into the prepared muscles
};

/// Solves the cells not stored yet (cachedCalculixMuscle) `jobs` at a time, each a ccx process
/// of its own, in the order given; after the first one that cannot be started, no further cell
/// starts, and its error is rethrown once the running ones end. `progress` is called from one
/// thread at a time.
void solveCalculixCells(const LoadedScene& scene, const PreparedScene& prepared,
                        const std::vector<ReferenceCell>& cells, const std::string& cacheDir,
                        const std::function<void(const ReferenceProgress&)>& progress,
                        const std::atomic<bool>* cancel, int jobs);

/// Merges the solve's parts into its entry `cacheDir/<key>/` (their files and one
/// surfaces.bin, as a whole solve stores them) once every muscle's part is stored (in the
/// cache, or shipped: loadStoredPart; a shipped part brings no files), and removes the cache's
/// parts; false (nothing changed) while one is missing. The solution is the serial
/// solve's (its seconds, the parts' summed, are measured times).
bool mergeCalculixParts(const LoadedScene& scene, const PreparedScene& prepared,
                        const CalculixDefinition& definition, const ContinuumCut& cut,
                        const std::string& cacheDir, CalculixSolution& solution);

}  // namespace fibremss
