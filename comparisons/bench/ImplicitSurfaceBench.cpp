// `fibremss_bench --implicit-surface R [ROUNDS]`: every thigh13 muscle's implicit surface
// (ImplicitSurface.h) at rest: its distance to the skinned surface both ways (the skinned surface
// at rest is the rest surface), its open edges and pieces, and the wall time of extracting them
// all per frame with 1 and 2 threads, alternated, medians, and each muscle's alone with the wall
// time on 2 idle cores that the pool's schedule of those gives; then posed: the scene stepped
// through its first poses, the surfaces extracted after every step, and the last pose's
// extraction timed as at rest.
#include "ImplicitSurfaceBench.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <numeric>
#include <string>
#include <vector>

#include "fibremss/ImplicitSurface.h"
#include "fibremss/MuscleSystem.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "fibremss/SceneSystem.h"

namespace fibremss::bench {
namespace {

/// Steps of the posed frames, as `fibremss run thigh13 --steps 7`.
constexpr int kPosedSteps = 7;

double medianOf(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  return values[values.size() / 2];
}

/// The largest distance between two surfaces and where it is.
struct Worst {
  double distance = 0;        ///< [m]
  btVector3 vertex{0, 0, 0};  ///< the vertex farthest from the other surface [m]
  bool onSkinned = false;     ///< that vertex is the skinned surface's
};

/// Sum of the distances of the vertices of `from` to `to` [m], added to `sum`; the largest into
/// `worst` when larger.
void addDistances(const TriangleMesh& from, const TriangleMesh& to, bool fromSkinned, double& sum,
                  Worst& worst) {
  const MeshDistance distance(to);
  for (const btVector3& v : from.vertices) {
    const double d = distance.closest(v).distance;
    sum += d;
    if (d > worst.distance) worst = {d, v, fromSkinned};
  }
}

/// The distance from `x` to the muscle's nearest fixed particle at rest [m].
double fixedDistance(const MuscleSettings& muscle, const btVector3& x) {
  double nearest = SIMD_INFINITY;
  for (uint32_t p : muscle.fixedParticles)
    nearest = std::min(nearest, double((muscle.restPositions[p] - x).length()));
  return nearest;
}

/// An FNV-1a hash of a mesh's vertex coordinates and triangles, bit for bit, continuing `hash`.
uint64_t meshHash(const TriangleMesh& mesh, uint64_t hash) {
  auto add = [&](const void* data, size_t bytes) {
    for (size_t b = 0; b < bytes; ++b)
      hash = (hash ^ static_cast<const unsigned char*>(data)[b]) * 1099511628211ull;
  };
  for (const btVector3& v : mesh.vertices) add(v.m_floats, 3 * sizeof(btScalar));
  add(mesh.triangles.data(), mesh.triangles.size() * sizeof(mesh.triangles[0]));
  return hash;
}

/// The hash of every surface's mesh in turn.
uint64_t surfacesHash(const std::vector<ImplicitSurface>& surfaces) {
  uint64_t hash = 14695981039346656037ull;
  for (const ImplicitSurface& surface : surfaces) hash = meshHash(surface.mesh(), hash);
  return hash;
}

/// Prints each muscle's distances (the worst vertex: whose, its distance from the nearest fixed
/// particle), open edges and pieces, and the whole scene's.
void accuracyReport(const PreparedScene& prepared, std::vector<ImplicitSurface>& surfaces) {
  double sum = 0, worst = 0;
  size_t count = 0, open = 0;
  for (size_t m = 0; m < surfaces.size(); ++m) {
    const MuscleSettings& muscle = *prepared.muscles[m];
    surfaces[m].extract(muscle.restPositions);
    const TriangleMesh& mesh = surfaces[m].mesh();
    double muscleSum = 0;
    Worst muscleWorst;
    addDistances(mesh, muscle.restSurface, false, muscleSum, muscleWorst);
    addDistances(muscle.restSurface, mesh, true, muscleSum, muscleWorst);
    const size_t vertices = mesh.vertices.size() + muscle.restSurface.vertices.size();
    const MeshTopology topology = meshTopology(mesh);
    std::printf(
        "%-24s %7zu triangles, voxel %.2f mm, h %.2f mm: mean %.3f mm, worst %.3f mm (a %s "
        "vertex %.2f mm from a fixed particle), open edges %zu, pieces %zu\n",
        muscle.name.c_str(), mesh.triangles.size(), 1000 * surfaces[m].voxel(),
        1000 * surfaces[m].kernelRadius(), 1000 * muscleSum / double(vertices),
        1000 * muscleWorst.distance, muscleWorst.onSkinned ? "skinned" : "implicit",
        1000 * fixedDistance(muscle, muscleWorst.vertex), topology.openEdges, topology.components);
    sum += muscleSum;
    count += vertices;
    worst = std::max(worst, muscleWorst.distance);
    open += topology.openEdges;
  }
  std::printf(
      "all muscles: mean %.3f mm, worst %.3f mm to the skinned surface (both ways), "
      "open edges %zu, meshes' hash %016llx\n",
      1000 * sum / double(count), 1000 * worst, open,
      static_cast<unsigned long long>(surfacesHash(surfaces)));
}

/// The process's CPU time [ms].
double cpuMs() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return 1e3 * double(t.tv_sec) + 1e-6 * double(t.tv_nsec);
}

/// Wall and CPU time of extracting every surface from `positions` on `pool` [ms].
std::pair<double, double> frameMs(std::vector<ImplicitSurface*>& surfaces,
                                  const std::vector<std::span<const btVector3>>& positions,
                                  const std::vector<std::span<const Spring>>& springs,
                                  TaskPool& pool) {
  const auto start = std::chrono::steady_clock::now();
  const double cpuStart = cpuMs();
  extractSurfaces(surfaces, positions, springs, pool);
  return {
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count(),
      cpuMs() - cpuStart};
}

/// Every surface's pointer, positions and springs for extractSurfaces.
struct Frame {
  std::vector<ImplicitSurface*> surfaces;
  std::vector<std::span<const btVector3>> positions;
  std::vector<std::span<const Spring>> springs;
};

/// This thread's CPU time [ms].
double threadCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return 1e3 * double(t.tv_sec) + 1e-6 * double(t.tv_nsec);
}

/// Each surface's extraction alone on this thread, its CPU time's median over `rounds`, and the
/// wall time of a frame on 2 idle cores that these times give: extractSurfaces hands the
/// surfaces out in extractionOrder, each to the thread that is free first.
void scheduleReport(const Frame& frame, int rounds) {
  std::vector<std::vector<double>> times(frame.surfaces.size());
  for (int round = 0; round < rounds; ++round)
    for (size_t m = 0; m < frame.surfaces.size(); ++m) {
      const double start = threadCpuMs();
      frame.surfaces[m]->extract(frame.positions[m], frame.springs[m]);
      times[m].push_back(threadCpuMs() - start);
    }
  std::vector<double> ms;
  for (const std::vector<double>& t : times) ms.push_back(medianOf(t));
  std::array<double, 2> busy{0, 0};  // per thread: when it is free [ms]
  for (size_t m : extractionOrder(frame.surfaces, frame.positions))
    *std::min_element(busy.begin(), busy.end()) += ms[m];
  std::printf(
      "  each muscle alone on 1 thread, medians: %.2f to %.2f ms (sum %.2f ms); the 2-thread "
      "schedule of these: %.2f ms\n",
      *std::min_element(ms.begin(), ms.end()), *std::max_element(ms.begin(), ms.end()),
      std::accumulate(ms.begin(), ms.end(), 0.0), std::max(busy[0], busy[1]));
}

/// Medians over `rounds` alternated rounds of extracting `frame` on 1 and 2 threads, printed
/// under `label` with the load.
void timingReport(const char* label, Frame& frame, int rounds) {
  std::vector<double> one, two, cpuOne, cpuTwo;
  TaskPool onePool(1), twoPool(2);
  for (int round = 0; round < rounds; ++round) {
    const auto [wallOne, cpuOneRound] =
        frameMs(frame.surfaces, frame.positions, frame.springs, onePool);
    const auto [wallTwo, cpuTwoRound] =
        frameMs(frame.surfaces, frame.positions, frame.springs, twoPool);
    one.push_back(wallOne);
    two.push_back(wallTwo);
    cpuOne.push_back(cpuOneRound);
    cpuTwo.push_back(cpuTwoRound);
  }
  std::ifstream loadavg("/proc/loadavg");
  std::string load;
  std::getline(loadavg, load);
  std::printf(
      "%s, %d rounds, medians per frame: 1 thread %.2f ms (CPU %.2f ms), "
      "2 threads %.2f ms (CPU %.2f ms); load %s\n",
      label, rounds, medianOf(one), medianOf(cpuOne), medianOf(two), medianOf(cpuTwo),
      load.c_str());
  scheduleReport(frame, rounds);
}

/// The scene stepped through its first `steps` poses (as `fibremss run`), every surface
/// extracted after each step on 1 thread: CPU time per frame as it comes, pieces and open
/// edges; then the last pose's extraction timed over `rounds` rounds.
void posedReport(const LoadedScene& scene, const PreparedScene& prepared,
                 std::vector<ImplicitSurface>& surfaces, int steps, int rounds) {
  MuscleSystem system(scene.simulation);
  const SceneHandles handles = addScene(system, prepared);
  Frame frame;
  for (size_t m = 0; m < surfaces.size(); ++m) frame.surfaces.push_back(&surfaces[m]);
  TaskPool serial(1);
  for (int step = 0; step < steps; ++step) {
    const int pose = std::min(step, scene.poseCount - 1);
    for (size_t b = 0; b < handles.bones.size(); ++b)
      system.setBoneTransform(handles.bones[b], scene.bonePose(b, pose));
    system.step();
    frame.positions.clear();
    frame.springs.clear();
    for (const MuscleHandle muscle : handles.muscles) {
      frame.positions.push_back(system.positions(muscle));
      frame.springs.push_back(system.settings(muscle).springs);
    }
    const double cpu = frameMs(frame.surfaces, frame.positions, frame.springs, serial).second;
    size_t triangles = 0, open = 0, pieces = 0;
    for (const ImplicitSurface& surface : surfaces) {
      const MeshTopology topology = meshTopology(surface.mesh());
      triangles += surface.mesh().triangles.size();
      open += topology.openEdges;
      pieces += topology.components;
    }
    std::printf("pose %d: CPU %.2f ms, %zu triangles, open edges %zu, pieces %zu, hash %016llx\n",
                pose, cpu, triangles, open, pieces,
                static_cast<unsigned long long>(surfacesHash(surfaces)));
  }
  timingReport(("thigh13 posed, pose " + std::to_string(steps - 1)).c_str(), frame, rounds);
}

}  // namespace

int implicitSurfaceReport(int resolution, int rounds) {
  const LoadedScene scene = loadScene("thigh13", {"resolution=" + std::to_string(resolution)});
  const PreparedScene prepared = prepareScene(scene);
  std::vector<ImplicitSurface> surfaces;
  for (const auto& muscle : prepared.muscles) surfaces.emplace_back(muscle);
  accuracyReport(prepared, surfaces);
  Frame frame;
  for (size_t m = 0; m < surfaces.size(); ++m) {
    frame.surfaces.push_back(&surfaces[m]);
    frame.positions.push_back(prepared.muscles[m]->restPositions);
    frame.springs.push_back(prepared.muscles[m]->springs);
  }
  timingReport(("thigh13 R=" + std::to_string(resolution) + " at rest").c_str(), frame, rounds);
  posedReport(scene, prepared, surfaces, kPosedSteps, rounds);
  return 0;
}

}  // namespace fibremss::bench
