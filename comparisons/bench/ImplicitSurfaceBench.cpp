// `fibremss_bench --implicit-surface R [ROUNDS]`: every thigh13 muscle's implicit surface
// (ImplicitSurface.h) at rest: its distance to the skinned surface both ways (the skinned surface
// at rest is the rest surface), its open edges and pieces, and the wall time of extracting them
// all per frame with 1 and 2 threads, alternated, medians.
#include "ImplicitSurfaceBench.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <string>
#include <vector>

#include "fibremss/ImplicitSurface.h"
#include "fibremss/Preparation.h"
#include "fibremss/Scene.h"
#include "fibremss/SceneSystem.h"

namespace fibremss::bench {
namespace {

double medianOf(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  return values[values.size() / 2];
}

/// Sum and largest distance of the vertices of `from` to `to` [m], added to `sum`, `worst`.
void addDistances(const TriangleMesh& from, const TriangleMesh& to, double& sum, double& worst) {
  const MeshDistance distance(to);
  for (const btVector3& v : from.vertices) {
    const double d = distance.closest(v).distance;
    sum += d;
    worst = std::max(worst, d);
  }
}

/// Prints each muscle's distances, open edges and pieces, and the whole scene's.
void accuracyReport(const PreparedScene& prepared, std::vector<ImplicitSurface>& surfaces) {
  double sum = 0, worst = 0;
  size_t count = 0, open = 0;
  for (size_t m = 0; m < surfaces.size(); ++m) {
    const MuscleSettings& muscle = *prepared.muscles[m];
    surfaces[m].extract(muscle.restPositions);
    const TriangleMesh& mesh = surfaces[m].mesh();
    double muscleSum = 0, muscleWorst = 0;
    addDistances(mesh, muscle.restSurface, muscleSum, muscleWorst);
    addDistances(muscle.restSurface, mesh, muscleSum, muscleWorst);
    const size_t vertices = mesh.vertices.size() + muscle.restSurface.vertices.size();
    const MeshTopology topology = meshTopology(mesh);
    std::printf(
        "%-24s %7zu triangles, voxel %.2f mm, h %.2f mm: mean %.3f mm, worst %.3f mm, "
        "open edges %zu, pieces %zu\n",
        muscle.name.c_str(), mesh.triangles.size(), 1000 * surfaces[m].voxel(),
        1000 * surfaces[m].kernelRadius(), 1000 * muscleSum / double(vertices), 1000 * muscleWorst,
        topology.openEdges, topology.components);
    sum += muscleSum;
    count += vertices;
    worst = std::max(worst, muscleWorst);
    open += topology.openEdges;
  }
  std::printf(
      "all muscles: mean %.3f mm, worst %.3f mm to the skinned surface (both ways), "
      "open edges %zu\n",
      1000 * sum / double(count), 1000 * worst, open);
}

/// The process's CPU time [ms].
double cpuMs() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return 1e3 * double(t.tv_sec) + 1e-6 * double(t.tv_nsec);
}

/// Wall and CPU time of extracting every surface from `positions` on `threads` threads [ms].
std::pair<double, double> frameMs(std::vector<ImplicitSurface*>& surfaces,
                                  const std::vector<std::span<const btVector3>>& positions,
                                  const std::vector<std::span<const Spring>>& springs,
                                  unsigned threads) {
  const auto start = std::chrono::steady_clock::now();
  const double cpuStart = cpuMs();
  extractSurfaces(surfaces, positions, springs, threads);
  return {
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count(),
      cpuMs() - cpuStart};
}

}  // namespace

int implicitSurfaceReport(int resolution, int rounds) {
  const LoadedScene scene = loadScene("thigh13", {"resolution=" + std::to_string(resolution)});
  const PreparedScene prepared = prepareScene(scene);
  std::vector<ImplicitSurface> surfaces;
  for (const auto& muscle : prepared.muscles) surfaces.emplace_back(muscle);
  accuracyReport(prepared, surfaces);
  std::vector<ImplicitSurface*> pointers;
  std::vector<std::span<const btVector3>> positions;
  std::vector<std::span<const Spring>> springs;
  for (size_t m = 0; m < surfaces.size(); ++m) {
    pointers.push_back(&surfaces[m]);
    positions.push_back(prepared.muscles[m]->restPositions);
    springs.push_back(prepared.muscles[m]->springs);
  }
  std::vector<double> one, two, cpuOne, cpuTwo;
  for (int round = 0; round < rounds; ++round) {
    const auto [wallOne, cpuOneRound] = frameMs(pointers, positions, springs, 1);
    const auto [wallTwo, cpuTwoRound] = frameMs(pointers, positions, springs, 2);
    one.push_back(wallOne);
    two.push_back(wallTwo);
    cpuOne.push_back(cpuOneRound);
    cpuTwo.push_back(cpuTwoRound);
  }
  std::ifstream loadavg("/proc/loadavg");
  std::string load;
  std::getline(loadavg, load);
  std::printf(
      "thigh13 R=%d, %d rounds, medians per frame: 1 thread %.2f ms (CPU %.2f ms), "
      "2 threads %.2f ms (CPU %.2f ms); load %s\n",
      resolution, rounds, medianOf(one), medianOf(cpuOne), medianOf(two), medianOf(cpuTwo),
      load.c_str());
  return 0;
}

}  // namespace fibremss::bench
