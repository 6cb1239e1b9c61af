// Memory estimate of a preparation, checked before anything is allocated: a scene that asks
// for 10^8 particles is refused with the estimate in the message instead of exhausting memory.
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include "fibremss/Error.h"
#include "fibremss/Preparation.h"

namespace fibremss {
namespace {

// Bytes per particle: positions (rest, sampled, kd-tree copy), radius, flags, bone indices,
// fibre order, kd-tree index, and the spring candidates and springs of each neighbour.
constexpr size_t kBytesPerParticle =
    3 * sizeof(btVector3) + sizeof(btScalar) + 1 + 2 * sizeof(int32_t) + 2 * sizeof(uint32_t);
constexpr size_t kBytesPerSpringCandidate = sizeof(Spring) + 2 * sizeof(uint32_t);
// Bytes per mesh triangle and vertex: the copies kept in the settings, the distance tree,
// the sphere candidates of a bone and the skinning of a muscle surface.
constexpr size_t kBytesPerTriangle = 2 * sizeof(std::array<uint32_t, 3>) + 96;
constexpr size_t kBytesPerVertex =
    3 * sizeof(btVector3) + 8 * (sizeof(uint32_t) + sizeof(btScalar));

std::string megabytes(size_t bytes) {
  return std::to_string(bytes / (1024 * 1024)) + " MiB";
}

/// MemAvailable from /proc/meminfo in bytes, or 0 when it cannot be read.
size_t availableMemory() {
  std::ifstream meminfo("/proc/meminfo");
  std::string line;
  while (std::getline(meminfo, line)) {
    std::istringstream fields(line);
    std::string key;
    size_t kibibytes = 0;
    if (fields >> key >> kibibytes && key == "MemAvailable:") return kibibytes * 1024;
  }
  return 0;
}

/// a * b, saturating at SIZE_MAX.
size_t times(size_t a, size_t b) {
  return b != 0 && a > SIZE_MAX / b ? SIZE_MAX : a * b;
}
size_t plus(size_t a, size_t b) {
  return a > SIZE_MAX - b ? SIZE_MAX : a + b;
}

}  // namespace

size_t estimatePreparationBytes(const std::vector<BoneInput>& bones,
                                const std::vector<MuscleInput>& muscles) {
  size_t bytes = 0;
  for (const auto& bone : bones) {
    bytes = plus(bytes, times(bone.mesh.triangles.size(), kBytesPerTriangle));
    bytes = plus(bytes, times(bone.mesh.vertices.size(), kBytesPerVertex));
  }
  for (const auto& muscle : muscles) {
    const size_t particles =
        times(muscle.fibres.fibreCount(), size_t(std::max(muscle.parameters.resolution, 0)));
    const size_t perParticle =
        kBytesPerParticle +
        times(size_t(std::max(muscle.parameters.springs.neighbours, 1)), kBytesPerSpringCandidate);
    bytes = plus(bytes, times(particles, perParticle));
    bytes = plus(bytes, times(muscle.surface.triangles.size(), kBytesPerTriangle));
    bytes = plus(bytes, times(muscle.surface.vertices.size(), kBytesPerVertex));
    bytes = plus(bytes, times(muscle.fibres.points.size(), sizeof(btVector3)));
  }
  return bytes;
}

size_t preparationMemoryLimit() {
  if (const char* limit = std::getenv("FIBREMSS_MEMORY_LIMIT_MB")) {
    char* end = nullptr;
    const unsigned long long megabytes = std::strtoull(limit, &end, 10);
    if (end != limit && *end == '\0' && megabytes > 0) return times(megabytes, 1024 * 1024);
  }
  const size_t available = availableMemory();
  return available > 0 ? available : SIZE_MAX;
}

void requirePreparationMemory(const std::vector<BoneInput>& bones,
                              const std::vector<MuscleInput>& muscles) {
  const size_t estimate = estimatePreparationBytes(bones, muscles);
  const size_t limit = preparationMemoryLimit();
  if (estimate <= limit) return;
  size_t particles = 0;
  for (const auto& muscle : muscles)
    particles = plus(particles, times(muscle.fibres.fibreCount(),
                                      size_t(std::max(muscle.parameters.resolution, 0))));
  throw InputError("scene", "size",
                   "preparation would need about " + megabytes(estimate) + " (" +
                       std::to_string(particles) + " particles) but the limit is " +
                       megabytes(limit) +
                       " (available memory, or FIBREMSS_MEMORY_LIMIT_MB); lower the "
                       "resolution or fibre_count");
}

}  // namespace fibremss
