#include "fibremss/VtkFiles.h"

#include <cstdlib>
#include <regex>

#include "MeshIOInternal.h"
#include "fibremss/Error.h"

namespace fibremss {

const PointArray* PolyDataFile::array(const std::string& name) const {
  for (const PointArray& a : pointData)
    if (a.name == name) return &a;
  return nullptr;
}

PolyDataFile readVtp(const std::string& path, double scale) {
  meshio::requireScale(path, scale);
  const std::string bytes = meshio::readWholeFile(path);
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
  const std::string text = meshio::readWholeFile(path);
  if (text.find("<VTKFile") == std::string::npos ||
      text.find("type=\"Collection\"") == std::string::npos)
    throw InputError(path, "", "expected a ParaView collection (<VTKFile type=\"Collection\">)");
  std::vector<PvdDataSet> sets;
  const std::regex tag("<DataSet\\b[^>]*>");
  const std::regex attribute("(\\w+)=\"([^\"]*)\"");
  for (auto it = std::sregex_iterator(text.begin(), text.end(), tag); it != std::sregex_iterator();
       ++it) {
    const std::string element = it->str();
    const std::string where = "DataSet " + std::to_string(sets.size() + 1);
    PvdDataSet set;
    bool timed = false;
    for (auto a = std::sregex_iterator(element.begin(), element.end(), attribute);
         a != std::sregex_iterator(); ++a) {
      const std::string key = (*a)[1], value = (*a)[2];
      if (key == "file") set.file = value;
      if (key == "part") set.part = std::atoi(value.c_str());
      if (key == "timestep") timed = meshio::parseReal(value, set.time);
    }
    if (set.file.empty()) throw InputError(path, where, "expected a file=\"...\" attribute");
    if (!timed) throw InputError(path, where, "expected a number as timestep=\"...\"");
    sets.push_back(std::move(set));
  }
  return sets;
}

}  // namespace fibremss
