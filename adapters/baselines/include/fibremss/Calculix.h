#pragma once
// The static hyperelastic reference's parts: conforming tetrahedral meshes of closed surfaces by
// Debian's tetgen, CalculiX input (.inp) for a Neo-Hookean body whose attached nodes follow
// prescribed displacements step by step, and CalculiX's printed results (.dat) read back.
// Both programs run as processes (ChildProcess); nothing of theirs is linked.
#include <LinearMath/btVector3.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <string>
#include <vector>

#include "fibremss/Geometry.h"
#include "fibremss/TetMesher.h"

namespace fibremss {

/// How tetgen meshes a surface: `tetgen -pYqQ` keeps the surface's vertices as the first nodes,
/// in order, and its triangles as the boundary (no Steiner point on it), so the surface
/// vertices are nodes of the mesh (no embedding error).
struct TetgenDefinition {
  btScalar radiusEdgeRatio = 2;  ///< -q bound on a tetrahedron's circumradius / shortest edge
  /// Mesh refinement level: each level splits every surface triangle into four (edge
  /// midpoints on the flat triangles: the same geometry, the original vertices still the first
  /// nodes) and bounds the tetrahedron volume (-a) by the mean of the level-0 mesh / 8^level.
  int refinement = 0;
  std::string program = "tetgen";  ///< the tetgen executable (PATH is searched)
};

/// Tetrahedralizes the closed surface with tetgen in `workDir` (files `<stem>.off`, `.1.node`,
/// `.1.ele` are left there). Nodes [0, surface.vertices.size()) are the surface's vertices.
/// Throws InputError with tetgen's message when it fails (e.g. self-intersecting facets).
TetMesh tetgenMesh(const TriangleMesh& surface, const TetgenDefinition& definition,
                   const std::string& workDir, const std::string& stem);

/// The surface with every triangle split into four at its edge midpoints, the original
/// vertices first (in order); `levels` times.
TriangleMesh subdivided(const TriangleMesh& surface, int levels);

/// Element types of the reference.
enum class CalculixElement : uint8_t {
  C3D4,   ///< linear tetrahedron (locks volumetrically as ν → 0.5)
  C3D10,  ///< quadratic tetrahedron (midside nodes on the straight edges)
};
const char* toString(CalculixElement element);

/// How CalculiX tracks a node-to-surface contact (its *CONTACT PAIR's SMALL SLIDING). Both pair
/// each slave node with a master face at the start of every increment (the face moves with its
/// body); they differ within an increment's Newton iterations.
enum class ContactSliding : uint8_t {
  Finite,  ///< ccx's default: paired anew in each of the first 8 iterations as well
  /// SMALL SLIDING: the pairs of the increment's start kept through its iterations: right where
  /// a node slides along the master surface by much less than a face within one increment
  Small,
};
const char* toString(ContactSliding sliding);

/// Compressible Neo-Hookean material as CalculiX writes it:
/// W = C10 (Ī1 − 3) + (J − 1)² / D1 with C10 = μ/2 = E / (4(1+ν)), D1 = 2/K = 6(1−2ν)/E.
struct NeoHookeMaterial {
  double youngsModulus = 200e3;  ///< E [Pa] (small-strain)
  double poissonRatio = 0.49;    ///< ν (0.5: incompressible)
  double c10() const { return youngsModulus / (4 * (1 + poissonRatio)); }   ///< [Pa]
  double d1() const { return 6 * (1 - 2 * poissonRatio) / youngsModulus; }  ///< [1/Pa]
};

/// Rigid obstacles of a job (the bones): linear tetrahedra whose every node is prescribed (so
/// they move rigidly with their bone), their boundary faces the master surface of a
/// frictionless node-to-surface penalty contact with the body's free surface nodes.
struct CalculixContact {
  std::vector<uint32_t> tetrahedra;  ///< 4 node indices (into CalculixJob::nodes) per element
  /// The master surface: per boundary face, its element (index into `tetrahedra` / 4) and
  /// CalculiX's face number of a C3D4 (1: nodes 1-2-3, 2: 1-4-2, 3: 2-4-3, 4: 3-4-1).
  std::vector<std::pair<uint32_t, uint8_t>> faces;
  /// Body nodes that may touch it: the free ones of surfaceNodes (C3D10's midside nodes too).
  std::vector<uint32_t> slaves;
  /// Linear pressure-overclosure slope K [Pa/m]; 0: none (no contact written).
  double stiffness = 0;
  double tension = 0;  ///< σ∞: the small tension at large clearance CalculiX asks for [Pa]
  ContactSliding sliding = ContactSliding::Finite;  ///< how the pairs are tracked
};

/// A node kept from moving along a direction: direction · u = 0 (*EQUATION).
struct CalculixEquation {
  uint32_t node = 0;             ///< 0-based
  btVector3 direction{0, 0, 0};  ///< unit vector
};

/// One CalculiX job: a body, its material and a sequence of static steps (NLGEOM), each giving
/// the displacement of every prescribed node from the rest position.
struct CalculixJob {
  std::string title;  ///< a comment line naming what it is
  CalculixElement element = CalculixElement::C3D4;
  std::vector<btVector3> nodes;        ///< rest positions [m] (midside nodes included)
  std::vector<uint32_t> connectivity;  ///< 4 or 10 node indices per element (0-based)
  NeoHookeMaterial material;
  std::vector<uint32_t> prescribed;           ///< nodes moved by the steps (0-based)
  std::vector<std::vector<btVector3>> steps;  ///< per step, per prescribed node: u [m]
  std::vector<uint32_t> printed;              ///< nodes whose displacements are printed
  double initialIncrement = 1;                ///< first increment, share of a step
  double minimumIncrement = 1e-4;             ///< smallest increment before ccx gives up
  /// Per step, its largest increment (share of the step; also bounds the first); empty: 1.
  std::vector<double> maximumIncrements;
  CalculixContact contact;                  ///< rigid obstacles (none when stiffness is 0)
  std::vector<CalculixEquation> equations;  ///< in every step (no node also prescribed)
};

/// The boundary faces of linear tetrahedra (4 node indices each) as CalculiX numbers them:
/// (element, face 1–4) for every face no other element shares.
std::vector<std::pair<uint32_t, uint8_t>> boundaryFaces(const std::vector<uint32_t>& tetrahedra);

/// A rigid obstacle's elements: nodes, C3D4 tetrahedra (4 indices into `nodes` each) and the
/// faces its contact's master surface is made of (element, CalculiX face number).
struct ObstacleMesh {
  std::vector<btVector3> nodes;                     ///< rest positions [m]
  std::vector<uint32_t> tetrahedra;                 ///< 4 node indices per element
  std::vector<std::pair<uint32_t, uint8_t>> faces;  ///< the master surface, facing out
};

/// A closed surface as a rigid obstacle without meshing its interior: its vertices first (in
/// order), then per triangle a tetrahedron with an apex of its own on the inner side (half the
/// triangle's longest edge from it along its inward normal), whose face 1 is the triangle
/// facing out. Every node of an obstacle is prescribed, so its elements carry nothing but the
/// master faces, and any surface works: one that intersects itself (which tetgen refuses) too.
ObstacleMesh obstacleMesh(const TriangleMesh& surface);

/// The body's nodes on its boundary, ascending: the surface vertices [0, surfaceVertices) and,
/// for C3D10, the midside nodes of its boundary faces. A contact's slaves must be all of them:
/// a midside node left out passes into the obstacle unresisted (a quadratic face between
/// corners that touch sags through it).
std::vector<uint32_t> surfaceNodes(const CalculixJob& job, size_t surfaceVertices);

/// Writes the job as CalculiX input (*NODE, *ELEMENT, *NSET, *HYPERELASTIC NEO HOOKE,
/// *EQUATION, one *STEP NLGEOM *STATIC per step with *BOUNDARY values and *NODE PRINT of U).
/// Node and element numbers are the indices + 1.
void writeCalculixInput(std::ostream& out, const CalculixJob& job);

/// The C3D10 mesh of a linear one: one node added at the midpoint of every edge, numbered after
/// the corners; connectivity in CalculiX's order (corners 1–4, then edges 1-2, 2-3, 3-1, 1-4,
/// 2-4, 3-4). Returns the nodes; `connectivity` receives 10 indices per tetrahedron.
std::vector<btVector3> quadraticTetrahedra(const TetMesh& mesh,
                                           std::vector<uint32_t>& connectivity);

/// One table CalculiX prints to its .dat file: "<quantity> (<components>) for set <SET> and
/// time <T>" followed by rows (a node number and its values, or the values alone for totals).
struct CalculixTable {
  std::string quantity;        ///< e.g. "displacements", "total force"
  std::string set;             ///< the node set, as ccx prints it (upper case)
  double time = 0;             ///< total time at the end of the increment
  std::vector<int> ids;        ///< node numbers (1-based), empty for totals
  std::vector<double> values;  ///< row after row, `components` each
  int components = 0;          ///< values per row
};

/// Reads every table of a .dat file. Throws InputError naming `source` and the line for a row
/// that is not numbers.
std::vector<CalculixTable> readCalculixDat(std::istream& in, const std::string& source);

/// Per step (steps of period 1, so step k ends at total time k), the table of `quantity` and
/// `set` printed at its end; stops at the first step that has none (ccx did not finish it).
std::vector<const CalculixTable*> stepEndTables(const std::vector<CalculixTable>& tables,
                                                const std::string& quantity, const std::string& set,
                                                int steps);

/// Runs `argv` (argv[0] searched on PATH) in `workDir` with stdout and stderr to `logPath`.
/// `poll` is called about every 0.2 s while it runs; returning false kills the process.
/// `memoryLimit` [bytes] bounds its address space (setrlimit RLIMIT_AS; 0: no bound), so that a
/// runaway solve fails its allocation instead of taking the machine's memory. Returns its exit
/// status (128 + signal when killed). Throws std::runtime_error when it cannot be started.
int runProgram(const std::vector<std::string>& argv, const std::string& workDir,
               const std::string& logPath, const std::function<bool()>& poll = {},
               uint64_t memoryLimit = 0);

/// The default memory limit of a ccx run [GiB]: 8, or half the machine's memory if that is
/// less (a 24 GiB machine shared with other work keeps two thirds of it).
double defaultCalculixMemoryGiB();

/// "ccx <version>" as `ccx -v` prints it (cached per process); "ccx (unknown version)" when it
/// prints none. Throws std::runtime_error when the program cannot be run.
std::string calculixVersion(const std::string& program = "ccx");

}  // namespace fibremss
