// Fibres as ASCII legacy VTK POLYDATA LINES (readable by loadFibres and ParaView).
#include <iomanip>
#include <sstream>

#include "fibremss/MeshIO.h"
#include "fibremss/Output.h"

namespace fibremss {

void saveFibresVtk(const std::string& path, const FibreSet& fibres, double scale) {
  std::ostringstream out;
  out << std::setprecision(9);
  out << "# vtk DataFile Version 3.0\n"
      << "FibreMSS fibres (" << fibres.fibreCount() << " polylines)\n"
      << "ASCII\nDATASET POLYDATA\n"
      << "POINTS " << fibres.points.size() << " double\n";
  const double inverse = scale != 0 ? 1.0 / scale : 1.0;
  for (const auto& p : fibres.points)
    out << double(p.x()) * inverse << ' ' << double(p.y()) * inverse << ' '
        << double(p.z()) * inverse << '\n';
  out << "LINES " << fibres.fibreCount() << ' ' << fibres.fibreCount() + fibres.points.size()
      << '\n';
  for (size_t f = 0; f < fibres.fibreCount(); ++f) {
    out << (fibres.offsets[f + 1] - fibres.offsets[f]);
    for (uint32_t i = fibres.offsets[f]; i < fibres.offsets[f + 1]; ++i) out << ' ' << i;
    out << '\n';
  }
  writeFileAtomically(path, out.str());
}

}  // namespace fibremss
