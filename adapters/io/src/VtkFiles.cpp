#include "fibremss/VtkFiles.h"

#include <cstdlib>

#include "MeshIOInternal.h"
#include "XmlTags.h"
#include "fibremss/Error.h"
#include "fibremss/InputFiles.h"

namespace fibremss {

const PointArray* PolyDataFile::array(const std::string& name) const {
  for (const PointArray& a : pointData)
    if (a.name == name) return &a;
  return nullptr;
}

PolyDataFile readVtp(const std::string& path, double scale) {
  meshio::requireScale(path, scale);
  const std::string bytes = readInputFile(path, "a mesh");
  if (!meshio::looksLikeVtkXml(bytes))
    throw InputError(path, "", "expected a VTK XML file (<?xml ... <VTKFile type=\"PolyData\">)");
  meshio::VtkPolyData data = meshio::readVtkXmlPolyData(path, bytes, scale);
  PolyDataFile file;
  file.points = std::move(data.points);
  file.triangles = std::move(data.triangles);
  file.lineIndices = std::move(data.lines.indices);
  file.lineOffsets = std::move(data.lines.offsets);
  file.pointData = std::move(data.pointData);
  return file;
}

std::vector<PvdDataSet> readPvd(const std::string& path) {
  const std::string text = readInputFile(path, "a ParaView collection (.pvd)", kMaxTextFileBytes);
  if (text.find("<VTKFile") == std::string::npos ||
      text.find("type=\"Collection\"") == std::string::npos)
    throw InputError(path, "", "expected a ParaView collection (<VTKFile type=\"Collection\">)");
  std::vector<PvdDataSet> sets;
  meshio::TagScanner tags(path, text);
  auto open = [&](const std::string& name, const meshio::Attributes& attributes, size_t start,
                  size_t, bool) {
    if (name != "DataSet") return;
    const std::string where = "line " + std::to_string(tags.lineAt(start)) + ", DataSet " +
                              std::to_string(sets.size() + 1);
    PvdDataSet set;
    set.file = attributes.get("file");
    set.part = std::atoi(attributes.get("part", "0").c_str());
    if (set.file.empty()) throw InputError(path, where, "expected a file=\"...\" attribute");
    if (!meshio::parseReal(attributes.get("timestep"), set.time))
      throw InputError(path, where, "expected a number as timestep=\"...\"");
    sets.push_back(std::move(set));
  };
  tags.scan(
      open, [](const std::string&, size_t) {}, false);
  return sets;
}

}  // namespace fibremss
