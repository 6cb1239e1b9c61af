// The reference cache: key, binary store of a solution, and the cached solve.
#include "fibremss/ReferenceCache.h"

#include <dlfcn.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <memory>
#include <mutex>
#include <sstream>
#include <thread>
#include <tuple>
#include <type_traits>

#include "CacheRead.h"
#include "SurfaceDeltas.h"
#include "fibremss/Error.h"

namespace fibremss {
namespace {

// Version 2 of a solution (cache or shipped) is version 1 followed by its muscles' parts
// (CalculixSolution::muscles); a solution without them is still written as version 1. Version 3
// of a shipped one (a gate's) names the solve shipped beside it that its surfaces are stored
// against (SurfaceDeltas), then holds version 1 or 2 of it.
constexpr char kMagic[8] = {'F', 'M', 'S', 'S', 'R', 'E', 'F', '1'};
constexpr char kMagic2[8] = {'F', 'M', 'S', 'S', 'R', 'E', 'F', '2'};
constexpr char kPartMagic[8] = {'F', 'M', 'S', 'S', 'P', 'R', 'T', '1'};
constexpr char kShippedMagic[8] = {'F', 'M', 'S', 'S', 'S', 'H', 'P', '1'};
constexpr char kShippedMagic2[8] = {'F', 'M', 'S', 'S', 'S', 'H', 'P', '2'};
constexpr char kShippedMagic3[8] = {'F', 'M', 'S', 'S', 'S', 'H', 'P', '3'};

/// FNV-1a over everything fed to it.
class Hasher {
 public:
  void bytes(const void* data, size_t size) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < size; ++i) hash_ = (hash_ ^ p[i]) * 0x100000001b3ull;
  }
  template <typename T>
  void value(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    bytes(&v, sizeof v);
  }
  void text(const std::string& s) {
    value(s.size());
    bytes(s.data(), s.size());
  }
  void points(const std::vector<btVector3>& points) {
    value(points.size());
    for (const btVector3& p : points) {
      value(p.x());
      value(p.y());
      value(p.z());
    }
  }
  void ids(const std::vector<uint32_t>& ids) {
    value(ids.size());
    if (!ids.empty()) bytes(ids.data(), ids.size() * sizeof(ids[0]));
  }
  void mesh(const TriangleMesh& mesh) {
    points(mesh.vertices);
    value(mesh.triangles.size());
    if (!mesh.triangles.empty())
      bytes(mesh.triangles.data(), mesh.triangles.size() * sizeof(mesh.triangles[0]));
  }
  std::string hex() const {
    char out[17];
    std::snprintf(out, sizeof out, "%016llx", static_cast<unsigned long long>(hash_));
    return out;
  }

 private:
  uint64_t hash_ = 0xcbf29ce484222325ull;
};

/// How a store holds positions: doubles in the cache, floats in a shipped reference (about
/// 10⁻⁵ mm on a muscle of 0.5 m, far below the gates' 0.1 mm), differences from earlier
/// surfaces in a shipped gate (`deltas`: SurfaceDeltas).
enum class Precision { Double, Float };
struct Positions {
  Precision precision = Precision::Double;
  SurfaceDeltas* deltas = nullptr;  ///< where not null, it stores them
};

void writePoints(std::ostream& out, const std::vector<btVector3>& points,
                 const Positions& positions = {}) {
  if (positions.deltas) return positions.deltas->write(out, points);
  const Precision precision = positions.precision;
  const uint64_t count = points.size();
  out.write(reinterpret_cast<const char*>(&count), sizeof count);
  for (const btVector3& p : points) {
    if (precision == Precision::Float) {
      const float xyz[3] = {float(p.x()), float(p.y()), float(p.z())};
      out.write(reinterpret_cast<const char*>(xyz), sizeof xyz);
    } else {
      const double xyz[3] = {p.x(), p.y(), p.z()};
      out.write(reinterpret_cast<const char*>(xyz), sizeof xyz);
    }
  }
}

void writeText(std::ostream& out, const std::string& text) {
  const uint64_t size = text.size();
  out.write(reinterpret_cast<const char*>(&size), sizeof size);
  out.write(text.data(), static_cast<std::streamsize>(size));
}

/// Reads from the stream or throws InputError naming the file.
class Reader {
 public:
  Reader(std::istream& in, const std::string& path, const Positions& positions = {})
      : in_(in), path_(path), positions_(positions) {}
  template <typename T>
  T value() {
    return readValue<T>(in_, path_);
  }
  std::string text() {
    const uint64_t size = value<uint64_t>();
    if (size > (1u << 20)) throw InputError(path_, "", "not a reference cache file");
    std::string s(size, '\0');
    in_.read(s.data(), static_cast<std::streamsize>(size));
    checkRead(in_, path_);
    return s;
  }
  std::vector<btVector3> points() {
    if (positions_.deltas) return positions_.deltas->read(in_, path_);
    const uint64_t count = value<uint64_t>();
    if (count > (1ull << 32)) throw InputError(path_, "", "not a reference cache file");
    std::vector<btVector3> points(count);
    for (btVector3& p : points) {
      if (positions_.precision == Precision::Float) {
        const auto xyz = value<std::array<float, 3>>();
        p.setValue(btScalar(xyz[0]), btScalar(xyz[1]), btScalar(xyz[2]));
      } else {
        const auto xyz = value<std::array<double, 3>>();
        p.setValue(btScalar(xyz[0]), btScalar(xyz[1]), btScalar(xyz[2]));
      }
    }
    return points;
  }
  /// Whether the stream has nothing left.
  bool atEnd() { return in_.peek() == std::char_traits<char>::eof(); }

 private:
  std::istream& in_;
  const std::string& path_;
  Positions positions_;
};

/// Writes what `write(out)` puts in a stream to `path` atomically (a temporary file renamed).
template <typename Write>
void writeAtomically(const std::string& path, Write&& write) {
  const std::string temporary = path + ".partial";
  {
    std::ofstream out(temporary, std::ios::binary);
    write(out);
    if (!out) throw std::runtime_error("cannot write " + temporary);
  }
  std::filesystem::rename(temporary, path);
}

/// The counts and time a solve and a muscle's part both end with: nodes, elements, prescribed
/// nodes, Newton iterations, increments, seconds.
using SolveCounts = std::tuple<size_t, size_t, size_t, long, long, double>;

void writeCounts(std::ostream& out, const SolveCounts& c) {
  const uint64_t counts[5] = {std::get<0>(c), std::get<1>(c), std::get<2>(c),
                              static_cast<uint64_t>(std::get<3>(c)),
                              static_cast<uint64_t>(std::get<4>(c))};
  out.write(reinterpret_cast<const char*>(counts), sizeof counts);
  const double seconds = std::get<5>(c);
  out.write(reinterpret_cast<const char*>(&seconds), sizeof seconds);
}

SolveCounts readCounts(Reader& read) {
  const auto counts = read.value<std::array<uint64_t, 5>>();
  return {counts[0],
          counts[1],
          counts[2],
          static_cast<long>(counts[3]),
          static_cast<long>(counts[4]),
          read.value<double>()};
}

/// Reads a magic from `in`: its place in `magics` counted from 1, else throws InputError naming
/// what `path` is not.
int expectMagic(std::istream& in, const std::string& path,
                std::initializer_list<const char*> magics, const char* what) {
  char magic[8];
  in.read(magic, sizeof magic);
  int version = 1;
  for (const char* expected : magics) {
    if (in && std::memcmp(magic, expected, sizeof magic) == 0) return version;
    ++version;
  }
  throw InputError(path, "", std::string("not a ") + what);
}

/// Writes a muscle's part (after a magic; its input file by name alone) in `precision`.
void writePart(std::ostream& out, const MuscleSolution& part, const Positions& positions = {}) {
  const uint64_t steps = part.stepSurfaces.size();
  out.write(reinterpret_cast<const char*>(&steps), sizeof steps);
  for (const std::vector<btVector3>& surface : part.stepSurfaces)
    writePoints(out, surface, positions);
  writeText(out, part.failure);
  writeCounts(out, std::tie(part.nodes, part.tetrahedra, part.prescribedNodes,
                            part.newtonIterations, part.increments, part.seconds));
  writeText(out, std::filesystem::path(part.inputFile).filename().string());
}

/// Reads what writePart wrote.
MuscleSolution readPart(Reader& read, const std::string& path) {
  MuscleSolution part;
  const auto steps = read.value<uint64_t>();
  if (steps > 1000000) throw InputError(path, "", "not a FibreMSS reference part");
  for (uint64_t s = 0; s < steps; ++s) part.stepSurfaces.push_back(read.points());
  part.failure = read.text();
  std::tie(part.nodes, part.tetrahedra, part.prescribedNodes, part.newtonIterations,
           part.increments, part.seconds) = readCounts(read);
  part.inputFile = read.text();
  return part;
}

/// Writes a muscle's part to `path` atomically.
void savePart(const std::string& path, const MuscleSolution& part) {
  writeAtomically(path, [&](std::ostream& out) {
    out.write(kPartMagic, sizeof kPartMagic);
    writePart(out, part);
  });
}

/// Reads what savePart wrote; false when `path` does not exist.
bool loadPart(const std::string& path, MuscleSolution& part) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  Reader read(in, path);
  expectMagic(in, path, {kPartMagic}, "FibreMSS reference part file");
  part = readPart(read, path);
  return true;
}

/// Writes a solution (after its magic) with its positions as `positions` says.
void writeSolution(std::ostream& out, const CalculixSolution& solution,
                   const Positions& positions) {
  const uint64_t poses = solution.poseSurfaces.size();
  out.write(reinterpret_cast<const char*>(&poses), sizeof poses);
  for (size_t p = 0; p < poses; ++p) {
    writeText(out, solution.poseFailures[p]);
    writePoints(out, solution.poseSurfaces[p], positions);
  }
  writeText(out, solution.returnFailure);
  writePoints(out, solution.returnSurface, positions);
  writeCounts(out, std::tie(solution.nodes, solution.elements, solution.prescribedNodes,
                            solution.newtonIterations, solution.increments, solution.seconds));
  writeText(out, std::to_string(solution.inputFiles.size()));
  for (const std::string& file : solution.inputFiles) writeText(out, file);
  // The continuum cut after what older entries hold (they are read as having none).
  const int64_t cut = solution.cut.pose;
  out.write(reinterpret_cast<const char*>(&cut), sizeof cut);
  out.write(reinterpret_cast<const char*>(&solution.cut.gapMm), sizeof solution.cut.gapMm);
  writeText(out, solution.cut.reason);
  if (solution.muscles.empty()) return;  // version 1
  const uint64_t muscles = solution.muscles.size();
  out.write(reinterpret_cast<const char*>(&muscles), sizeof muscles);
  for (const MuscleSolution& part : solution.muscles) writePart(out, part, positions);
}

/// Reads what writeSolution wrote, of `version` (its magic's).
void readSolution(Reader& read, const std::string& path, int version, CalculixSolution& solution) {
  solution = {};
  const auto poses = read.value<uint64_t>();
  if (poses > 1000000) throw InputError(path, "", "not a FibreMSS reference cache file");
  for (uint64_t p = 0; p < poses; ++p) {
    solution.poseFailures.push_back(read.text());
    solution.poseSurfaces.push_back(read.points());
  }
  solution.returnFailure = read.text();
  solution.returnSurface = read.points();
  std::tie(solution.nodes, solution.elements, solution.prescribedNodes, solution.newtonIterations,
           solution.increments, solution.seconds) = readCounts(read);
  const size_t files = std::stoul(read.text());
  for (size_t f = 0; f < files; ++f) solution.inputFiles.push_back(read.text());
  if (read.atEnd()) return;  // stored before the cut was
  solution.cut.pose = static_cast<int>(read.value<int64_t>());
  solution.cut.gapMm = read.value<double>();
  solution.cut.reason = read.text();
  if (version < 2) return;
  const auto muscles = read.value<uint64_t>();
  if (muscles > 1000000) throw InputError(path, "", "not a FibreMSS reference cache file");
  for (uint64_t m = 0; m < muscles; ++m) solution.muscles.push_back(readPart(read, path));
}

std::string entryDir(const std::string& cacheDir, const std::string& key) {
  return cacheDir + "/" + key;
}

/// Moves the solve's work directory into place as `dir` holding `stored`; when another
/// process stored it first (the rename fails on a directory that is not empty), its is kept.
void storeWork(const std::string& work, const std::string& dir, const std::string& stored) {
  std::error_code error;
  std::filesystem::rename(work, dir, error);
  if (error && !std::filesystem::exists(stored)) {
    std::filesystem::remove_all(dir);  // a solve stopped before it stored anything
    std::filesystem::rename(work, dir);
  }
  std::filesystem::remove_all(work, error);
}

/// A work directory of this process's own beside `dir`, emptied: solved there and moved into
/// place whole, so that two processes solving one key at once do not share ccx's files.
std::string freshWorkDir(const std::string& dir) {
  const std::string work = dir + ".solving-" + std::to_string(getpid());
  std::filesystem::remove_all(work);
  return work;
}

/// solve(), with `work` removed when it throws (tetgen or ccx not found, a surface tetgen
/// refuses).
template <typename Solve>
auto solveIn(const std::string& work, Solve&& solve) {
  try {
    return solve();
  } catch (...) {
    std::error_code ignored;
    std::filesystem::remove_all(work, ignored);
    throw;
  }
}

/// Copies every file of the parts (but their part.bin) into `work`, as a whole solve leaves them;
/// a part without an input file (shipped) has none.
void copyPartFiles(const std::string& cacheDir, const std::string& key,
                   const std::vector<MuscleSolution>& parts, const std::string& work) {
  namespace fs = std::filesystem;
  fs::create_directories(work);
  for (size_t m = 0; m < parts.size(); ++m)
    if (!parts[m].inputFile.empty())
      for (const fs::directory_entry& file :
           fs::directory_iterator(referencePartDir(cacheDir, key, m)))
        if (file.path().filename() != "part.bin")
          fs::copy_file(file.path(), work / file.path().filename(),
                        fs::copy_options::overwrite_existing);
}

}  // namespace

std::string referenceCacheKey(const LoadedScene& scene, const PreparedScene& prepared,
                              const CalculixDefinition& definition, const ContinuumCut& cut) {
  Hasher h;
  h.text("fibremss calculix reference 2");
  h.text(calculixVersion(definition.program));
  const int poses = std::max(scene.poseCount, 1);
  h.value(poses);
  for (size_t b = 0; b < prepared.bones.size(); ++b) {
    h.mesh(prepared.bones[b]->mesh);
    for (int p = 0; p < poses; ++p) {
      const btTransform t = scene.bonePose(b, p);
      h.points({t.getOrigin(), t.getBasis()[0], t.getBasis()[1], t.getBasis()[2]});
    }
  }
  for (size_t m = 0; m < prepared.muscles.size(); ++m) {
    h.mesh(scene.muscles[m].surface);
    h.mesh(prepared.muscles[m]->restSurface);
    h.value(scene.muscles[m].parameters.attachmentDistance);
  }
  // A muscle's declared areas: meshed as prepared and attached by them (scenes without declared
  // areas keep their keys).
  for (size_t m = 0; m < scene.muscles.size(); ++m)
    for (const DeclaredAttachment& area : scene.muscles[m].attachments) {
      h.text("declared area");
      h.value(m);
      h.ids(area.surfaceVertices);
      h.ids(area.bones);
    }
  h.value(definition.material.youngsModulus);
  h.value(definition.material.poissonRatio);
  h.value(definition.element);
  h.value(definition.mesher.radiusEdgeRatio);
  h.value(definition.mesher.refinement);
  h.value(definition.attachmentScale);
  h.value(definition.returnToRest);
  h.value(definition.initialIncrement);
  h.value(definition.contactPenalty);
  // Poses past a continuum cut are not solved: the same scene's entries from before the cut
  // was found hold ccx's failures there instead. Scenes without a cut keep their keys.
  if (cut.pose >= 0) {
    h.text("continuum cut");
    h.value(cut.pose);
  }
  // A pose limit that drops poses: a gate of a partly solved reference (no other key changes).
  if (const int given = ccxPoseCount(scene, cut, definition.poseLimit);
      given < ccxPoseCount(scene, cut)) {
    h.text("pose limit");
    h.value(given);
  }
  if (definition.incrementScale != 1) {  // finer increments (no other key changes)
    h.text("increment scale");
    h.value(definition.incrementScale);
  }
  if (!definition.muscleIncrementScales.empty()) {  // per muscle (no other key changes)
    h.text("muscle increment scales");
    h.value(definition.muscleIncrementScales.size());
    for (const double scale : definition.muscleIncrementScales) h.value(scale);
  }
  // Increments bounded in the bone's frame (the world rule's entries keep their keys).
  if (definition.incrementRule != IncrementRule::World) {
    h.text("increment rule");
    h.value(definition.incrementRule);
  }
  // Small sliding (where a scene chooses it; no other key changes).
  if (definition.contactPenalty > 0 && definition.contactSliding != ContactSliding::Finite) {
    h.text("contact sliding");
    h.value(definition.contactSliding);
  }
  // C3D10 under contact: the midside nodes became contact slaves (no other key changes).
  if (definition.element == CalculixElement::C3D10 && definition.contactPenalty > 0)
    h.text("C3D10 midside slaves");
  if (scene.analytic.type == "sphere-planes") {  // held by its symmetry (no other key changes)
    h.text(scene.analytic.type);
    h.points({scene.analytic.axisStart, scene.analytic.axisEnd});
  }
  return h.hex();
}

std::string defaultReferenceCacheDir() {
  if (const char* dir = std::getenv("FIBREMSS_CACHE"); dir && *dir)
    return std::string(dir) + "/reference";
  if (const char* dir = std::getenv("XDG_CACHE_HOME"); dir && *dir)
    return std::string(dir) + "/fibremss/reference";
  if (const char* home = std::getenv("HOME"); home && *home)
    return std::string(home) + "/.cache/fibremss/reference";
  return ".fibremss-cache/reference";
}

void saveSolution(const std::string& path, const CalculixSolution& solution) {
  writeAtomically(path, [&](std::ostream& out) {
    out.write(solution.muscles.empty() ? kMagic : kMagic2, sizeof kMagic);
    writeSolution(out, solution, {Precision::Double});
  });
}

bool loadSolution(const std::string& path, CalculixSolution& solution) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  Reader read(in, path);
  const int version = expectMagic(in, path, {kMagic, kMagic2}, "FibreMSS reference cache file");
  readSolution(read, path, version, solution);
  return true;
}

namespace {

/// Writes `data` gzip-compressed to `path` atomically.
void writeGzip(const std::string& path, const std::string& data) {
  const std::string temporary = path + ".partial";
  gzFile out = gzopen(temporary.c_str(), "wb9");
  const bool written = out && gzwrite(out, data.data(), static_cast<unsigned>(data.size())) ==
                                  static_cast<int>(data.size());
  if (!(out && gzclose(out) == Z_OK && written))
    throw std::runtime_error("cannot write " + temporary);
  std::filesystem::rename(temporary, path);
}

/// Writes a shipped file to `path`: `magic`, then what `write(out, positions)` writes, its
/// positions as floats; with a `base`, after kShippedMagic3 and the base's key, and its
/// positions as differences from the base's surfaces (SurfaceDeltas).
template <typename Write>
void shipFile(const std::string& path, const char* magic, const ShippedBase* base, Write&& write) {
  std::ostringstream bytes;
  if (!base) {
    bytes.write(magic, sizeof kShippedMagic);
    write(bytes, Positions{Precision::Float});
    return writeGzip(path, bytes.str());
  }
  bytes.write(kShippedMagic3, sizeof kShippedMagic3);
  writeText(bytes, base->key);
  bytes.write(magic, sizeof kShippedMagic);
  const std::vector<uint64_t>& vertices = base->muscleVertices;
  const uint64_t muscles = vertices.size();
  bytes.write(reinterpret_cast<const char*>(&muscles), sizeof muscles);
  bytes.write(reinterpret_cast<const char*>(vertices.data()),
              std::streamsize(muscles * sizeof(uint64_t)));
  SurfaceDeltas deltas(base->solution, vertices);
  write(bytes, Positions{Precision::Float, &deltas});
  writeGzip(path, bytes.str());
}

}  // namespace

void shipSolution(const std::string& path, const CalculixSolution& solution,
                  const ShippedBase* base) {
  CalculixSolution shipped = solution;
  shipped.inputFiles.clear();  // they name another machine's cache
  shipFile(path, solution.muscles.empty() ? kShippedMagic : kShippedMagic2, base,
           [&](std::ostream& out, const Positions& positions) {
             writeSolution(out, shipped, positions);
           });
}

void shipPart(const std::string& path, const MuscleSolution& part, const ShippedBase* base) {
  MuscleSolution shipped = part;
  shipped.inputFile.clear();  // its files stay on the machine that solved it
  shipFile(path, kPartMagic, base, [&](std::ostream& out, const Positions& positions) {
    writePart(out, shipped, positions);
  });
}

namespace {

/// The bytes of the gzip file `path`; false when it does not exist. Throws InputError when it is
/// not gzip or truncated.
bool gunzip(const std::string& path, std::string& data) {
  if (!std::filesystem::exists(path)) return false;
  gzFile in = gzopen(path.c_str(), "rb");
  if (!in) throw InputError(path, "", "cannot be opened");
  char buffer[1 << 16];
  int got;
  while ((got = gzread(in, buffer, sizeof buffer)) > 0) data.append(buffer, size_t(got));
  int error = Z_OK;
  if (got < 0) gzerror(in, &error);
  gzclose(in);
  if (got < 0)
    throw InputError(path, "",
                     "not a gzip file or truncated (zlib error " + std::to_string(error) + ")");
  return true;
}

bool isKey(const std::string& key) {
  return key.size() == 16 && std::all_of(key.begin(), key.end(), [](char c) {
           return std::isxdigit(static_cast<unsigned char>(c));
         });
}

bool readShipped(const std::string& path, CalculixSolution& solution, bool againstBase);

/// The differences a shipped file of version 3 holds its surfaces as, after its magic: its base
/// read from beside `path`; `version`: the place in `magics` of the magic after the base's key.
std::unique_ptr<SurfaceDeltas> readShippedBase(std::istream& bytes, const std::string& path,
                                               std::initializer_list<const char*> magics,
                                               const char* what, int& version) {
  Reader header(bytes, path);
  const std::string key = header.text();
  if (!isKey(key)) throw InputError(path, "", std::string("not a ") + what);
  CalculixSolution base;
  if (!readShipped((std::filesystem::path(path).parent_path() / (key + ".ref.gz")).string(), base,
                   false))
    throw InputError(path, "",
                     "the solve it is stored against, " + key + ".ref.gz, is not beside it");
  version = expectMagic(bytes, path, magics, what);
  std::vector<uint64_t> vertices(header.value<uint64_t>());
  if (vertices.size() > 1000000) throw InputError(path, "", std::string("not a ") + what);
  for (uint64_t& count : vertices) count = header.value<uint64_t>();
  return std::make_unique<SurfaceDeltas>(base, std::move(vertices));
}

/// Reads a file shipFile wrote: `read(reader, version)` after its magic, one of `magics`
/// (`version`: its place counted from 1), against its base only where `againstBase`; false
/// when `path` does not exist. Throws InputError naming what `path` is not.
template <typename Read>
bool readShippedFile(const std::string& path, std::initializer_list<const char*> magics,
                     const char* what, bool againstBase, Read&& read) {
  std::string data;
  if (!gunzip(path, data)) return false;
  std::istringstream bytes(data);
  if (data.compare(0, sizeof kShippedMagic3, kShippedMagic3, sizeof kShippedMagic3) != 0) {
    const int version = expectMagic(bytes, path, magics, what);
    Reader reader(bytes, path, {Precision::Float});
    read(reader, version);
    return true;
  }
  if (!againstBase)
    throw InputError(path, "", "a shipped gate, not the solve a gate is stored against");
  bytes.seekg(sizeof kShippedMagic3);
  int version = 0;
  const std::unique_ptr<SurfaceDeltas> deltas = readShippedBase(bytes, path, magics, what, version);
  Reader reader(bytes, path, {Precision::Float, deltas.get()});
  read(reader, version);
  return true;
}

/// loadShippedSolution; a gate (version 3) only where `againstBase` (a base is none).
bool readShipped(const std::string& path, CalculixSolution& solution, bool againstBase) {
  return readShippedFile(
      path, {kShippedMagic, kShippedMagic2}, "FibreMSS shipped reference", againstBase,
      [&](Reader& read, int version) { readSolution(read, path, version, solution); });
}

/// The first of shippedReferenceDirs' `<dir>/<name>` that exists; "" when none does.
std::string shippedFilePath(const std::string& name) {
  for (const std::string& dir : shippedReferenceDirs())
    if (const std::string path = dir + "/" + name; std::filesystem::exists(path)) return path;
  return "";
}

}  // namespace

bool loadShippedSolution(const std::string& path, CalculixSolution& solution) {
  return readShipped(path, solution, true);
}

bool loadShippedPart(const std::string& path, MuscleSolution& part) {
  return readShippedFile(path, {kPartMagic}, "FibreMSS shipped reference part", true,
                         [&](Reader& read, int) { part = readPart(read, path); });
}

std::vector<std::string> shippedReferenceDirs() {
  std::vector<std::string> dirs;
  if (const char* dir = std::getenv("FIBREMSS_REFERENCES"); dir && *dir) dirs.push_back(dir);
  dirs.push_back(FIBREMSS_SOURCE_REFERENCES);
  Dl_info library;
  if (dladdr(reinterpret_cast<const void*>(&shippedReferenceDirs), &library) && library.dli_fname)
    dirs.push_back(
        (std::filesystem::path(library.dli_fname).parent_path() / FIBREMSS_LIBRARY_TO_REFERENCES)
            .lexically_normal()
            .string());
  return dirs;
}

std::string shippedReferencePath(const std::string& key) {
  return shippedFilePath(key + ".ref.gz");
}

std::string shippedPartName(const std::string& key, size_t m) {
  return key + ".m" + std::to_string(m) + ".ref.gz";
}

bool loadStoredSolution(const std::string& cacheDir, const std::string& key,
                        CalculixSolution& solution, std::string* shippedFrom) {
  if (shippedFrom) shippedFrom->clear();
  if (loadSolution(entryDir(cacheDir, key) + "/surfaces.bin", solution)) return true;
  const std::string shipped = shippedReferencePath(key);
  if (shipped.empty() || !loadShippedSolution(shipped, solution)) return false;
  if (shippedFrom) *shippedFrom = shipped;
  return true;
}

namespace {
/// Whether the solve `key` is stored whole: in the cache or shipped.
bool storedWhole(const std::string& cacheDir, const std::string& key) {
  return std::filesystem::exists(entryDir(cacheDir, key) + "/surfaces.bin") ||
         !shippedReferencePath(key).empty();
}

/// Whether muscle `m`'s part of the solve `key` is stored alone: in the cache or shipped.
bool partStored(const std::string& cacheDir, const std::string& key, size_t m) {
  return std::filesystem::exists(referencePartDir(cacheDir, key, m) + "/part.bin") ||
         !shippedFilePath(shippedPartName(key, m)).empty();
}

/// Whether a part of the solve `key`, of `muscles`, is shipped alone.
bool anyPartShipped(const std::string& key, size_t muscles) {
  for (size_t m = 0; m < muscles; ++m)
    if (!shippedFilePath(shippedPartName(key, m)).empty()) return true;
  return false;
}
}  // namespace

std::string referencePartDir(const std::string& cacheDir, const std::string& key, size_t m) {
  return entryDir(cacheDir, key) + ".parts/muscle" + std::to_string(m);
}

bool referencePartStored(const std::string& cacheDir, const std::string& key, size_t m) {
  return storedWhole(cacheDir, key) || partStored(cacheDir, key, m);
}

bool loadStoredPart(const std::string& cacheDir, const std::string& key, size_t m,
                    MuscleSolution& part) {
  if (loadPart(referencePartDir(cacheDir, key, m) + "/part.bin", part)) return true;
  const std::string shipped = shippedFilePath(shippedPartName(key, m));
  return !shipped.empty() && loadShippedPart(shipped, part);
}

bool loadSolvedPart(const std::string& cacheDir, const std::string& key, size_t m,
                    MuscleSolution& part) {
  CalculixSolution solution;
  if (key.empty() || !loadStoredSolution(cacheDir, key, solution) || m >= solution.muscles.size())
    return false;
  part = std::move(solution.muscles[m]);
  return part.solvedEveryStep() && !part.stepSurfaces.empty();
}

bool recoverCalculixParts(const LoadedScene& scene, const PreparedScene& prepared,
                          const CalculixDefinition& definition, const ContinuumCut& cut,
                          const std::string& cacheDir, CalculixSolution& solution) {
  const auto failed = [](const std::string& failure) { return !failure.empty(); };
  if (!solution.muscles.empty() || solution.interrupted ||
      (solution.returnFailure.empty() &&
       std::none_of(solution.poseFailures.begin(), solution.poseFailures.end(), failed)))
    return false;
  const std::string entry = entryDir(cacheDir, referenceCacheKey(scene, prepared, definition, cut));
  if (!std::filesystem::exists(entry + "/surfaces.bin")) return false;  // shipped: no ccx files
  const std::string work = freshWorkDir(entry + ".reading");
  std::vector<MuscleSolution> parts(prepared.muscles.size());
  bool read = true;
  for (size_t m = 0; m < parts.size() && read; ++m)
    read = solveIn(work, [&] {
      return readSolvedMuscle(scene, prepared, definition, cut, m, entry, work, parts[m]);
    });
  std::filesystem::remove_all(work);
  if (!read) return false;
  const CalculixSolution again = assembleCalculixSolution(scene, prepared, definition, cut, parts);
  // The parts read give back what the solve stored, or they are not its.
  if (again.muscles.empty() || again.poseSurfaces != solution.poseSurfaces ||
      again.returnSurface != solution.returnSurface)
    return false;
  solution.muscles = again.muscles;
  saveSolution(work + ".bin", solution);  // this process's own, then in place
  std::filesystem::rename(work + ".bin", entry + "/surfaces.bin");
  return true;
}

std::string keptPartKey(const LoadedScene& scene, const PreparedScene& prepared,
                        const CalculixDefinition& definition, const ContinuumCut& cut, size_t m) {
  if (definition.incrementScaleOf(m) == definition.incrementScale) return "";
  return referenceCacheKey(scene, prepared, muscleDefinition(definition, m), cut);
}

namespace {
/// Muscle `m`'s part of the solve whose key keptPartKey gives, into `work` as a solved part
/// (with its .inp and ccx's files where they are in the cache); false where that solve does not
/// keep it solved.
bool takeKeptPart(const LoadedScene& scene, const PreparedScene& prepared,
                  const CalculixDefinition& definition, const ContinuumCut& cut,
                  const std::string& cacheDir, size_t m, const std::string& work,
                  MuscleSolution& part) {
  namespace fs = std::filesystem;
  const std::string source = keptPartKey(scene, prepared, definition, cut, m);
  if (source.empty() || !loadSolvedPart(cacheDir, source, m, part)) return false;
  fs::create_directories(work);
  const std::string stem = fs::path(part.inputFile).stem().string();
  if (fs::is_directory(entryDir(cacheDir, source)))
    for (const fs::directory_entry& file : fs::directory_iterator(entryDir(cacheDir, source)))
      if (file.path().stem() == stem) fs::copy_file(file.path(), work / file.path().filename());
  if (!fs::exists(work / fs::path(part.inputFile).filename()))
    part.inputFile.clear();  // taken from a shipped solve: no files
  return true;
}

/// Muscle `m`'s part of the solve taken as takeKeptPart says into its part directory (as
/// cachedCalculixMuscle stores one); false (nothing kept) where it cannot be taken.
bool storeKeptPart(const LoadedScene& scene, const PreparedScene& prepared,
                   const CalculixDefinition& definition, const ContinuumCut& cut,
                   const std::string& cacheDir, size_t m) {
  const std::string dir =
      referencePartDir(cacheDir, referenceCacheKey(scene, prepared, definition, cut), m);
  const std::string work = freshWorkDir(dir);
  MuscleSolution part;
  if (!solveIn(work, [&] {
        return takeKeptPart(scene, prepared, definition, cut, cacheDir, m, work, part);
      })) {
    std::filesystem::remove_all(work);
    return false;
  }
  savePart(work + "/part.bin", part);
  storeWork(work, dir, dir + "/part.bin");
  return true;
}
}  // namespace

bool cachedCalculixMuscle(const LoadedScene& scene, const PreparedScene& prepared,
                          const CalculixDefinition& definition, const ContinuumCut& cut,
                          const std::string& cacheDir, size_t m,
                          const std::function<void(const ReferenceProgress&)>& progress,
                          const std::atomic<bool>* cancel) {
  const std::string key = referenceCacheKey(scene, prepared, definition, cut);
  const std::string dir = referencePartDir(cacheDir, key, m);
  MuscleSolution part;
  if (storedWhole(cacheDir, key)) return true;
  if (loadStoredPart(cacheDir, key, m, part) && !part.hitMemoryLimit()) return true;
  std::filesystem::remove_all(dir);  // none, or one that hit the memory limit: solved again
  if (storeKeptPart(scene, prepared, definition, cut, cacheDir, m)) return true;
  const std::string work = freshWorkDir(dir);
  part = solveIn(work, [&] {
    return solveCalculixMuscle(scene, prepared, definition, cut, m, work, progress, cancel);
  });
  if (part.interrupted) {
    std::filesystem::remove_all(work);
    return false;
  }
  savePart(work + "/part.bin", part);
  storeWork(work, dir, dir + "/part.bin");
  return true;
}

bool mergeCalculixParts(const LoadedScene& scene, const PreparedScene& prepared,
                        const CalculixDefinition& definition, const ContinuumCut& cut,
                        const std::string& cacheDir, CalculixSolution& solution) {
  const std::string key = referenceCacheKey(scene, prepared, definition, cut);
  const std::string entry = entryDir(cacheDir, key);
  std::vector<MuscleSolution> parts(prepared.muscles.size());
  const auto partFile = [&](size_t m) { return referencePartDir(cacheDir, key, m) + "/part.bin"; };
  MuscleSolution kept;
  for (size_t m = 0; m < parts.size(); ++m)  // each stored, or one a retry keeps (no ccx)
    if (!partStored(cacheDir, key, m) &&
        !loadSolvedPart(cacheDir, keptPartKey(scene, prepared, definition, cut, m), m, kept))
      return false;
  for (size_t m = 0; m < parts.size(); ++m) {
    if (!loadStoredPart(cacheDir, key, m, parts[m]) &&
        !(storeKeptPart(scene, prepared, definition, cut, cacheDir, m) &&
          loadPart(partFile(m), parts[m])))
      return false;
    if (!parts[m].inputFile.empty()) parts[m].inputFile = entry + "/" + parts[m].inputFile;
  }
  const std::string work = freshWorkDir(entry);
  try {
    copyPartFiles(cacheDir, key, parts, work);
  } catch (const std::filesystem::filesystem_error&) {  // another process merged them first
    std::error_code ignored;
    std::filesystem::remove_all(work, ignored);
    if (loadSolution(entry + "/surfaces.bin", solution)) return true;
    throw;
  }
  solution = assembleCalculixSolution(scene, prepared, definition, cut, parts);
  saveSolution(work + "/surfaces.bin", solution);
  storeWork(work, entry, entry + "/surfaces.bin");
  std::error_code ignored;
  std::filesystem::remove_all(entry + ".parts", ignored);
  loadSolution(entry + "/surfaces.bin", solution);  // the one kept, ours or another's
  return true;
}

void solveCalculixCells(const LoadedScene& scene, const PreparedScene& prepared,
                        const std::vector<ReferenceCell>& cells, const std::string& cacheDir,
                        const std::function<void(const ReferenceProgress&)>& progress,
                        const std::atomic<bool>* cancel, int jobs) {
  std::atomic<size_t> next{0};
  std::mutex mutex;
  std::exception_ptr failure;
  const auto report = [&](const ReferenceProgress& p) {
    const std::lock_guard<std::mutex> lock(mutex);
    if (progress) progress(p);
  };
  const auto work = [&] {
    for (size_t c; (c = next++) < cells.size() && !(cancel && cancel->load());) {
      const ReferenceCell& cell = cells[c];
      try {
        cachedCalculixMuscle(scene, prepared, cell.definition, cell.cut, cacheDir, cell.muscle,
                             report, cancel);
      } catch (...) {
        const std::lock_guard<std::mutex> lock(mutex);
        if (!failure) failure = std::current_exception();
        next = cells.size();
      }
    }
  };
  std::vector<std::thread> threads;
  for (int j = 0; j < std::max(1, std::min(jobs, static_cast<int>(cells.size()))); ++j)
    threads.emplace_back(work);
  for (std::thread& thread : threads) thread.join();
  if (failure) std::rethrow_exception(failure);
}

CalculixSolution cachedCalculixReference(
    const LoadedScene& scene, const PreparedScene& prepared, const CalculixDefinition& definition,
    const ContinuumCut& cut, const std::string& cacheDir,
    const std::function<void(const ReferenceProgress&)>& progress, const std::atomic<bool>* cancel,
    bool* fromCache, int jobs) {
  const std::string key = referenceCacheKey(scene, prepared, definition, cut);
  const std::string entry = entryDir(cacheDir, key);
  const std::string stored = entry + "/surfaces.bin";
  CalculixSolution solution;
  const bool found = loadStoredSolution(cacheDir, key, solution) && !solution.hitMemoryLimit();
  if (fromCache) *fromCache = found;
  if (found) return solution;
  if (solution.hitMemoryLimit()) std::filesystem::remove_all(entry);  // solved again
  // A solve with muscles at other increments takes those from the solve they were solved in.
  if (jobs > 1 || std::filesystem::exists(entry + ".parts") ||
      anyPartShipped(key, prepared.muscles.size()) || !definition.muscleIncrementScales.empty()) {
    std::vector<ReferenceCell> cells;
    for (size_t m = 0; m < prepared.muscles.size(); ++m) cells.push_back({definition, cut, m});
    solveCalculixCells(scene, prepared, cells, cacheDir, progress, cancel, jobs);
    if (mergeCalculixParts(scene, prepared, definition, cut, cacheDir, solution)) return solution;
    return assembleCalculixSolution(scene, prepared, definition, cut, {});  // interrupted
  }
  const std::string work = freshWorkDir(entry);
  solution = solveIn(work, [&] {
    return solveCalculixReference(scene, prepared, definition, cut, work, progress, cancel);
  });
  if (solution.interrupted) {
    std::filesystem::remove_all(work);
    solution.inputFiles.clear();  // they were in the work directory
    return solution;
  }
  for (std::string& file : solution.inputFiles) file = entry + file.substr(work.size());
  saveSolution(work + "/surfaces.bin", solution);
  storeWork(work, entry, stored);
  if (!loadSolution(stored, solution)) throw std::runtime_error("cannot read " + stored);
  return solution;
}

}  // namespace fibremss
