#pragma once
// The CalculiX reference's cache: a solve is stored under a key hashed from everything it
// depends on (the bones' rest meshes and every pose of their motion, the prepared rest
// surfaces, the attachment rule, the material, element, mesher settings, the ccx version), in
// its own directory beside the .inp files it was solved from.
#include <atomic>
#include <functional>
#include <string>

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

/// Writes the solution (binary, all poses, failures and counts) to `path` atomically (a
/// temporary file renamed). Throws std::runtime_error when it cannot be written.
void saveSolution(const std::string& path, const CalculixSolution& solution);

/// Reads what saveSolution wrote; false when `path` does not exist. Throws InputError when it
/// is not such a file (truncated, other format).
bool loadSolution(const std::string& path, CalculixSolution& solution);

/// The solution stored under the key in `cacheDir/<key>/` or, when absent, solved
/// (solveCalculixReference) in `cacheDir/<key>.solving-<pid>/`, which becomes `<key>/` once
/// stored (removed when interrupted), so that processes solving the same key at once never
/// share ccx's files; when another one stored it first, its solution is returned. `fromCache`
/// (may be null) tells whether it came from the cache.
CalculixSolution cachedCalculixReference(
    const LoadedScene& scene, const PreparedScene& prepared, const CalculixDefinition& definition,
    const ContinuumCut& cut, const std::string& cacheDir,
    const std::function<void(const ReferenceProgress&)>& progress, const std::atomic<bool>* cancel,
    bool* fromCache);

}  // namespace fibremss
