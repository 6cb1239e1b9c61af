// Surfaces as differences from earlier ones (SurfaceDeltas.h).
#include "SurfaceDeltas.h"

#include <cmath>
#include <cstring>
#include <numeric>
#include <utility>

#include "CacheRead.h"
#include "fibremss/Error.h"

namespace fibremss {
namespace {

enum class Unit : uint8_t { Ulps = 0, Quanta = 1 };

/// A float's bits as an integer that orders as the floats do (-0 and 0 both 0).
int64_t ordered(float f) {
  int32_t bits;
  std::memcpy(&bits, &f, sizeof bits);
  return bits >= 0 ? int64_t(bits) : -int64_t(bits & 0x7fffffff);
}

float fromOrdered(int64_t o) {
  const uint32_t bits = o >= 0 ? uint32_t(o) : (uint32_t(-o) | 0x80000000u);
  float f;
  std::memcpy(&f, &bits, sizeof f);
  return f;
}

uint64_t zigzag(int64_t v) {
  return (uint64_t(v) << 1) ^ uint64_t(v >> 63);
}
int64_t unzigzag(uint64_t u) {
  return int64_t(u >> 1) ^ -int64_t(u & 1);
}

size_t varintBytes(uint64_t u) {
  size_t bytes = 1;
  for (; u >= 0x80; u >>= 7) ++bytes;
  return bytes;
}

void writeVarint(std::string& out, uint64_t u) {
  for (; u >= 0x80; u >>= 7) out.push_back(char(0x80 | (u & 0x7f)));
  out.push_back(char(u));
}

uint64_t readVarint(std::istream& in, const std::string& path) {
  uint64_t u = 0;
  for (int shift = 0; shift < 64; shift += 7) {
    const int byte = in.get();
    if (byte == std::char_traits<char>::eof())
      throw InputError(path, "", "truncated reference cache file");
    u |= uint64_t(byte & 0x7f) << shift;
    if (!(byte & 0x80)) return u;
  }
  throw InputError(path, "", "not a FibreMSS shipped reference");
}

int64_t quanta(float target, float base) {
  return std::llround((double(target) - double(base)) / kShippedGateQuantum);
}

float fromQuanta(float base, int64_t k) {
  return float(double(base) + double(k) * kShippedGateQuantum);
}

/// The coordinate `delta` from `base` in `unit`, as the reader gives it back; throws InputError
/// naming `path` where ulps leave the floats.
float decoded(float base, int64_t delta, Unit unit, const std::string& path) {
  if (unit == Unit::Quanta) return fromQuanta(base, delta);
  const auto bits = int64_t(uint64_t(ordered(base)) + uint64_t(delta));  // wraps, never overflows
  if (bits > 0x7fffffff || bits < -0x7fffffff)
    throw InputError(path, "", "not a FibreMSS shipped reference");
  return fromOrdered(bits);
}

/// Coordinate i of points (x, y, z of point i / 3), 0 where there are none.
float coordinate(const btVector3* points, size_t i) {
  return points ? float(points[i / 3][int(i % 3)]) : 0.0f;
}

}  // namespace

SurfaceDeltas::SurfaceDeltas(const CalculixSolution& base, std::vector<uint64_t> muscleVertices)
    : muscleVertices_(std::move(muscleVertices)) {
  for (const std::vector<btVector3>& surface : base.poseSurfaces) remember(surface);
  remember(base.returnSurface);
  for (const MuscleSolution& part : base.muscles)
    for (const std::vector<btVector3>& surface : part.stepSurfaces) remember(surface);
}

void SurfaceDeltas::remember(std::vector<btVector3> surface) {
  if (surface.empty()) return;
  kept_.push_back(std::move(surface));
  const std::vector<btVector3>& kept = kept_.back();
  bases_.push_back({kept.data(), kept.size()});
  if (muscleVertices_.size() < 2 ||
      std::accumulate(muscleVertices_.begin(), muscleVertices_.end(), uint64_t(0)) != kept.size())
    return;
  size_t first = 0;
  for (const uint64_t vertices : muscleVertices_) {
    bases_.push_back({kept.data() + first, size_t(vertices)});
    first += vertices;
  }
}

uint32_t SurfaceDeltas::nearestBase(const std::vector<float>& target) const {
  const auto cost = [&](const btVector3* base, size_t bound) {
    size_t bytes = 0;
    int64_t previous[3] = {0, 0, 0};
    for (size_t i = 0; i < target.size() && bytes < bound; ++i) {
      const int64_t delta = quanta(target[i], coordinate(base, i));
      bytes += varintBytes(zigzag(delta - std::exchange(previous[i % 3], delta)));
    }
    return bytes;
  };
  uint32_t nearest = 0;
  size_t least = cost(nullptr, SIZE_MAX);
  for (size_t b = 0; b < bases_.size(); ++b)
    if (bases_[b].size * 3 == target.size())
      if (const size_t bytes = cost(bases_[b].points, least); bytes < least) {
        least = bytes;
        nearest = uint32_t(b + 1);
      }
  return nearest;
}

const btVector3* SurfaceDeltas::basePoints(uint32_t base, size_t size,
                                           const std::string& path) const {
  if (base == 0) return nullptr;
  if (base > bases_.size() || bases_[base - 1].size != size)
    throw InputError(path, "", "not a FibreMSS shipped reference (no such base surface)");
  return bases_[base - 1].points;
}

void SurfaceDeltas::write(std::ostream& out, const std::vector<btVector3>& points) {
  const uint64_t count = points.size();
  out.write(reinterpret_cast<const char*>(&count), sizeof count);
  if (points.empty()) return;
  std::vector<float> target(points.size() * 3);
  for (size_t i = 0; i < target.size(); ++i) target[i] = coordinate(points.data(), i);
  const uint32_t base = nearestBase(target);
  const btVector3* from = basePoints(base, points.size(), "");
  bool exact = true;
  for (size_t i = 0; i < target.size() && exact; ++i)
    exact = std::abs(double(target[i]) - double(coordinate(from, i))) <= kShippedGateQuantum;
  const Unit unit = exact ? Unit::Ulps : Unit::Quanta;
  out.write(reinterpret_cast<const char*>(&base), sizeof base);
  out.write(reinterpret_cast<const char*>(&unit), sizeof unit);
  std::string bytes;
  std::vector<btVector3> back(points.size());
  int64_t previous[3] = {0, 0, 0};  // each coordinate as the change from the vertex before
  for (size_t i = 0; i < target.size(); ++i) {
    const float b = coordinate(from, i);
    const int64_t delta = exact ? ordered(target[i]) - ordered(b) : quanta(target[i], b);
    writeVarint(bytes, zigzag(delta - std::exchange(previous[i % 3], delta)));
    back[i / 3][int(i % 3)] = btScalar(decoded(b, delta, unit, ""));
  }
  out.write(bytes.data(), std::streamsize(bytes.size()));
  remember(std::move(back));
}

std::vector<btVector3> SurfaceDeltas::read(std::istream& in, const std::string& path) {
  const auto count = readValue<uint64_t>(in, path);
  if (count > (1ull << 32)) throw InputError(path, "", "not a FibreMSS shipped reference");
  if (count == 0) return {};
  const btVector3* from = basePoints(readValue<uint32_t>(in, path), count, path);
  const auto unit = readValue<Unit>(in, path);
  if (unit != Unit::Ulps && unit != Unit::Quanta)
    throw InputError(path, "", "not a FibreMSS shipped reference");
  std::vector<btVector3> points(count);
  int64_t previous[3] = {0, 0, 0};
  for (size_t i = 0; i < count * 3; ++i) {
    const float b = coordinate(from, i);
    const auto delta =
        int64_t(uint64_t(previous[i % 3]) + uint64_t(unzigzag(readVarint(in, path))));
    previous[i % 3] = delta;
    points[i / 3][int(i % 3)] = btScalar(decoded(b, delta, unit, path));
  }
  remember(points);
  return points;
}

}  // namespace fibremss
