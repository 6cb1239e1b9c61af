#include "FrameWriter.h"

#include <array>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <variant>

#include "fibremss/Geometry.h"
#include "fibremss/Gltf.h"

namespace fibremss {

std::string fileSafe(const std::string& name) {
  std::string safe = name.empty() ? "unnamed" : name;
  for (char& c : safe)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') c = '_';
  return safe;
}

namespace {

/// Per surface vertex, the skin-weighted average of a per-particle value (method.md §7).
std::vector<float> onSurface(const MuscleSettings& muscle, std::span<const float> particleValues) {
  const size_t vertices = muscle.restSurface.vertices.size();
  const auto neighbours = size_t(muscle.skinNeighbours);
  std::vector<float> values(vertices, 0.0f);
  if (muscle.skinParticles.size() != vertices * neighbours) return values;
  for (size_t v = 0; v < vertices; ++v) {
    double sum = 0;
    for (size_t k = v * neighbours; k < (v + 1) * neighbours; ++k)
      sum += double(muscle.skinWeights[k]) * particleValues[muscle.skinParticles[k]];
    values[v] = float(sum);
  }
  return values;
}

/// `current − rest` per point, in scene units, as a three-component array.
DataArray displacement(std::span<const btVector3> current, std::span<const btVector3> rest,
                       btScalar scale) {
  std::vector<float> values(3 * current.size());
  for (size_t i = 0; i < current.size(); ++i)
    for (int k = 0; k < 3; ++k) values[3 * i + k] = float((current[i][k] - rest[i][k]) * scale);
  return {"displacement", 3, std::move(values)};
}

DataArray constant(const std::string& name, size_t count, int32_t value) {
  return {name, 1, std::vector<int32_t>(count, value)};
}

}  // namespace

void particleFibreStretch(const MuscleSettings& muscle, std::span<const btVector3> positions,
                          std::vector<float>& stretch) {
  const size_t n = muscle.particleCount();
  std::vector<double> current(n, 0.0), rest(n, 0.0);
  for (size_t f = 0; f < muscle.fibreCount(); ++f)
    for (uint32_t k = muscle.fibreOffsets[f] + 1; k < muscle.fibreOffsets[f + 1]; ++k) {
      const uint32_t a = muscle.fibreParticles[k - 1], b = muscle.fibreParticles[k];
      const double length = positions[a].distance(positions[b]);
      const double restLength = muscle.restPositions[a].distance(muscle.restPositions[b]);
      current[a] += length;
      current[b] += length;
      rest[a] += restLength;
      rest[b] += restLength;
    }
  stretch.resize(n);
  for (size_t i = 0; i < n; ++i) stretch[i] = rest[i] > 0 ? float(current[i] / rest[i]) : 1.0f;
}

void particleSpringStrain(const MuscleSettings& muscle, std::span<const btVector3> positions,
                          std::vector<float>& strain) {
  const size_t n = muscle.particleCount();
  std::vector<double> change(n, 0.0), rest(n, 0.0);
  for (const Spring& spring : muscle.springs) {
    const double delta = positions[spring.a].distance(positions[spring.b]) - spring.restLength;
    change[spring.a] += delta;
    change[spring.b] += delta;
    rest[spring.a] += spring.restLength;
    rest[spring.b] += spring.restLength;
  }
  strain.resize(n);
  for (size_t i = 0; i < n; ++i) strain[i] = rest[i] > 0 ? float(change[i] / rest[i]) : 0.0f;
}

FrameWriter::FrameWriter(const std::string& outDir, const OutputSettings& settings,
                         double unitScale, FrameFormats formats)
    : outDir_(outDir),
      settings_(settings),
      formats_(formats),
      sceneUnitsPerMetre_(btScalar(1.0 / unitScale)),
      lengthStep_(powerOfTwoStep(settings.quantiseMm / 1000 / unitScale)),
      strainStep_(powerOfTwoStep(settings.quantiseStrain)) {}

void FrameWriter::extractImplicit(const MuscleSystem& system, std::span<const MuscleHandle> muscles,
                                  const PreparedScene& prepared) {
  if (implicit_.empty()) {
    for (size_t m = 0; m < muscles.size(); ++m) implicit_.emplace_back(prepared.muscles[m]);
    pool_ = std::make_unique<TaskPool>(system.threads(), system.definition().scheduler);
  }
  const auto start = std::chrono::steady_clock::now();
  std::vector<ImplicitSurface*> surfaces;
  std::vector<std::span<const btVector3>> positions;
  std::vector<std::span<const Spring>> springs;
  for (size_t m = 0; m < muscles.size(); ++m) {
    surfaces.push_back(&implicit_[m]);
    positions.push_back(system.positions(muscles[m]));
    springs.push_back(system.settings(muscles[m]).springs);
  }
  extractSurfaces(surfaces, positions, springs, *pool_);
  implicitMs_.push_back(
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
}

TriangleMesh FrameWriter::frameSurface(size_t m, const MuscleSystem& system,
                                       MuscleHandle handle) const {
  if (!implicit_.empty()) return implicit_[m].mesh();
  const std::span<const btVector3> vertices = system.surface(handle);
  return {{vertices.begin(), vertices.end()}, system.settings(handle).restSurface.triangles};
}

std::vector<DataArray> FrameWriter::implicitArrays(size_t m, const MuscleSystem& system,
                                                   MuscleHandle handle,
                                                   std::span<const float> fixed) const {
  const std::vector<uint32_t> nearest = implicit_[m].nearestParticles();
  auto carried = [&](std::span<const float> values) {
    std::vector<float> out(nearest.size());
    for (size_t v = 0; v < nearest.size(); ++v) out[v] = values[nearest[v]];
    return out;
  };
  const std::span<const btVector3> positions = system.positions(handle);
  const std::span<const btVector3> rest = system.settings(handle).restPositions;
  std::vector<btVector3> current(nearest.size()), atRest(nearest.size());
  for (size_t v = 0; v < nearest.size(); ++v) {
    current[v] = positions[nearest[v]];
    atRest[v] = rest[nearest[v]];
  }
  return {{"fibre_stretch", 1, carried(stretch_)},
          {"spring_strain", 1, carried(strain_)},
          displacement(current, atRest, sceneUnitsPerMetre_),
          constant("muscle_id", nearest.size(), int32_t(m)),
          {"fixed", 1, carried(fixed)}};
}

void FrameWriter::write(const FrameInfo& info, const MuscleSystem& system,
                        std::span<const MuscleHandle> muscles, const PreparedScene& prepared,
                        std::span<const btTransform> boneTransforms,
                        std::span<const std::vector<float>> surfaceDepthsMm) {
  if (settings_.implicitSurface && settings_.writeSurfaces)
    extractImplicit(system, muscles, prepared);
  if (formats_.vtk) {
    int part = 0;
    for (size_t m = 0; m < muscles.size(); ++m)
      writeMuscle(info, m, system, muscles[m], surfaceDepthsMm[m], part);
    writeBones(info, prepared, boneTransforms, part);
    pvd_.write(outDir_ + "/run.pvd");
  }
  if (formats_.gltf) writeGltf(info, system, muscles, prepared, boneTransforms);
  ++frames_;
}

void FrameWriter::writeGltf(const FrameInfo& info, const MuscleSystem& system,
                            std::span<const MuscleHandle> muscles, const PreparedScene& prepared,
                            std::span<const btTransform> boneTransforms) {
  constexpr std::array<float, 4> kMuscle{0.75f, 0.25f, 0.22f, 1}, kBone{0.86f, 0.84f, 0.76f, 1};
  std::vector<GltfMesh> meshes;
  std::vector<TriangleMesh> surfaces;  // the meshes' muscle surfaces
  surfaces.reserve(muscles.size());
  for (size_t m = 0; m < muscles.size(); ++m) {
    const MuscleSettings& muscle = system.settings(muscles[m]);
    if (muscle.restSurface.empty()) continue;
    surfaces.push_back(frameSurface(m, system, muscles[m]));
    meshes.push_back({"muscle" + std::to_string(m) + "_" + fileSafe(muscle.name),
                      surfaces.back().vertices, surfaces.back().triangles, kMuscle});
  }
  std::vector<TriangleMesh> bones;  // placed where they are
  for (size_t b = 0; b < prepared.bones.size(); ++b)
    bones.push_back(transformed(prepared.bones[b]->mesh, boneTransforms[b]));
  for (size_t b = 0; b < bones.size(); ++b)
    meshes.push_back({"bone" + std::to_string(b) + "_" + fileSafe(prepared.bones[b]->name),
                      bones[b].vertices, bones[b].triangles, kBone});
  char name[32];
  std::snprintf(name, sizeof name, "/gltf/frame_%05d.glb", info.step);
  writeGlb(outDir_ + name, meshes);
  if (implicit_.empty()) animation_.addFrame(info.time, meshes);
}

void FrameWriter::finish() const {
  if (animation_.frames() > 0) animation_.write(outDir_ + "/gltf/run.glb");
}

void FrameWriter::writeMuscle(const FrameInfo& info, size_t m, const MuscleSystem& system,
                              MuscleHandle handle, std::span<const float> depthsMm, int& part) {
  const MuscleSettings& muscle = system.settings(handle);
  std::span<const btVector3> positions = system.positions(handle);
  particleFibreStretch(muscle, positions, stretch_);
  particleSpringStrain(muscle, positions, strain_);
  std::vector<float> fixed(muscle.particleCount());
  for (uint32_t i = 0; i < muscle.particleCount(); ++i) fixed[i] = muscle.isFixed(i) ? 1.0f : 0.0f;
  char number[16];
  std::snprintf(number, sizeof number, "%05d", info.step);
  const std::string stem = "frames/muscle" + std::to_string(m) + "_" + fileSafe(muscle.name);
  const auto id = int32_t(m);

  if (settings_.writeSurfaces && !muscle.restSurface.empty()) {
    TriangleMesh mesh = frameSurface(m, system, handle);
    PolyData surface;
    surface.points = std::move(mesh.vertices);
    surface.pointScale = sceneUnitsPerMetre_;
    surface.triangles = std::move(mesh.triangles);
    if (implicit_.empty()) {
      std::vector<float> penetration(depthsMm.begin(), depthsMm.end());
      for (float& depth : penetration) depth *= float(sceneUnitsPerMetre_ / 1000);
      surface.pointData = {
          {"fibre_stretch", 1, onSurface(muscle, stretch_)},
          {"spring_strain", 1, onSurface(muscle, strain_)},
          displacement(surface.points, muscle.restSurface.vertices, sceneUnitsPerMetre_),
          constant("muscle_id", surface.points.size(), id),
          {"penetration", 1, std::move(penetration)},
          {"fixed", 1, onSurface(muscle, fixed)}};
    } else {
      surface.pointData = implicitArrays(m, system, handle, fixed);
    }
    surface.fieldData = frameFields(info);
    add(info.time, stem + "_surface_" + number + ".vtp", surface, part, muscle.name + " surface");
  }
  ++part;
  if (settings_.writeParticles || settings_.writeFibres) {
    PolyData particles;
    particles.points.assign(positions.begin(), positions.end());
    particles.pointScale = sceneUnitsPerMetre_;
    particles.pointsAsVertices = settings_.writeParticles;
    if (settings_.writeFibres) {
      particles.lineIndices = muscle.fibreParticles;
      particles.lineOffsets = muscle.fibreOffsets;
    }
    std::vector<float> radius(muscle.particleCount()), boundary(muscle.particleCount());
    for (uint32_t i = 0; i < muscle.particleCount(); ++i) {
      radius[i] = float(muscle.radii[i] * sceneUnitsPerMetre_);
      boundary[i] = muscle.isBoundary(i) ? 1.0f : 0.0f;
    }
    particles.pointData = {{"fibre_stretch", 1, stretch_},
                           {"spring_strain", 1, strain_},
                           displacement(positions, muscle.restPositions, sceneUnitsPerMetre_),
                           constant("muscle_id", positions.size(), id),
                           {"fixed", 1, std::move(fixed)},
                           {"radius", 1, std::move(radius)},
                           {"boundary", 1, std::move(boundary)}};
    particles.fieldData = frameFields(info);
    add(info.time, stem + "_particles_" + number + ".vtp", particles, part,
        muscle.name + " particles");
  }
  ++part;
}

void FrameWriter::writeBones(const FrameInfo& info, const PreparedScene& prepared,
                             std::span<const btTransform> boneTransforms, int& part) {
  boneFiles_.resize(prepared.bones.size());
  boneWrittenAt_.resize(prepared.bones.size());
  char number[16];
  std::snprintf(number, sizeof number, "%05d", info.step);
  for (size_t b = 0; b < prepared.bones.size(); ++b, ++part) {
    const BoneSettings& bone = *prepared.bones[b];
    if (boneFiles_[b].empty() || !(boneWrittenAt_[b] == boneTransforms[b])) {
      PolyData mesh;
      mesh.points = transformed(bone.mesh, boneTransforms[b]).vertices;
      mesh.pointScale = sceneUnitsPerMetre_;
      mesh.triangles = bone.mesh.triangles;
      // Rest → current as a row-major 4×4 matrix in scene units.
      std::vector<double> matrix(16, 0.0);
      const btMatrix3x3& basis = boneTransforms[b].getBasis();
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) matrix[4 * r + c] = basis[r][c];
        matrix[4 * r + 3] = boneTransforms[b].getOrigin()[r] * sceneUnitsPerMetre_;
      }
      matrix[15] = 1;
      mesh.fieldData = {{"transform", 16, std::move(matrix)}};
      boneFiles_[b] =
          "frames/bone" + std::to_string(b) + "_" + fileSafe(bone.name) + "_" + number + ".vtp";
      boneWrittenAt_[b] = boneTransforms[b];
      quantise(mesh);
      writeVtp(outDir_ + "/" + boneFiles_[b], mesh);
    }
    pvd_.add(info.time, boneFiles_[b], part, bone.name);
  }
}

std::vector<DataArray> FrameWriter::frameFields(const FrameInfo& info) const {
  return {{"TimeValue", 1, std::vector<double>{info.time}},
          {"step", 1, std::vector<int32_t>{info.step}},
          {"pose", 1, std::vector<int32_t>{info.pose}},
          {"pose_label", 1, std::vector<double>{info.poseLabel}}};
}

void FrameWriter::quantise(PolyData& data) const {
  if (lengthStep_ == 0 && strainStep_ == 0) return;
  data.pointStep = lengthStep_;
  for (DataArray& array : data.pointData) {
    auto* values = std::get_if<std::vector<float>>(&array.values);
    const bool length =
        array.name == "displacement" || array.name == "penetration" || array.name == "radius";
    if (values) roundToStep(*values, length ? lengthStep_ : strainStep_);
  }
  data.fieldData.push_back({"quantisation_length_step", 1, std::vector<double>{lengthStep_}});
  data.fieldData.push_back({"quantisation_strain_step", 1, std::vector<double>{strainStep_}});
}

void FrameWriter::add(double time, const std::string& file, PolyData& data, int part,
                      const std::string& name) {
  quantise(data);
  writeVtp(outDir_ + "/" + file, data);
  pvd_.add(time, file, part, name);
}

}  // namespace fibremss
