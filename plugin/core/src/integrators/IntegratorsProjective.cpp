// The projective integrator (docs/integrators.md): projective dynamics' local/global iteration
// for springs (Liu et al. 2013) as a solver for the pose's equilibrium, without inertia. Its
// global step L·x⁺ = J·d is, with the spring forces F(x) = J·d − L·x, the step x⁺ = x + L⁻¹·F(x):
// a fixed-point iteration preconditioned by the constant matrix A = L + c·V over the free
// particles. L = Σ k·(e_a − e_b)(e_a − e_b)ᵀ is the springs' Laplacian (a spring to a fixed
// particle adds k to its free end's diagonal: fixed particles are Dirichlet, and F already holds
// their pull); V is the same kind of matrix for the volume terms: each tetrahedron's stiffness at
// rest, K/V0·∂V/∂x_i·∂V/∂x_jᵀ·G0/G, with the outer product replaced by the dot product (its
// trace), weighted by c = kVolumeWeight. A acts alike on x, y and z, so one sparse Cholesky
// factor (AMD ordering, computed in double, kept in btScalar: it only preconditions, the forces
// alone set the fixed point) serves all three; it is made once per muscle. Unlike a local
// iteration (Verlet needs O(diameter²) iterations for the whole-muscle modes) each step moves
// every particle by the whole muscle's response to the forces. Contacts stay projections after
// the step, which the global step undoes every iteration: see docs/integrators.md.
#include <Eigen/OrderingMethods>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <vector>

#include "IntegratorsInternal.h"
#include "fibremss/Error.h"
#include "solver/VolumeForces.h"

namespace fibremss {
namespace {

using Matrix = Eigen::SparseMatrix<double>;
using Factor = Eigen::SimplicialLLT<Matrix, Eigen::Lower, Eigen::AMDOrdering<int>>;

/// c, the weight of the volume terms' stand-in in A [1]. Measured on fusiform at 10 iterations
/// per pose (docs/performance.md, "Projective solver"): 1.5, 2 and 3 ended 0.108, 0.136 and 0.334
/// mm from the equilibrium; 1 let the volume terms overshoot (+59 % volume).
constexpr double kVolumeWeight = 1.5;

/// The Cholesky factor L of P·A·Pᵀ and the solve's buffer.
struct ProjectiveWorkspace final : IntegratorWorkspace {
  std::vector<int> columnStart;     ///< L by columns: entries [columnStart[j], columnStart[j+1])
  std::vector<int> rows;            ///< row of each entry (a column's first: its diagonal)
  std::vector<btScalar> values;     ///< L's entries, the diagonal inverted [√(N/m), its inverse]
  std::vector<int> order;           ///< free particle k → its row P·k in the factor
  std::vector<btVector3> solution;  ///< per row: the forces [N], then the step A⁻¹·F [m]
};

/// The scalar matrix A over the free particles (the 3n × 3n one is A ⊗ I₃) [N/m].
Matrix assemble(const MuscleSettings& settings, const std::vector<uint32_t>& free) {
  std::vector<int> rows(settings.particleCount(), -1);
  for (size_t k = 0; k < free.size(); ++k) rows[free[k]] = static_cast<int>(k);
  std::vector<Eigen::Triplet<double>> entries;
  const auto couple = [&](uint32_t a, uint32_t b, double weight) {
    const int ra = rows[a], rb = rows[b];
    if (ra >= 0) entries.emplace_back(ra, ra, weight);
    if (rb >= 0) entries.emplace_back(rb, rb, weight);
    if (ra >= 0 && rb >= 0) entries.emplace_back(std::max(ra, rb), std::min(ra, rb), -weight);
  };
  for (const Spring& spring : settings.springs) couple(spring.a, spring.b, spring.stiffness);
  const uint32_t* t = settings.tetParticles.data();
  for (size_t k = 0; k < settings.tetInverseVolume.size(); ++k, t += 4) {
    const RestGradients rest = restTetrahedronGradients(settings, k);
    double gradient = 0;
    for (const btVector3& g : rest.gradients) gradient += g.length2();
    // K/V0·(1/36)·G0/G with 1/V0 = 6·inverse.
    const double scale = kVolumeWeight * settings.volumeModulus * settings.tetInverseVolume[k] / 6 *
                         settings.tetRestGradient[k] / gradient;
    // a_i·a_j·scale = Σ over pairs −(a_i·a_j)·scale·(e_i − e_j)² as the rows sum to zero.
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j)
        couple(t[i], t[j], -scale * rest.gradients[i].dot(rest.gradients[j]));
  }
  double trace = 0;
  for (const auto& entry : entries)
    if (entry.row() == entry.col()) trace += entry.value();
  // A tiny shift keeps A definite for particles no spring ties to a fixed one.
  const double shift = 1e-9 * trace / static_cast<double>(std::max<size_t>(1, free.size()));
  for (size_t k = 0; k < free.size(); ++k)
    entries.emplace_back(static_cast<int>(k), static_cast<int>(k), shift);
  Matrix matrix(static_cast<Eigen::Index>(free.size()), static_cast<Eigen::Index>(free.size()));
  matrix.setFromTriplets(entries.begin(), entries.end());
  return matrix;
}

/// Solves L·Lᵀ·z = b in place for the three coordinates of `x` together (entries of a column:
/// its inverted diagonal, then the rows below it).
void solveInPlace(const ProjectiveWorkspace& w, btVector3* x) {
  const int* start = w.columnStart.data();
  const int* rows = w.rows.data();
  const btScalar* values = w.values.data();
  const auto n = static_cast<int>(w.columnStart.size()) - 1;
  for (int j = 0; j < n; ++j) {
    const btVector3 xj = x[j] *= values[start[j]];
    for (int p = start[j] + 1; p < start[j + 1]; ++p) x[rows[p]] -= xj * values[p];
  }
  for (int j = n - 1; j >= 0; --j) {
    btVector3 sum = x[j];
    for (int p = start[j] + 1; p < start[j + 1]; ++p) sum -= x[rows[p]] * values[p];
    x[j] = sum * values[start[j]];
  }
}

/// x⁺ = x + ω·A⁻¹·F(x) + (ω − 1)·(x − x⁻): the projective step over-relaxed with momentum.
class ProjectiveIntegrator final : public TimeIntegrator {
 public:
  IntegrationResult advance(MuscleState& muscle, const SimulationParameters& parameters, btScalar,
                            btScalar) const override {
    auto& w = static_cast<ProjectiveWorkspace&>(*muscle.workspace);
    const std::vector<uint32_t>& free = muscle.freeParticles;
    for (size_t k = 0; k < free.size(); ++k) w.solution[w.order[k]] = muscle.forces[free[k]];
    solveInPlace(w, w.solution.data());
    const double rho = parameters.projectiveRho;
    const auto omega = static_cast<btScalar>(2 / (1 + std::sqrt(1 - rho * rho)));
    IntegrationResult result;
    for (size_t k = 0; k < free.size(); ++k)
      result.displacement +=
          heavyBallStep(muscle, free[k], w.solution[w.order[k]], omega - 1, omega);
    result.finite = std::isfinite(result.displacement);
    return result;
  }
  bool usesVelocities() const override { return false; }
  Integrator kind() const override { return Integrator::Projective; }

 protected:
  std::unique_ptr<IntegratorWorkspace> makeWorkspace(const MuscleState& muscle) const override {
    const MuscleSettings& settings = *muscle.settings;
    const Factor factor(assemble(settings, muscle.freeParticles));
    if (factor.info() != Eigen::Success)
      throw InputError("integrator", "projective",
                       "the muscle's spring matrix is not positive definite");
    auto w = std::make_unique<ProjectiveWorkspace>();
    const Matrix& lower = factor.matrixL().nestedExpression();
    w->columnStart.assign(lower.outerIndexPtr(), lower.outerIndexPtr() + lower.cols() + 1);
    w->rows.assign(lower.innerIndexPtr(), lower.innerIndexPtr() + lower.nonZeros());
    w->values.resize(static_cast<size_t>(lower.nonZeros()));
    for (Eigen::Index j = 0; j < lower.cols(); ++j)
      for (int p = w->columnStart[j]; p < w->columnStart[j + 1]; ++p)
        w->values[p] = static_cast<btScalar>(p == w->columnStart[j] ? 1 / lower.valuePtr()[p]
                                                                    : lower.valuePtr()[p]);
    const auto& permutation = factor.permutationP().indices();
    w->order.assign(permutation.data(), permutation.data() + permutation.size());
    w->solution.assign(muscle.freeParticles.size(), btVector3(0, 0, 0));
    return w;
  }
};

}  // namespace

const TimeIntegrator* projectiveIntegratorFor(Integrator kind) {
  static const ProjectiveIntegrator projective;
  return kind == Integrator::Projective ? &projective : nullptr;
}

}  // namespace fibremss
