#include "FramePlayer.h"

#include <imgui.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>

#include "Panel.h"
#include "fibremss/Error.h"
#include "fibremss/InputFiles.h"
#include "fibremss/MuscleSystem.h"

namespace fibremss::viewer {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

/// Frames a second while playing.
constexpr double kFramesPerSecond = 8;

/// The JSON file at `path`, or null when it is absent; InputError when it is no regular file or
/// nests too deep.
nlohmann::json readJson(const fs::path& path) {
  return fs::exists(path) ? nlohmann::json::parse(readJsonText(path.string()), nullptr, false)
                          : nlohmann::json();
}

/// The array's values as one scalar per point: itself, or the length of a vector.
std::vector<float> scalars(const PointArray& array) {
  if (array.components == 1) return array.values;
  const size_t n = array.values.size() / size_t(array.components);
  std::vector<float> values(n);
  for (size_t i = 0; i < n; ++i) {
    double sum = 0;
    for (int k = 0; k < array.components; ++k) {
      const double v = array.values[i * size_t(array.components) + size_t(k)];
      sum += v * v;
    }
    values[i] = float(std::sqrt(sum));
  }
  return values;
}

/// A field of the summary's series row at simulated time `time` (as the .pvd's text gives it,
/// to about 10 digits; NaN when there is none).
double seriesAt(const nlohmann::json& summary, double time, const char* key) {
  if (!summary.is_object() || !summary.contains("series")) return NAN;
  for (const nlohmann::json& row : summary["series"])
    if (std::abs(row.value("time_s", double(NAN)) - time) <= 1e-9 * std::max(1.0, std::abs(time)) &&
        row.contains(key) && row[key].is_number())
      return row[key].get<double>();
  return NAN;
}

}  // namespace

FramePlayer::FramePlayer(const std::string& runDir, const DebugRequest& debug)
    : dir_(runDir), summary_(readJson(fs::path(runDir) / "summary.json")), debug_(debug) {
  const nlohmann::json scene = readJson(fs::path(runDir) / "scene.json");
  if (scene.is_object() && scene.value("units", "m") == "mm") scale_ = 0.001;
  for (const PvdDataSet& set : readPvd((fs::path(runDir) / "run.pvd").string())) {
    if (frames_.empty() || frames_.back().time != set.time)
      frames_.push_back({set.time, {}, {}, {}});
    Frame& frame = frames_.back();
    const std::string name = fs::path(set.file).filename().string();
    if (name.starts_with("bone"))
      frame.bones.push_back(set.file);
    else if (name.find("_particles_") != std::string::npos)
      frame.particles.push_back(set.file);
    else
      frame.surfaces.push_back(set.file);
  }
  if (frames_.empty())
    throw InputError((fs::path(runDir) / "run.pvd").string(), "",
                     "expected at least one DataSet (a run with frames)");
  load();
}

void FramePlayer::show(int index) {
  const int last = int(frames_.size()) - 1;
  const int next = loop && index > last ? 0 : std::clamp(index, 0, last);
  if (next != index_) loaded_ = false;
  index_ = next;
}

void FramePlayer::setDebug(const DebugRequest& debug) {
  if (debug == debug_) return;
  debug_ = debug;
  loaded_ = false;
}

bool FramePlayer::fetch(Snapshot& into) {
  if (playing_ &&
      std::chrono::duration<double>(Clock::now() - shownAt_).count() >= 1.0 / kFramesPerSecond) {
    if (!loop && index_ + 1 >= int(frames_.size()))
      playing_ = false;
    else
      show(index_ + 1);
  }
  if (!loaded_) load();
  if (snapshot_.version <= into.version) return false;
  into = snapshot_;
  return true;
}

ViewMesh FramePlayer::surface(const std::string& file, size_t muscle) const {
  PolyDataFile data = readVtp((fs::path(dir_) / file).string(), scale_);
  ViewMesh mesh;
  mesh.name = fs::path(file).stem().string();
  mesh.vertices = std::move(data.points);
  mesh.triangles = std::make_shared<const Triangles>(std::move(data.triangles));
  for (const PointArray& array : data.pointData)
    mesh.arrays.emplace_back(array.name, scalars(array));
  if (!mesh.array("muscle_id"))
    mesh.arrays.emplace_back("muscle_id", std::vector<float>(mesh.vertices.size(), float(muscle)));
  return mesh;
}

const ViewMesh& FramePlayer::bone(const std::string& file) {
  auto found = bones_.find(file);
  if (found != bones_.end()) return found->second;
  PolyDataFile data = readVtp((fs::path(dir_) / file).string(), scale_);
  ViewMesh mesh;
  mesh.name = fs::path(file).stem().string();
  mesh.vertices = std::move(data.points);
  mesh.triangles = std::make_shared<const Triangles>(std::move(data.triangles));
  return bones_.emplace(file, std::move(mesh)).first->second;
}

void FramePlayer::drawParticles(const PolyDataFile& particles, DebugGeometry& debug) const {
  auto push = [](std::vector<float>& to, const btVector3& p) {
    for (int k = 0; k < 3; ++k) to.push_back(float(p[k]));
  };
  if (debug_.muscleFlags & kDrawFibres)
    for (size_t f = 0; f + 1 < particles.lineOffsets.size(); ++f)
      for (uint32_t k = particles.lineOffsets[f] + 1; k < particles.lineOffsets[f + 1]; ++k) {
        push(debug.lineVertices, particles.points[particles.lineIndices[k - 1]]);
        push(debug.lineVertices, particles.points[particles.lineIndices[k]]);
        for (int end = 0; end < 2; ++end)
          debug.lineColours.insert(debug.lineColours.end(), {1, 1, 0});
      }
  if (debug_.muscleFlags & kDrawParticles) {
    const PointArray* boundary = particles.array("boundary");
    for (size_t i = 0; i < particles.points.size(); ++i) {
      if (boundary && boundary->values[i] == 0) continue;  // as live: boundary particles
      push(debug.points, particles.points[i]);
      debug.pointColours.insert(debug.pointColours.end(), {0.3f, 0.8f, 1});
    }
  }
}

void FramePlayer::load() {
  const auto start = Clock::now();
  const Frame& frame = frames_[size_t(index_)];
  Snapshot next;
  for (size_t m = 0; m < frame.surfaces.size(); ++m)
    next.frame.muscles.push_back(surface(frame.surfaces[m], m));
  for (const std::string& file : frame.bones) next.frame.bones.push_back(bone(file));
  next.frame.lengthUnit = scale_ == 0.001 ? "mm" : "m";
  // A still bone keeps its file from frame to frame; a moving one's earlier files go.
  std::erase_if(bones_, [&](const auto& entry) {
    return std::find(frame.bones.begin(), frame.bones.end(), entry.first) == frame.bones.end();
  });
  if (debug_.muscleFlags & (kDrawParticles | kDrawFibres))
    for (const std::string& file : frame.particles)
      drawParticles(readVtp((fs::path(dir_) / file).string(), scale_), next.debug);
  next.steps = index_;
  next.version = snapshot_.version + 1;
  snapshot_ = std::move(next);
  readMs_ = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
  shownAt_ = Clock::now();
  loaded_ = true;
}

Playback FramePlayer::controls(const Snapshot& shown) {
  const int last = int(frames_.size()) - 1;
  const Frame& frame = frames_[size_t(std::clamp(shown.steps, 0, last))];
  const double label = seriesAt(summary_, frame.time, "pose_label");
  const double solverStep = seriesAt(summary_, frame.time, "step");
  char where[96] = "";
  if (std::isfinite(solverStep)) std::snprintf(where, sizeof where, ", step %d", int(solverStep));
  if (std::isfinite(label))
    std::snprintf(where + std::strlen(where), sizeof where - std::strlen(where),
                  ", pose label %.4g", label);
  ImGui::Text("%s", dir_.c_str());
  ImGui::Text("frame %d (0 to %d), t = %.6g s%s", shown.steps, last, frame.time, where);
  playbackButtons(*this, loop);
  int index = index_;  // counted from 0, as the line above
  if (ImGui::SliderInt("frame", &index, 0, last)) show(index);
  return {shown.steps, index, std::isfinite(solverStep) ? int(solverStep) : -1};
}

void FramePlayer::timings(const Snapshot& shown) {
  ImGui::Text("frame %d read in %.3g ms", shown.steps, readMs_);
  if (!summary_.is_object() || !summary_.contains("timing")) return;
  const nlohmann::json& t = summary_["timing"];
  auto ms = [&](const char* key) { return t.value(key, double(NAN)); };
  partTimes("run, median ms per iteration:",
            {ms("mss"), ms("muscle_cd"), ms("bone_cd"), ms("response"), ms("output")});
}

}  // namespace fibremss::viewer
