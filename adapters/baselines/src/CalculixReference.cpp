// The CalculiX static reference: per muscle a tetgen mesh, its attached nodes, one ccx job with
// a step per pose (and steps back to rest), the printed surface displacements read back.
#include "fibremss/CalculixReference.h"

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <utility>

#include "fibremss/DeclaredAreas.h"
#include "fibremss/Error.h"

namespace fibremss {
namespace {

using Clock = std::chrono::steady_clock;

/// What a failure says after an allocation error when ccx ran under a memory limit.
constexpr const char* kMemoryLimitNote = "ccx's memory limit is ";

double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

/// A muscle's ccx job and where its files are.
struct MuscleJob {
  CalculixJob job;
  size_t surfaceVertices = 0;  ///< printed nodes: the surface vertices 0..n-1
  size_t tetrahedra = 0;
  std::string stem;          ///< file stem in the work directory
  size_t attachedNodes = 0;  ///< the muscle's nodes that move with a bone
  /// Surface vertices preparation moved (out of a bone): they move with the bone they are
  /// attached to, so per step their position is that bone's transform of the prepared vertex.
  std::vector<uint32_t> moved;
  std::vector<std::vector<btVector3>> movedPositions;  ///< per step, per moved vertex [m]
};

/// Nodes within `distance` of a bone (or inside it), each with its nearest bone.
void attach(const std::vector<btVector3>& nodes, const std::vector<MeshDistance>& bones,
            btScalar distance, std::vector<uint32_t>& attached, std::vector<int>& boneOf) {
  for (size_t n = 0; n < nodes.size(); ++n) {
    int nearest = -1;
    btScalar best = distance;
    for (size_t b = 0; b < bones.size(); ++b) {
      const btScalar d = bones[b].signedDistance(nodes[n]);
      if (d < best) {
        best = d;
        nearest = static_cast<int>(b);
      }
    }
    if (nearest >= 0) {
      attached.push_back(static_cast<uint32_t>(n));
      boneOf.push_back(nearest);
    }
  }
}

/// The bones' distance trees as declaredAreaBones takes them.
std::vector<const MeshDistance*> trees(const std::vector<MeshDistance>& bones) {
  std::vector<const MeshDistance*> pointers;
  for (const MeshDistance& bone : bones) pointers.push_back(&bone);
  return pointers;
}

/// Per vertex of `surface`, whether it lies in an area's end sunk in a bone: the vertices
/// `fixed` marks and those joined to them by edges through vertices inside a bone.
std::vector<bool> sunkEnds(const TriangleMesh& surface, const std::vector<MeshDistance>& bones,
                           std::vector<bool> fixed) {
  std::vector<bool> inside(surface.vertices.size(), false);
  for (size_t v = 0; v < inside.size(); ++v)
    for (const MeshDistance& bone : bones)
      inside[v] = inside[v] || bone.signedDistance(surface.vertices[v]) < 0;
  for (bool grown = true; grown;) {
    grown = false;
    for (const auto& t : surface.triangles)
      for (int i = 0; i < 3; ++i) {
        const uint32_t from = t[size_t(i)], to = t[size_t((i + 1) % 3)];
        for (const auto& [a, b] : {std::pair{from, to}, std::pair{to, from}})
          if (fixed[a] && !fixed[b] && inside[b]) grown = fixed[b] = true;
      }
  }
  return fixed;
}

/// The surface a muscle that declares its areas is meshed as: as prepared (its free part moved
/// out of the bones), but its areas' ends as loaded (sunkEnds from the vertices the areas fix,
/// declaredAreaBones at `distance`): moved out, the ends sunk in their bones fold the surface
/// onto itself (tetgen refuses it); fixed, they may stay inside.
TriangleMesh declaredSurface(const MuscleInput& input, const MuscleSettings& muscle,
                             const std::vector<MeshDistance>& bones, btScalar distance) {
  const std::vector<btVector3>& prepared = muscle.restSurface.vertices;
  const std::vector<int32_t> fixedTo =
      declaredAreaBones(input.attachments, distance, prepared, trees(bones), prepared);
  std::vector<bool> fixed(prepared.size());
  for (size_t v = 0; v < prepared.size(); ++v) fixed[v] = fixedTo[v] >= 0;
  const std::vector<bool> sunk = sunkEnds(input.surface, bones, std::move(fixed));
  TriangleMesh surface = muscle.restSurface;
  for (size_t v = 0; v < prepared.size(); ++v)
    if (sunk[v]) surface.vertices[v] = input.surface.vertices[v];
  return surface;
}

/// Nodes the muscle's declared areas fix (declaredAreaBones at `distance`; a surface node where
/// its vertex was prepared), each with its bone, and the free nodes that lie inside a bone at
/// rest (next to an area's end sunk in it), each with that bone.
void attachDeclared(const MuscleInput& input, const MuscleSettings& muscle,
                    const std::vector<btVector3>& nodes, const std::vector<MeshDistance>& bones,
                    btScalar distance, std::vector<uint32_t>& attached, std::vector<int>& boneOf) {
  std::vector<btVector3> at = nodes;
  std::copy(muscle.restSurface.vertices.begin(), muscle.restSurface.vertices.end(), at.begin());
  const std::vector<int32_t> fixedTo =
      declaredAreaBones(input.attachments, distance, muscle.restSurface.vertices, trees(bones), at);
  for (size_t n = 0; n < nodes.size(); ++n) {
    int bone = fixedTo[n];
    for (size_t b = 0; bone < 0 && b < bones.size(); ++b)
      if (bones[b].signedDistance(nodes[n]) < 0) bone = static_cast<int>(b);
    if (bone < 0) continue;
    attached.push_back(static_cast<uint32_t>(n));
    boneOf.push_back(bone);
  }
}

/// A body no bone holds, squeezed between symmetric plates (sphere-planes): its rigid-body
/// modes, which a static solve cannot take (frictionless contact resists no rotation of a
/// sphere about its centre), held without changing the answer. By the plates' symmetry the
/// centre stays, the mid-plane stays a plane and nothing turns about the axis: the node nearest
/// the centre is fixed, and of the nodes farthest from the axis (within 10 % of it) the one
/// nearest the mid-plane, A, and the one most nearly a quarter turn from it, B, keep their
/// axial place; A also keeps its place around the axis. Returns the fixed node.
uint32_t holdBySymmetry(CalculixJob& job, const AnalyticCase& analytic) {
  const btVector3 centre = analytic.axisStart;
  const btVector3 axis = (analytic.axisEnd - analytic.axisStart).normalized();
  auto offAxis = [&](uint32_t n) {
    const btVector3 d = job.nodes[n] - centre;
    return d - axis * d.dot(axis);
  };
  uint32_t fixed = 0;
  btScalar widest = 0;
  for (uint32_t n = 0; n < job.nodes.size(); ++n) {
    if (job.nodes[n].distance2(centre) < job.nodes[fixed].distance2(centre)) fixed = n;
    widest = std::max(widest, offAxis(n).length());
  }
  // A: the widest nodes' nearest to the mid-plane; B: theirs most nearly a quarter turn from A.
  const auto wide = [&](uint32_t n) { return offAxis(n).length() >= btScalar(0.9) * widest; };
  const auto height = [&](uint32_t n) { return std::abs((job.nodes[n] - centre).dot(axis)); };
  uint32_t a = fixed, b = fixed;
  for (uint32_t n = 0; n < job.nodes.size(); ++n)
    if (wide(n) && (a == fixed || height(n) < height(a))) a = n;
  const btVector3 around = axis.cross(offAxis(a)).normalized();
  const auto turn = [&](uint32_t n) { return offAxis(n).normalized().dot(around); };
  for (uint32_t n = 0; n < job.nodes.size(); ++n)
    if (wide(n) && (b == fixed || turn(n) > turn(b))) b = n;
  job.equations = {{a, around}, {a, axis}, {b, axis}};
  return fixed;
}

/// The job's elements (C3D4, or C3D10 with midside nodes) on the mesh.
void setElements(CalculixJob& job, const TetMesh& mesh) {
  if (job.element == CalculixElement::C3D10) {
    job.nodes = quadraticTetrahedra(mesh, job.connectivity);
    return;
  }
  job.nodes = mesh.nodes;
  for (const auto& t : mesh.tetrahedra)
    job.connectivity.insert(job.connectivity.end(), t.begin(), t.end());
}

/// Bone b's transform of pose p (the rest pose after the last one: the return step).
btTransform stepTransform(const LoadedScene& scene, size_t bone, int pose) {
  return pose >= 0 ? scene.bonePose(bone, pose) : btTransform::getIdentity();
}

/// The largest turn of any bone between poses `from` and `to` (-1: rest) [°].
double largestTurnDeg(const LoadedScene& scene, size_t bones, int from, int to) {
  double largest = 0;
  for (size_t b = 0; b < bones; ++b) {
    const btQuaternion q =
        (stepTransform(scene, b, to) * stepTransform(scene, b, from).inverse()).getRotation();
    const double w = std::min(1.0, std::abs(double(q.w())));
    largest = std::max(largest, 2 * std::acos(w) * 180 / M_PI);
  }
  return largest;
}

/// The largest move of an attached node within step s against the rigid motion `frame` [m].
double largestMove(const CalculixJob& job, size_t s, const btTransform& frame) {
  double move = 0;
  for (size_t i = 0; i < job.prescribed.size(); ++i) {
    const btVector3& x = job.nodes[job.prescribed[i]];
    const btVector3 from = x + (s == 0 ? btVector3(0, 0, 0) : job.steps[s - 1][i]);
    move = std::max(move, double((x + job.steps[s][i] - frame * from).length()));
  }
  return move;
}

/// The largest move of an attached node within step s [m] by the rule (IncrementRule): in the
/// world, or against the rigid step of the bone (or the world) in whose frame it is smallest.
double stepMove(const LoadedScene& scene, size_t bones, const std::vector<int>& steps,
                const CalculixJob& job, size_t s, IncrementRule rule) {
  double move = largestMove(job, s, btTransform::getIdentity());
  const int from = s == 0 ? -1 : steps[s - 1];
  for (size_t b = 0; rule == IncrementRule::BoneFrame && b < bones; ++b)
    move = std::min(move, largestMove(job, s,
                                      stepTransform(scene, b, steps[s]) *
                                          stepTransform(scene, b, from).inverse()));
  return move;
}

/// The largest increment of each of the job's steps (share of it): no bone turns more than
/// 2.5° and no attached node moves more than 1 mm (stepMove: with the bone-frame rule, beyond
/// the rigid motion of the frame it moves least in) within one, both × `scale`
/// (CalculixDefinition::incrementScale). ccx's Newton on a twisted
/// cylinder (C3D4, ν 0.49) diverged on 5° increments from 25° of twist on, converged in 2
/// iterations on 1.25° ones, and ended on a NaN within a 45° step whose increments it let grow
/// to 11°; pinch's step back from pose 1 (7 mm) ended on a NaN at its second try, 1.75 mm.
std::vector<double> maximumIncrements(const LoadedScene& scene, size_t bones,
                                      const std::vector<int>& steps, const CalculixJob& job,
                                      const CalculixDefinition& definition) {
  const double turnDeg = 2.5 * definition.incrementScale;
  const double moveBound = 1e-3 * definition.incrementScale;
  std::vector<double> largest;
  for (size_t s = 0; s < steps.size(); ++s) {
    const double turn = largestTurnDeg(scene, bones, s == 0 ? -1 : steps[s - 1], steps[s]);
    const double move = stepMove(scene, bones, steps, job, s, definition.incrementRule);
    largest.push_back(
        std::min({1.0, turnDeg / std::max(turn, 1e-9), moveBound / std::max(move, 1e-12)}));
  }
  return largest;
}

/// The pose each step of the job ends at (-1: rest): the first `poses` poses, then with
/// `returnToRest` back to rest retracing them, each return step to the earliest pose (or rest)
/// that no bone turns more than kReturnTurnDeg from. Within a step ccx moves a prescribed node
/// along a straight line: a bone turned 180° straight back would pass its nodes through its
/// axis (cylinder-twist's return), a turn of 45° squeezes them by 8 % at most on the way.
std::vector<int> stepPoses(const LoadedScene& scene, size_t bones, int poses, bool returnToRest) {
  constexpr double kReturnTurnDeg = 45;
  std::vector<int> steps;
  for (int p = 0; p < poses; ++p) steps.push_back(p);
  for (int at = poses - 1; returnToRest && (steps.empty() || steps.back() >= 0);) {
    int to = -1;
    // 0.001° of slack: a float rotation of exactly 45° reads back as 45.0001°.
    while (to < at - 1 && largestTurnDeg(scene, bones, at, to) > kReturnTurnDeg + 1e-3) ++to;
    steps.push_back(to);
    at = to;
  }
  return steps;
}

/// The bones as rigid contact obstacles of the job (CalculixContact): each bone's rest surface
/// as an obstacle mesh (obstacleMesh: its triangles the master surface; thigh13's pelvis
/// intersects itself at its bends, which tetgen refuses), its nodes appended and prescribed to
/// follow the bone at every step, the muscle's free surface nodes (midside nodes of C3D10
/// included) the slaves.
void addBoneContact(MuscleJob& result, const LoadedScene& scene, const PreparedScene& prepared,
                    const CalculixDefinition& definition, const std::vector<int>& steps) {
  CalculixJob& job = result.job;
  CalculixContact& contact = job.contact;
  for (size_t b = 0; b < prepared.bones.size(); ++b) {
    const ObstacleMesh bone = obstacleMesh(prepared.bones[b]->mesh);
    const auto first = static_cast<uint32_t>(job.nodes.size());
    const auto elements = static_cast<uint32_t>(contact.tetrahedra.size() / 4);
    for (const btVector3& x : bone.nodes) {
      job.prescribed.push_back(static_cast<uint32_t>(job.nodes.size()));
      job.nodes.push_back(x);
      for (size_t s = 0; s < steps.size(); ++s)
        job.steps[s].push_back(stepTransform(scene, b, steps[s]) * x - x);
    }
    for (uint32_t corner : bone.tetrahedra) contact.tetrahedra.push_back(first + corner);
    for (const auto& [element, face] : bone.faces)
      contact.faces.emplace_back(elements + element, face);
  }
  std::vector<bool> held(job.nodes.size(), false);
  for (uint32_t n : job.prescribed) held[n] = true;
  for (uint32_t n : surfaceNodes(job, result.surfaceVertices))
    if (!held[n]) contact.slaves.push_back(n);
  contact.stiffness = definition.contactPenalty * definition.material.youngsModulus;
  contact.tension = 1e-3 * definition.material.youngsModulus;
  contact.sliding = definition.contactSliding;
}

/// Meshes the muscle's surface and attaches its nodes, and prescribes their displacement per
/// step: the first step to its pose of `steps` (stepPoses). A muscle that declares its areas
/// (MuscleInput::attachments) is meshed as prepared (preparation moved its surface out of the
/// bones, so no free node starts inside one) and attached by the areas' rule
/// (declaredAreaBones): its belly is free and meets the bones through contact. Any other is
/// meshed as loaded (preparation's push out of the bones makes the prepared surface
/// self-intersect where it overlapped a bone) and attached wherever within the attachment
/// distance of a bone (attach).
MuscleJob muscleJob(const LoadedScene& scene, const PreparedScene& prepared, size_t m,
                    const std::vector<MeshDistance>& bones, const CalculixDefinition& definition,
                    const std::string& workDir, const std::vector<int>& steps) {
  const MuscleSettings& muscle = *prepared.muscles[m];
  const MuscleInput& input = scene.muscles[m];
  const bool declared = !input.attachments.empty();
  if (input.surface.vertices.size() != muscle.restSurface.vertices.size()) {
    throw InputError("muscles[" + std::to_string(m) + "]", muscle.name,
                     "the prepared surface has other vertices than the loaded one");
  }
  const btScalar distance = input.parameters.attachmentDistance * definition.attachmentScale;
  const TriangleMesh meshed =
      declared ? declaredSurface(input, muscle, bones, distance) : input.surface;
  MuscleJob result;
  result.stem = "muscle" + std::to_string(m);
  const TetMesh mesh = tetgenMesh(meshed, definition.mesher, workDir, result.stem);
  result.surfaceVertices = meshed.vertices.size();
  result.tetrahedra = mesh.tetrahedra.size();
  CalculixJob& job = result.job;
  job.title = "muscle " + muscle.name + " of scene " + scene.name;
  job.element = definition.element;
  job.material = definition.material;
  job.initialIncrement = definition.initialIncrement;
  setElements(job, mesh);
  std::vector<int> boneOf;
  if (declared)
    attachDeclared(input, muscle, job.nodes, bones, distance, job.prescribed, boneOf);
  else
    attach(job.nodes, bones, distance, job.prescribed, boneOf);
  const bool symmetric = job.prescribed.empty() && scene.analytic.type == "sphere-planes";
  if (job.prescribed.empty() && !symmetric) {
    throw InputError("muscles[" + std::to_string(m) + "]", muscle.name,
                     "no material within the attachment distance (" +
                         std::to_string(distance * 1000) +
                         " mm) of a bone: the static reference needs the muscle held");
  }
  for (const int pose : steps) {
    std::vector<btVector3>& u = job.steps.emplace_back();
    for (size_t i = 0; i < job.prescribed.size(); ++i) {
      const btVector3& x = job.nodes[job.prescribed[i]];
      u.push_back(stepTransform(scene, static_cast<size_t>(boneOf[i]), pose) * x - x);
    }
  }
  job.maximumIncrements = maximumIncrements(scene, prepared.bones.size(), steps, job, definition);
  // Prescribed nodes are ascending: the surface vertices among them come first.
  result.movedPositions.resize(steps.size());
  for (size_t i = 0; i < job.prescribed.size() && job.prescribed[i] < meshed.vertices.size(); ++i) {
    const uint32_t v = job.prescribed[i];
    if (muscle.restSurface.vertices[v] == meshed.vertices[v]) continue;
    result.moved.push_back(v);
    for (size_t s = 0; s < steps.size(); ++s)
      result.movedPositions[s].push_back(
          stepTransform(scene, static_cast<size_t>(boneOf[i]), steps[s]) *
          muscle.restSurface.vertices[v]);
  }
  for (uint32_t v = 0; v < result.surfaceVertices; ++v) job.printed.push_back(v);
  result.attachedNodes = job.prescribed.size();
  if (symmetric) {
    job.prescribed.push_back(holdBySymmetry(job, scene.analytic));
    for (std::vector<btVector3>& u : job.steps) u.emplace_back(0, 0, 0);
  }
  if (definition.contactPenalty > 0) addBoneContact(result, scene, prepared, definition, steps);
  return result;
}

/// ccx's .sta rows: step, increment, attempt, iterations, total time, step time, increment.
struct StaSummary {
  int stepsDone = 0;
  long increments = 0;
  long iterations = 0;
};

StaSummary readSta(const std::string& path) {
  StaSummary summary;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream row(line);
    int step = 0, increment = 0, attempt = 0, iterations = 0;
    double total = 0, stepTime = 0;
    if (!(row >> step >> increment >> attempt >> iterations >> total >> stepTime)) continue;
    ++summary.increments;
    summary.iterations += iterations;
    if (std::abs(stepTime - 1) < 1e-6) summary.stepsDone = std::max(summary.stepsDone, step);
  }
  return summary;
}

/// The last line of ccx's log that says what went wrong ("*ERROR ..."), else its exit status;
/// a failed allocation names the memory limit it ran into.
std::string ccxFailure(const std::string& logPath, int status, double memoryLimitGiB) {
  std::ifstream in(logPath);
  std::string line, error;
  while (std::getline(in, line))
    if (line.find("ERROR") != std::string::npos) error = line.substr(line.find_first_not_of(' '));
  if (error.empty()) return "ccx stopped (exit " + std::to_string(status) + ")";
  if (memoryLimitGiB > 0 && error.find("allocat") != std::string::npos) {
    std::ostringstream limit;
    limit << error << " (" << kMemoryLimitNote << memoryLimitGiB
          << " GiB: --ccx-memory sets it, 0 for none)";
    return limit.str();
  }
  return error;
}

void readMuscleResult(const MuscleJob& muscle, const CalculixDefinition& definition,
                      const std::string& base, int status,
                      std::vector<std::vector<btVector3>>& stepSurfaces, std::string& failure,
                      StaSummary& sta);

/// Runs one muscle's job; per step the surface positions (empty where ccx gave none) and the
/// reason of a failure.
void solveMuscle(const MuscleJob& muscle, const CalculixDefinition& definition,
                 const std::string& workDir, const std::function<bool(int)>& poll,
                 std::vector<std::vector<btVector3>>& stepSurfaces, std::string& failure,
                 StaSummary& sta) {
  const std::string base = workDir + "/" + muscle.stem;
  {
    std::ofstream out(base + ".inp");
    writeCalculixInput(out, muscle.job);
    if (!out) throw InputError(base + ".inp", "", "cannot write the CalculiX input");
  }
  std::filesystem::remove(base + ".sta");
  std::filesystem::remove(base + ".dat");
  const int status = runProgram(
      {definition.program, "-i", muscle.stem}, workDir, base + ".log",
      [&] { return poll(readSta(base + ".sta").stepsDone); },
      static_cast<uint64_t>(definition.memoryLimitGiB * (1ull << 30)));
  readMuscleResult(muscle, definition, base, status, stepSurfaces, failure, sta);
}

/// What ccx left of the muscle's job at `base` (its .sta, .dat and .log) and exited with
/// (`status`): per step the surface positions (empty where ccx gave none), the reason of a
/// failure and the .sta's counts.
void readMuscleResult(const MuscleJob& muscle, const CalculixDefinition& definition,
                      const std::string& base, int status,
                      std::vector<std::vector<btVector3>>& stepSurfaces, std::string& failure,
                      StaSummary& sta) {
  sta = readSta(base + ".sta");
  std::ifstream dat(base + ".dat");
  const std::vector<CalculixTable> tables = readCalculixDat(dat, base + ".dat");
  const int steps = static_cast<int>(muscle.job.steps.size());
  const auto ends = stepEndTables(tables, "displacements", "NPRINT", steps);
  stepSurfaces.assign(static_cast<size_t>(steps), {});
  for (size_t s = 0; s < ends.size(); ++s) {
    const CalculixTable& table = *ends[s];
    std::vector<btVector3>& surface = stepSurfaces[s];
    surface.assign(muscle.job.nodes.begin(),
                   muscle.job.nodes.begin() + static_cast<long>(muscle.surfaceVertices));
    for (size_t row = 0; row < table.ids.size(); ++row) {
      const size_t v = static_cast<size_t>(table.ids[row] - 1);
      const double* u = &table.values[row * 3];
      if (v < surface.size())
        surface[v] += btVector3(btScalar(u[0]), btScalar(u[1]), btScalar(u[2]));
    }
    for (size_t i = 0; i < muscle.moved.size(); ++i)
      surface[muscle.moved[i]] = muscle.movedPositions[s][i];
  }
  failure = static_cast<int>(ends.size()) == steps
                ? ""
                : ccxFailure(base + ".log", status, definition.memoryLimitGiB);
}

/// Muscle `m`'s job under `definition` (one increment scale) as ccx is given it, its mesh made by
/// tetgen in `workDir` (created); its counts into `part`.
MuscleJob jobOf(const LoadedScene& scene, const PreparedScene& prepared,
                const CalculixDefinition& definition, const ContinuumCut& cut, size_t m,
                const std::string& workDir, MuscleSolution& part) {
  std::filesystem::create_directories(workDir);
  std::vector<MeshDistance> bones;
  for (const auto& bone : prepared.bones) bones.emplace_back(bone->mesh);
  const std::vector<int> steps =
      stepPoses(scene, prepared.bones.size(), ccxPoseCount(scene, cut, definition.poseLimit),
                definition.returnToRest);
  MuscleJob muscle = muscleJob(scene, prepared, m, bones, definition, workDir, steps);
  part.nodes = muscle.job.nodes.size();
  part.tetrahedra = muscle.tetrahedra;
  part.prescribedNodes = muscle.attachedNodes;
  return muscle;
}

/// Where ccx failed a muscle's job (not interrupted), every part into solution.muscles, the
/// failed ones without their surfaces (CalculixSolution::muscles).
void keepParts(const std::vector<MuscleSolution>& muscles, CalculixSolution& solution) {
  const auto failed = [](const MuscleSolution& m) { return !m.solvedEveryStep(); };
  if (solution.interrupted || std::none_of(muscles.begin(), muscles.end(), failed)) return;
  solution.muscles = muscles;
  for (MuscleSolution& part : solution.muscles) {
    part.inputFile = std::filesystem::path(part.inputFile).filename().string();
    if (failed(part)) part.stepSurfaces.clear();
  }
}

}  // namespace

int ccxPoseCount(const LoadedScene& scene, const ContinuumCut& cut, int poseLimit) {
  const int uncut = cut.pose >= 0 ? cut.pose : std::max(scene.poseCount, 1);
  return poseLimit > 0 ? std::min(uncut, poseLimit) : uncut;
}

const char* toString(IncrementRule rule) {
  return rule == IncrementRule::BoneFrame ? "bone frame" : "world";
}

int CalculixSolution::solvedPoses() const {
  int solved = 0;
  while (solved < static_cast<int>(poseSurfaces.size()) &&
         !poseSurfaces[static_cast<size_t>(solved)].empty())
    ++solved;
  return solved;
}

bool MuscleSolution::hitMemoryLimit() const {
  return failure.find(kMemoryLimitNote) != std::string::npos;
}

bool CalculixSolution::hitMemoryLimit() const {
  const auto named = [](const std::string& failure) {
    return failure.find(kMemoryLimitNote) != std::string::npos;
  };
  return named(returnFailure) || std::any_of(poseFailures.begin(), poseFailures.end(), named);
}

CalculixDefinition muscleDefinition(const CalculixDefinition& definition, size_t m) {
  CalculixDefinition own = definition;
  own.incrementScale = definition.incrementScaleOf(m);
  own.muscleIncrementScales.clear();
  return own;
}

MuscleSolution solveCalculixMuscle(const LoadedScene& scene, const PreparedScene& prepared,
                                   const CalculixDefinition& mixed, const ContinuumCut& cut,
                                   size_t m, const std::string& workDir,
                                   const std::function<void(const ReferenceProgress&)>& progress,
                                   const std::atomic<bool>* cancel) {
  const auto start = Clock::now();
  const CalculixDefinition definition = muscleDefinition(mixed, m);
  MuscleSolution result;
  const MuscleJob muscle = jobOf(scene, prepared, definition, cut, m, workDir, result);
  result.inputFile = workDir + "/" + muscle.stem + ".inp";
  const int stepCount = static_cast<int>(muscle.job.steps.size());
  int reported = -1;
  const auto poll = [&](int done) {
    if (progress && done != reported) {
      reported = done;
      progress({prepared.muscles[m]->name, static_cast<int>(m),
                static_cast<int>(prepared.muscles.size()), done, stepCount, secondsSince(start)});
    }
    if (cancel && cancel->load()) result.interrupted = true;
    return !result.interrupted;
  };
  poll(0);
  StaSummary sta;
  solveMuscle(muscle, definition, workDir, poll, result.stepSurfaces, result.failure, sta);
  poll(sta.stepsDone);
  result.increments = sta.increments;
  result.newtonIterations = sta.iterations;
  if (result.interrupted) result.failure = "interrupted";
  result.seconds = secondsSince(start);
  return result;
}

bool readSolvedMuscle(const LoadedScene& scene, const PreparedScene& prepared,
                      const CalculixDefinition& mixed, const ContinuumCut& cut, size_t m,
                      const std::string& solvedDir, const std::string& workDir,
                      MuscleSolution& part) {
  const CalculixDefinition definition = muscleDefinition(mixed, m);
  MuscleSolution read;
  const MuscleJob muscle = jobOf(scene, prepared, definition, cut, m, workDir, read);
  std::ostringstream input;
  writeCalculixInput(input, muscle.job);
  const std::string base = solvedDir + "/" + muscle.stem;
  std::ifstream solved(base + ".inp");
  const std::string solvedInput((std::istreambuf_iterator<char>(solved)),
                                std::istreambuf_iterator<char>());
  if (!solved || input.str() != solvedInput) return false;  // not the job ccx solved
  part = read;
  part.inputFile = muscle.stem + ".inp";
  StaSummary sta;
  readMuscleResult(muscle, definition, base, -1, part.stepSurfaces, part.failure, sta);
  part.increments = sta.increments;
  part.newtonIterations = sta.iterations;
  std::ifstream log(base + ".log");
  for (std::string line; std::getline(log, line);)
    if (const size_t at = line.find("Total CalculiX Time:"); at != std::string::npos)
      part.seconds = std::atof(line.c_str() + at + 20);
  return true;
}

CalculixSolution assembleCalculixSolution(const LoadedScene& scene, const PreparedScene& prepared,
                                          const CalculixDefinition& definition,
                                          const ContinuumCut& cut,
                                          const std::vector<MuscleSolution>& muscles) {
  CalculixSolution solution;
  solution.cut = cut;
  const int poses = ccxPoseCount(scene, cut, definition.poseLimit);
  const int stepCount = static_cast<int>(
      stepPoses(scene, prepared.bones.size(), poses, definition.returnToRest).size());
  solution.poseSurfaces.assign(static_cast<size_t>(std::max(scene.poseCount, 1)), {});
  solution.poseFailures.assign(solution.poseSurfaces.size(), "");
  solution.interrupted = muscles.size() < prepared.muscles.size();
  const std::vector<btVector3> none;  // a step a stored part lacks
  for (size_t m = 0; m < muscles.size(); ++m) {
    const MuscleSolution& muscle = muscles[m];
    solution.nodes += muscle.nodes;
    solution.elements += muscle.tetrahedra;
    solution.prescribedNodes += muscle.prescribedNodes;
    if (!muscle.inputFile.empty()) solution.inputFiles.push_back(muscle.inputFile);  // shipped
    solution.increments += muscle.increments;
    solution.newtonIterations += muscle.newtonIterations;
    solution.seconds += muscle.seconds;
    solution.interrupted = solution.interrupted || muscle.interrupted;
    const std::string blame = "muscle " + prepared.muscles[m]->name + ": " + muscle.failure;
    for (int s = 0; s < stepCount; ++s) {
      const bool pose = s < poses;
      if (!pose && s + 1 < stepCount) continue;  // on the way back to rest: only its end counts
      const std::vector<btVector3>& surface = static_cast<size_t>(s) < muscle.stepSurfaces.size()
                                                  ? muscle.stepSurfaces[static_cast<size_t>(s)]
                                                  : none;
      std::vector<btVector3>& into =
          pose ? solution.poseSurfaces[static_cast<size_t>(s)] : solution.returnSurface;
      std::string& why =
          pose ? solution.poseFailures[static_cast<size_t>(s)] : solution.returnFailure;
      const bool earlierFailed = !why.empty();
      if (surface.empty() && !earlierFailed) why = blame;
      if (m == 0 || !into.empty()) into.insert(into.end(), surface.begin(), surface.end());
      if (!why.empty()) into.clear();
    }
  }
  for (size_t p = 0; solution.interrupted && p <= solution.poseSurfaces.size(); ++p) {
    const bool pose = p < solution.poseSurfaces.size();
    std::string& why = pose ? solution.poseFailures[p] : solution.returnFailure;
    const bool excluded = pose && static_cast<int>(p) >= poses;  // past the cut or limit
    const bool returns = pose || definition.returnToRest;        // a gate's solve has no return
    if (why.empty() && !excluded && returns) why = "interrupted";
    (pose ? solution.poseSurfaces[p] : solution.returnSurface).clear();
  }
  keepParts(muscles, solution);
  return solution;
}

CalculixSolution solveCalculixReference(
    const LoadedScene& scene, const PreparedScene& prepared, const CalculixDefinition& definition,
    const ContinuumCut& cut, const std::string& workDir,
    const std::function<void(const ReferenceProgress&)>& progress,
    const std::atomic<bool>* cancel) {
  std::vector<MuscleSolution> muscles;
  for (size_t m = 0; m < prepared.muscles.size(); ++m) {
    muscles.push_back(
        solveCalculixMuscle(scene, prepared, definition, cut, m, workDir, progress, cancel));
    if (muscles.back().interrupted) break;
  }
  return assembleCalculixSolution(scene, prepared, definition, cut, muscles);
}

}  // namespace fibremss
