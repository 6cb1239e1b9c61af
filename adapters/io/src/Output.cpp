// Output writers: atomic file writes, VTK XML PolyData (.vtp, appended raw data in
// vtkZLibDataCompressor blocks) and .pvd collections.
#include "fibremss/Output.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <span>
#include <stdexcept>
#include <system_error>

#include "fibremss/Error.h"

namespace fibremss {
namespace {

namespace fs = std::filesystem;

static_assert(std::endian::native == std::endian::little,
              "the .vtp writer copies numbers as they are in memory and declares LittleEndian");

/// Uncompressed bytes per block, VTK's default (vtkXMLWriter::BlockSize).
constexpr size_t kBlockSize = 32768;

/// A name unique per process and call, so concurrent writers never share a temporary file.
fs::path temporaryPathFor(const fs::path& target) {
  static std::atomic<unsigned> counter{0};
  fs::path temporary = target;
  temporary += ".tmp." + std::to_string(::getpid()) + "." + std::to_string(counter++);
  return temporary;
}

std::string escapeXml(std::string_view text) {
  std::string escaped;
  for (char c : text) {
    switch (c) {
      case '&':
        escaped += "&amp;";
        break;
      case '<':
        escaped += "&lt;";
        break;
      case '>':
        escaped += "&gt;";
        break;
      case '"':
        escaped += "&quot;";
        break;
      default:
        escaped += c;
    }
  }
  return escaped;
}

template <typename T>
void appendRaw(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out.append(bytes, sizeof(T));
}

/// `bytes` as vtkZLibDataCompressor writes them: a header of UInt64 numbers (block count,
/// uncompressed block size, uncompressed size of a partial last block or 0, then each block's
/// compressed size) followed by the zlib streams of the blocks.
void appendCompressed(std::string& out, std::span<const char> bytes) {
  const size_t blocks = (bytes.size() + kBlockSize - 1) / kBlockSize;
  const size_t headerAt = out.size();
  appendRaw<uint64_t>(out, blocks);
  appendRaw<uint64_t>(out, kBlockSize);
  appendRaw<uint64_t>(out, bytes.size() % kBlockSize);
  out.append(8 * blocks, '\0');  // the compressed sizes, filled in below
  std::string block(compressBound(kBlockSize), '\0');
  for (size_t b = 0; b < blocks; ++b) {
    const size_t begin = b * kBlockSize, size = std::min(kBlockSize, bytes.size() - begin);
    uLongf compressed = static_cast<uLongf>(block.size());
    if (compress2(reinterpret_cast<Bytef*>(block.data()), &compressed,
                  reinterpret_cast<const Bytef*>(bytes.data() + begin), static_cast<uLong>(size),
                  Z_DEFAULT_COMPRESSION) != Z_OK)
      throw std::runtime_error("zlib could not compress a block");
    const uint64_t compressedSize = compressed;
    std::memcpy(out.data() + headerAt + 8 * (3 + b), &compressedSize, 8);
    out.append(block.data(), compressed);
  }
}

template <typename T>
constexpr const char* vtkType() {
  if constexpr (std::is_same_v<T, float>) return "Float32";
  if constexpr (std::is_same_v<T, double>) return "Float64";
  if constexpr (std::is_same_v<T, int32_t>) return "Int32";
}

/// The XML of a .vtp and its appended data, built array by array.
class VtpBuilder {
 public:
  /// A DataArray element pointing into the appended data, and its values compressed there.
  /// `tuples` > 0 writes NumberOfTuples (field data needs it).
  template <typename T>
  void array(std::string_view name, int components, std::span<const T> values, size_t tuples = 0) {
    xml += "        <DataArray type=\"";
    xml += vtkType<T>();
    xml += "\" Name=\"" + escapeXml(name) + '"';
    if (components > 1) xml += " NumberOfComponents=\"" + std::to_string(components) + '"';
    if (tuples > 0) xml += " NumberOfTuples=\"" + std::to_string(tuples) + '"';
    xml += " format=\"appended\" offset=\"" + std::to_string(appended.size()) + "\"/>\n";
    appendCompressed(appended, std::span<const char>(reinterpret_cast<const char*>(values.data()),
                                                     values.size_bytes()));
  }

  void array(const DataArray& data, size_t tuples = 0) {
    std::visit(
        [&](const auto& values) { array(data.name, data.components, std::span(values), tuples); },
        data.values);
  }

  /// A cell block (Verts, Lines, Polys) with its connectivity and end offsets; nothing when empty.
  void cells(std::string_view tag, std::span<const int32_t> connectivity,
             std::span<const int32_t> offsets) {
    if (offsets.empty()) return;
    xml += "      <" + std::string(tag) + ">\n";
    array<int32_t>("connectivity", 1, connectivity);
    array<int32_t>("offsets", 1, offsets);
    xml += "      </" + std::string(tag) + ">\n";
  }

  std::string xml;       ///< the document up to the appended data
  std::string appended;  ///< the appended data's bytes
};

void checkPolyData(const std::string& path, const PolyData& data) {
  const size_t n = data.points.size();
  auto fail = [&](const std::string& what) {
    throw std::runtime_error(path + ": cannot write PolyData: " + what);
  };
  if (n >= size_t(std::numeric_limits<int32_t>::max())) fail("too many points for Int32 cells");
  if (data.lineOffsets.empty() || data.lineOffsets.front() != 0 ||
      data.lineOffsets.back() != data.lineIndices.size())
    fail("line offsets must start at 0 and end at the number of line indices");
  for (size_t i = 1; i < data.lineOffsets.size(); ++i)
    if (data.lineOffsets[i] < data.lineOffsets[i - 1]) fail("line offsets must not decrease");
  for (uint32_t index : data.lineIndices)
    if (index >= n) fail("line index " + std::to_string(index) + " >= point count");
  for (const auto& triangle : data.triangles)
    for (uint32_t index : triangle)
      if (index >= n) fail("triangle index " + std::to_string(index) + " >= point count");
  for (const DataArray& array : data.pointData)
    if (array.components < 1 || array.size() != n * size_t(array.components))
      fail("array '" + array.name + "' has " + std::to_string(array.size()) + " values for " +
           std::to_string(n) + " points of " + std::to_string(array.components) + " component(s)");
  for (const DataArray& array : data.fieldData)
    if (array.components < 1 || array.size() == 0 || array.size() % size_t(array.components) != 0)
      fail("field array '" + array.name + "' has " + std::to_string(array.size()) +
           " values, not a whole number of tuples of " + std::to_string(array.components));
}

std::vector<int32_t> sequence(size_t count, int32_t first, int32_t step) {
  std::vector<int32_t> values(count);
  for (size_t i = 0; i < count; ++i) values[i] = first + step * int32_t(i);
  return values;
}

void writeCells(VtpBuilder& out, const PolyData& data) {
  const size_t pointCount = data.points.size();
  if (data.pointsAsVertices)
    out.cells("Verts", sequence(pointCount, 0, 1), sequence(pointCount, 1, 1));
  const std::vector<int32_t> lineIndices(data.lineIndices.begin(), data.lineIndices.end());
  const std::vector<int32_t> lineEnds(data.lineOffsets.begin() + 1, data.lineOffsets.end());
  out.cells("Lines", lineIndices, lineEnds);
  std::vector<int32_t> triangles;
  triangles.reserve(3 * data.triangles.size());
  for (const auto& triangle : data.triangles)
    for (uint32_t index : triangle) triangles.push_back(int32_t(index));
  out.cells("Polys", triangles, sequence(data.triangles.size(), 3, 3));
}

/// The process id the directory's previous writer recorded in its lock file ("" if none).
std::string recordedWriter(int lock) {
  char text[24] = {};
  const ssize_t size = ::pread(lock, text, sizeof text - 1, 0);
  std::string pid(text, size > 0 ? size_t(size) : 0);
  while (!pid.empty() && pid.back() == '\n') pid.pop_back();
  const bool digits = !pid.empty() && std::all_of(pid.begin(), pid.end(),
                                                  [](char c) { return c >= '0' && c <= '9'; });
  return digits ? pid : "";
}

/// Records this process as the directory's writer (its temporaries carry this id); false, with
/// errno set, when the lock file cannot be written.
bool recordWriter(int lock) {
  const std::string pid = std::to_string(::getpid()) + "\n";
  return ::ftruncate(lock, 0) == 0 && ::pwrite(lock, pid.data(), pid.size(), 0) >= 0;
}

/// Whether `name` is NAME.tmp.PID.N for the given writer's `pid`.
bool isTemporaryOf(const std::string& name, const std::string& pid) {
  const std::string marker = ".tmp." + pid + ".";
  const size_t at = name.rfind(marker);
  if (at == std::string::npos || at == 0 || at + marker.size() == name.size()) return false;
  return std::all_of(name.begin() + std::ptrdiff_t(at + marker.size()), name.end(),
                     [](char c) { return c >= '0' && c <= '9'; });
}

/// Removes the temporaries (NAME.tmp.PID.N) the writer `pid` left below `path`: a killed writer's.
/// Nothing else, whatever its name: another process's files are not this one's to remove.
size_t removeTemporariesOf(const std::string& path, const std::string& pid) {
  size_t removed = 0;
  if (pid.empty()) return removed;
  std::error_code error;
  for (auto it = fs::recursive_directory_iterator(path, error);
       !error && it != fs::recursive_directory_iterator(); it.increment(error))
    if (it->is_regular_file(error) && isTemporaryOf(it->path().filename().string(), pid) &&
        fs::remove(it->path(), error))
      ++removed;
  return removed;
}

}  // namespace

size_t DataArray::size() const {
  return std::visit([](const auto& v) { return v.size(); }, values);
}

void writeFileAtomically(const std::string& path, std::string_view content) {
  const fs::path target(path);
  std::error_code error;
  if (target.has_parent_path()) {
    fs::create_directories(target.parent_path(), error);
    if (error)
      throw InputError(
          path, "",
          "cannot create the directory " + target.parent_path().string() + ": " + error.message());
  }
  if (fs::is_directory(target, error))
    throw InputError(path, "", "cannot write: a directory has this name; expected a file or none");
  const fs::path temporary = temporaryPathFor(target);
  const int file = ::open(temporary.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (file < 0) throw InputError(path, "", std::string("cannot write: ") + std::strerror(errno));
  int cause = 0;
  for (size_t written = 0; written < content.size() && cause == 0;) {
    const ssize_t n = ::write(file, content.data() + written, content.size() - written);
    if (n > 0) written += size_t(n);
    if (n < 0 && errno != EINTR) cause = errno;
  }
  if (::close(file) != 0 && cause == 0) cause = errno;
  if (cause == 0 && ::rename(temporary.c_str(), target.c_str()) != 0) cause = errno;
  if (cause != 0) {
    ::unlink(temporary.c_str());  // nothing half-written stays
    throw InputError(path, "", std::string("cannot write: ") + std::strerror(cause));
  }
}

void removeOutputFile(const std::string& path) {
  std::error_code error;
  if (fs::is_directory(path, error))
    throw InputError(path, "",
                     "a directory has the name of an output file; expected a file or none");
  fs::remove(path, error);
  if (error) throw InputError(path, "", "cannot remove the previous output: " + error.message());
}

void requireWritableDirectory(const std::string& path) {
  std::error_code error;
  fs::path existing = fs::absolute(path, error);
  while (!fs::exists(existing, error) && existing.has_relative_path())
    existing = existing.parent_path();
  if (!fs::is_directory(existing, error))
    throw InputError(path, "", existing.string() + " is not a directory; expected a directory");
  if (::access(existing.c_str(), W_OK | X_OK) != 0)
    throw InputError(path, "",
                     "cannot write output: " + existing.string() + ": " + std::strerror(errno));
}

OutputDirectory::OutputDirectory(const std::string& path) {
  requireWritableDirectory(path);
  std::error_code error;
  fs::create_directories(path, error);
  if (error) throw InputError(path, "", "cannot create the directory: " + error.message());
  lockPath_ = (fs::path(path) / ".fibremss.lock").string();
  // A writer removes the lock file when it ends: a lock taken on a file already removed is
  // taken again on the file now there.
  while (!lockHeld()) {
  }
  removed_ = removeTemporariesOf(path, recordedWriter(lock_));
  if (!recordWriter(lock_)) {
    const int cause = errno;
    ::close(lock_);
    throw InputError(lockPath_, "",
                     std::string("cannot record this writer: ") + std::strerror(cause));
  }
}

bool OutputDirectory::lockHeld() {
  // Not followed when it is a symbolic link: the lock is created in this directory or nowhere.
  lock_ = ::open(lockPath_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC | O_NOFOLLOW, 0644);
  if (lock_ < 0) {
    const int cause = errno;
    throw InputError(lockPath_, "",
                     std::string("cannot open the lock file: ") + std::strerror(cause) +
                         (cause == ELOOP ? " (a symbolic link; expected a regular file)" : ""));
  }
  if (::flock(lock_, LOCK_EX | LOCK_NB) != 0) {
    ::close(lock_);
    throw InputError(fs::path(lockPath_).parent_path().string(), "",
                     "another fibremss process is writing into this directory; wait for it or "
                     "choose another --out");
  }
  struct stat held {
  }, named{};
  if (::fstat(lock_, &held) == 0 && ::stat(lockPath_.c_str(), &named) == 0 &&
      held.st_ino == named.st_ino && held.st_dev == named.st_dev)
    return true;
  ::close(lock_);
  return false;
}

OutputDirectory::~OutputDirectory() {
  ::unlink(lockPath_.c_str());  // while still held: no writer takes the file being removed
  ::close(lock_);               // releases the flock
}

double powerOfTwoStep(double limit) {
  return limit > 0 ? std::exp2(std::floor(std::log2(limit))) : 0;
}

void roundToStep(std::vector<float>& values, double step) {
  if (step > 0)
    for (float& value : values) value = float(std::nearbyint(double(value) / step) * step);
}

void writeVtp(const std::string& path, const PolyData& data) {
  checkPolyData(path, data);
  const size_t pointCount = data.points.size();
  VtpBuilder out;
  out.xml =
      "<?xml version=\"1.0\"?>\n"
      "<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" "
      "header_type=\"UInt64\" compressor=\"vtkZLibDataCompressor\">\n  <PolyData>\n";
  if (!data.fieldData.empty()) {
    out.xml += "    <FieldData>\n";
    for (const DataArray& array : data.fieldData)
      out.array(array, array.size() / size_t(array.components));
    out.xml += "    </FieldData>\n";
  }
  out.xml += "    <Piece NumberOfPoints=\"" + std::to_string(pointCount) + "\" NumberOfVerts=\"" +
             std::to_string(data.pointsAsVertices ? pointCount : 0) + "\" NumberOfLines=\"" +
             std::to_string(data.lineOffsets.size() - 1) +
             "\" NumberOfStrips=\"0\" NumberOfPolys=\"" + std::to_string(data.triangles.size()) +
             "\">\n";
  out.xml += "      <PointData";
  const auto scalars = std::find_if(data.pointData.begin(), data.pointData.end(),
                                    [](const DataArray& a) { return a.components == 1; });
  if (scalars != data.pointData.end()) out.xml += " Scalars=\"" + escapeXml(scalars->name) + '"';
  out.xml += ">\n";
  for (const DataArray& array : data.pointData) out.array(array);
  out.xml += "      </PointData>\n      <Points>\n";
  std::vector<float> points(3 * pointCount);
  for (size_t i = 0; i < pointCount; ++i)
    for (int k = 0; k < 3; ++k) points[3 * i + k] = float(data.points[i][k] * data.pointScale);
  roundToStep(points, data.pointStep);
  out.array<float>("Points", 3, points);
  out.xml += "      </Points>\n";
  writeCells(out, data);
  out.xml += "    </Piece>\n  </PolyData>\n  <AppendedData encoding=\"raw\">\n   _";
  out.xml += out.appended;
  out.xml += "\n  </AppendedData>\n</VTKFile>\n";
  writeFileAtomically(path, out.xml);
}

void PvdCollection::add(double time, const std::string& file, int part, const std::string& name) {
  entries_.push_back({time, file, part, name});
}

void PvdCollection::write(const std::string& path) const {
  std::string out = "<?xml version=\"1.0\"?>\n";
  out += "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n";
  out += "  <Collection>\n";
  for (const Entry& entry : entries_) {
    char time[32];
    const auto end = std::to_chars(time, time + sizeof time, entry.time).ptr;
    out += "    <DataSet timestep=\"" + std::string(time, end) + "\" group=\"\" part=\"" +
           std::to_string(entry.part) + "\" file=\"" + escapeXml(entry.file) + '"' +
           (entry.name.empty() ? "" : " name=\"" + escapeXml(entry.name) + '"') + "/>\n";
  }
  out += "  </Collection>\n</VTKFile>\n";
  writeFileAtomically(path, out);
}

}  // namespace fibremss
