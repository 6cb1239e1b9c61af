#include "fibremss/Gltf.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string_view>
#include <type_traits>

#include "fibremss/Output.h"

namespace fibremss {
namespace {

using Json = nlohmann::json;

constexpr int kFloat = 5126, kUnsignedInt = 5125;          // accessor component types
constexpr int kArrayBuffer = 34962, kIndexBuffer = 34963;  // buffer view targets

/// The JSON and binary chunks of a .glb under construction.
class GlbBuilder {
 public:
  /// `count` elements of `type` ("VEC3", "SCALAR") as a buffer view of its own and an accessor
  /// over it; `bounds` adds the accessor's min and max. Returns the accessor's index.
  template <typename T>
  int accessor(std::span<const T> values, const char* type, int components, int target,
               bool bounds) {
    const size_t offset = binary_.size();
    binary_.resize(offset + values.size_bytes());
    std::memcpy(binary_.data() + offset, values.data(), values.size_bytes());
    binary_.resize((binary_.size() + 3) / 4 * 4, 0);  // the next view starts 4-byte aligned
    Json view{{"buffer", 0}, {"byteOffset", offset}, {"byteLength", values.size_bytes()}};
    if (target) view["target"] = target;
    gltf["bufferViews"].push_back(view);
    Json accessor{{"bufferView", gltf["bufferViews"].size() - 1},
                  {"componentType", std::is_same_v<T, float> ? kFloat : kUnsignedInt},
                  {"count", values.size() / size_t(components)},
                  {"type", type}};
    if (bounds) {
      Json low = Json::array(), high = Json::array();
      for (int c = 0; c < components; ++c) {
        T lowest = std::numeric_limits<T>::max(), highest = std::numeric_limits<T>::lowest();
        for (size_t i = size_t(c); i < values.size(); i += size_t(components))
          lowest = std::min(lowest, values[i]), highest = std::max(highest, values[i]);
        low.push_back(lowest), high.push_back(highest);
      }
      accessor["min"] = low, accessor["max"] = high;
    }
    gltf["accessors"].push_back(accessor);
    return int(gltf["accessors"].size() - 1);
  }

  /// The .glb file: header, JSON chunk (padded with spaces), binary chunk (padded with zeros).
  std::string file() {
    gltf["buffers"] = Json::array({{{"byteLength", binary_.size()}}});
    std::string json = gltf.dump();
    json.resize((json.size() + 3) / 4 * 4, ' ');
    std::string out;
    const auto word = [&out](uint32_t value) {
      out.append(reinterpret_cast<const char*>(&value), 4);
    };
    word(0x46546C67);  // "glTF"
    word(2);
    word(uint32_t(12 + 8 + json.size() + 8 + binary_.size()));
    word(uint32_t(json.size()));
    word(0x4E4F534A);  // "JSON"
    out += json;
    word(uint32_t(binary_.size()));
    word(0x004E4942);  // "BIN"
    out.append(binary_.begin(), binary_.end());
    return out;
  }

  Json gltf{{"asset", {{"version", "2.0"}, {"generator", "FibreMSS"}}},
            {"scene", 0},
            {"scenes", Json::array({{{"nodes", Json::array()}}})},
            {"nodes", Json::array()},
            {"meshes", Json::array()},
            {"materials", Json::array()},
            {"accessors", Json::array()},
            {"bufferViews", Json::array()}};

 private:
  std::string binary_;
};

/// x y z per vertex as float, checking that there are triangles and that they name vertices the
/// mesh has.
std::vector<float> positionsOf(const GltfMesh& mesh) {
  if (mesh.triangles.empty())
    throw std::runtime_error("glTF mesh '" + mesh.name + "' has no triangle");
  for (size_t f = 0; f < mesh.triangles.size(); ++f)
    for (uint32_t v : mesh.triangles[f])
      if (v >= mesh.vertices.size())
        throw std::runtime_error("glTF mesh '" + mesh.name + "': triangle " + std::to_string(f) +
                                 " names vertex " + std::to_string(v) + " of " +
                                 std::to_string(mesh.vertices.size()));
  std::vector<float> positions;
  positions.reserve(3 * mesh.vertices.size());
  for (const btVector3& p : mesh.vertices)
    positions.insert(positions.end(), {float(p.x()), float(p.y()), float(p.z())});
  return positions;
}

/// Area-weighted vertex normals (unit length; +y for a vertex of no area).
std::vector<float> normalsOf(std::span<const float> positions,
                             std::span<const std::array<uint32_t, 3>> triangles) {
  std::vector<double> sum(positions.size(), 0.0);
  const auto at = [&](uint32_t v, int k) { return double(positions[3 * v + k]); };
  for (const auto& t : triangles) {
    double a[3], b[3];
    for (int k = 0; k < 3; ++k) a[k] = at(t[1], k) - at(t[0], k), b[k] = at(t[2], k) - at(t[0], k);
    const double n[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                         a[0] * b[1] - a[1] * b[0]};
    for (uint32_t v : t)
      for (int k = 0; k < 3; ++k) sum[3 * v + k] += n[k];
  }
  std::vector<float> normals(positions.size());
  for (size_t v = 0; v < positions.size() / 3; ++v) {
    const double* n = &sum[3 * v];
    const double length = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int k = 0; k < 3; ++k)
      normals[3 * v + k] = length > 0 ? float(n[k] / length) : (k == 1 ? 1.0f : 0.0f);
  }
  return normals;
}

/// Frame k's values less the first frame's.
std::vector<float> difference(std::span<const float> frame, std::span<const float> first) {
  std::vector<float> delta(frame.size());
  for (size_t i = 0; i < frame.size(); ++i) delta[i] = frame[i] - first[i];
  return delta;
}

}  // namespace

void GltfAnimation::addFrame(double time, std::span<const GltfMesh> meshes) {
  const float seconds = float(time);
  if (!times_.empty() && !(seconds > times_.back()))
    throw std::runtime_error("glTF animation: frame times must increase, got " +
                             std::to_string(time) + " after " + std::to_string(times_.back()));
  if (!times_.empty() && meshes.size() != meshes_.size())
    throw std::runtime_error("glTF animation: every frame has the same meshes");
  for (size_t m = 0; m < meshes.size(); ++m) {
    std::vector<float> positions = positionsOf(meshes[m]);
    if (times_.empty()) {
      meshes_.push_back({meshes[m].name,
                         {meshes[m].triangles.begin(), meshes[m].triangles.end()},
                         meshes[m].colour,
                         {}});
    } else if (positions.size() != meshes_[m].positions.front().size() ||
               meshes[m].name != meshes_[m].name) {
      throw std::runtime_error("glTF animation: mesh '" + meshes[m].name +
                               "' differs from the first frame's");
    }
    meshes_[m].positions.push_back(std::move(positions));
  }
  times_.push_back(seconds);
}

void GltfAnimation::write(const std::string& path) const {
  GlbBuilder glb;
  Json& gltf = glb.gltf;
  const size_t targets = times_.empty() ? 0 : times_.size() - 1;
  for (size_t m = 0; m < meshes_.size(); ++m) {
    const Mesh& mesh = meshes_[m];
    const std::span<const std::array<uint32_t, 3>> triangles = mesh.triangles;
    const std::vector<float>& first = mesh.positions.front();
    const std::vector<float> normals = normalsOf(first, triangles);
    Json primitive{
        {"attributes",
         {{"POSITION", glb.accessor<float>(first, "VEC3", 3, kArrayBuffer, true)},
          {"NORMAL", glb.accessor<float>(normals, "VEC3", 3, kArrayBuffer, false)}}},
        {"indices", glb.accessor<uint32_t>({triangles.front().data(), 3 * triangles.size()},
                                           "SCALAR", 1, kIndexBuffer, false)},
        {"material", m}};
    for (size_t k = 1; k <= targets; ++k) {
      const std::vector<float> moved = difference(mesh.positions[k], first);
      const std::vector<float> turned =
          difference(normalsOf(mesh.positions[k], triangles), normals);
      primitive["targets"].push_back(
          {{"POSITION", glb.accessor<float>(moved, "VEC3", 3, kArrayBuffer, true)},
           {"NORMAL", glb.accessor<float>(turned, "VEC3", 3, kArrayBuffer, false)}});
    }
    Json object{{"name", mesh.name}, {"primitives", Json::array({primitive})}};
    if (targets > 0) object["weights"] = std::vector<float>(targets, 0.0f);
    gltf["meshes"].push_back(object);
    gltf["materials"].push_back(
        {{"name", mesh.name},
         {"pbrMetallicRoughness",
          {{"baseColorFactor", mesh.colour}, {"metallicFactor", 0.0}, {"roughnessFactor", 0.7}}}});
    gltf["nodes"].push_back({{"name", mesh.name}, {"mesh", m}});
    gltf["scenes"][0]["nodes"].push_back(m);
  }
  if (targets > 0 && !meshes_.empty()) {
    // Frame k is target k-1 at weight 1, every other at 0.
    std::vector<float> weights(times_.size() * targets, 0.0f);
    for (size_t k = 1; k <= targets; ++k) weights[k * targets + k - 1] = 1.0f;
    const int input = glb.accessor<float>(times_, "SCALAR", 1, 0, true);
    const int output = glb.accessor<float>(weights, "SCALAR", 1, 0, false);
    Json animation{
        {"name", "run"},
        {"samplers",
         Json::array({{{"input", input}, {"output", output}, {"interpolation", "LINEAR"}}})}};
    for (size_t m = 0; m < meshes_.size(); ++m)
      animation["channels"].push_back(
          {{"sampler", 0}, {"target", {{"node", m}, {"path", "weights"}}}});
    gltf["animations"] = Json::array({animation});
  }
  writeFileAtomically(path, glb.file());
}

void writeGlb(const std::string& path, std::span<const GltfMesh> meshes) {
  GltfAnimation still;
  still.addFrame(0, meshes);
  still.write(path);
}

}  // namespace fibremss
