// The projective integrator (docs/integrators.md): projective dynamics' local/global iteration
// for springs (Liu et al. 2013) as a solver for the pose's equilibrium, without inertia. Its
// global step L·x⁺ = J·d is, with the spring forces F(x) = J·d − L·x, the step x⁺ = x + L⁻¹·F(x):
// a fixed-point iteration preconditioned by the matrix A + W over the free particles. L = Σ
// k·(e_a − e_b)(e_a − e_b)ᵀ is the springs' Laplacian (a spring to a fixed particle adds k to its
// free end's diagonal: fixed particles are Dirichlet, and F already holds their pull); A = L + c·V,
// V the same kind of matrix for the volume terms: each tetrahedron's stiffness at rest,
// K/V0·∂V/∂x_i·∂V/∂x_jᵀ·G0/G, with the outer product replaced by the dot product (its trace),
// weighted by c = kVolumeWeight. W holds the contacts: projective dynamics' constraint x_i = p_i
// with weight projectiveContactWeight·A_ii on each particle a contact pushed (lately), its target
// p_i the pushed position itself (the response moved the particle there before the forces), so W
// adds to the diagonal only and the right-hand side stays F. A particle in W is held nearly in
// place by the global step while the rest of the muscle answers around it; without W the step moves
// a pushed particle back where the springs alone want it, into the bone or the other muscle, every
// iteration. With persistent contacts (SimulationParameters::persistentContacts) a particle the
// last response pushed also gives up the part of its force into the push
// (what the contact holds, contactNormal: the force residual's rule) before the solve, while the
// response leaves every contact a slop deep (kContactSlop) so that it is found again: the step's
// fixed point is then the equilibrium with contacts, where the residual is 0 (the force a pushed
// particle kept would otherwise be spread over its neighbours by (A + W)⁻¹ and moved back by the
// next push, every iteration). A + W acts alike on x, y and z, so one sparse Cholesky factor (AMD
// ordering, computed in double, kept in btScalar: it only preconditions, the forces alone set the
// fixed point) serves all three; the ordering and pattern are found once per muscle, the values
// again whenever W changes (same pattern: only the diagonal changes), and then only in the rows of
// L a changed diagonal reaches: its own and those above it in the elimination tree.
#include <Eigen/OrderingMethods>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "IntegratorsInternal.h"
#include "collision/CollisionPairs.h"
#include "fibremss/Error.h"
#include "solver/ParticleSimd.h"
#include "solver/Residual.h"
#include "solver/VolumeForces.h"

namespace fibremss {
namespace {

using Matrix = Eigen::SparseMatrix<double>;
using Factor = Eigen::SimplicialLLT<Matrix, Eigen::Lower, Eigen::AMDOrdering<int>>;

/// c, the weight of the volume terms' stand-in in A [1]. Measured on fusiform at 10 iterations
/// per pose (docs/performance.md, "Projective solver"): 1.5, 2 and 3 ended 0.108, 0.136 and 0.334
/// mm from the equilibrium; 1 let the volume terms overshoot (+59 % volume).
constexpr double kVolumeWeight = 1.5;

/// A particle leaves W after this many iterations without a push [iterations]. Measured on
/// thigh13 at resolution 20, 10 iterations per pose: a hold of 1 000 refactors in 156 of 1 690
/// muscle-iterations, a hold of 10 in 634, at the same distance to Verlet's equilibrium run.
constexpr uint16_t kContactHold = 1000;
/// What a rank-one update costs per entry of L it visits, in entries a new factor visits [1]
/// (the inner loops as compiled for x86-64 with SSE2: 15 instructions per entry against 10).
constexpr double kUpdateCost = 1.5;

/// The numeric Cholesky factorisation of P·(A + W)·Pᵀ on the pattern Eigen's analysis found
/// (up-looking, as Eigen's SimplicialLLT and CSparse's cs_chol do it): row k of L from column k
/// of the upper triangle, its pattern found by walking the elimination tree. Buffers sized once.
struct NumericCholesky {
  std::vector<int> upperStart;  ///< P·A·Pᵀ's upper triangle by columns: [start[k], start[k+1])
  std::vector<int> upperRows;   ///< row of each entry
  std::vector<double> upperValues;  ///< value of each entry, without W [N/m]
  std::vector<int> diagonalEntry;   ///< index of column k's diagonal in upperValues
  std::vector<int> parent;          ///< elimination tree: first row below L's diagonal, −1: root
  std::vector<double> lower;        ///< L's entries as L's pattern orders them [√(N/m)]
  std::vector<double> scatter;      ///< row k of L being formed (zero between rows)
  std::vector<int> tags;            ///< the row that last visited each column
  std::vector<int> pattern;         ///< stack of the columns of row k, in topological order
  /// 1 for a row of L to recompute: a row whose W changed and every row above it in the
  /// elimination tree (L's other rows and columns do not depend on it), else 0.
  std::vector<uint8_t> stale;
  std::vector<long> rowWork;      ///< per row: the entries its refactorisation visits [1]
  std::vector<int> changedRows;   ///< rows whose W changed since the factor was last brought up
  std::vector<double> changedBy;  ///< and by how much [N/m]
};

/// The factor L of P·(A + W)·Pᵀ as the solve reads it, the contact weights and the solve's buffer.
/// A rollback of the guard keeps W: it shapes the iteration's path, not its fixed point.
struct ProjectiveWorkspace final : IntegratorWorkspace {
  std::vector<int> columnStart;     ///< L by columns: entries [columnStart[j], columnStart[j+1])
  std::vector<int> rows;            ///< row of each entry (a column's first: its diagonal)
  std::vector<btScalar> values;     ///< L's entries, the diagonal inverted [√(N/m), its inverse]
  std::vector<int> order;           ///< free particle k → its row P·k in the factor
  std::vector<btVector3> solution;  ///< per row: the forces [N], then the step A⁻¹·F [m]
  std::vector<double>
      weights;  ///< W per row: projectiveContactWeight·A_kk while held, else 0 [N/m]
  std::vector<uint16_t> idle;  ///< per row: iterations since its particle's last push
  NumericCholesky numeric;     ///< what a new factor of A + W needs
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
/// its inverted diagonal, then the rows below it). With SSE each entry is one vector product and
/// difference over x, y, z (and w, which stays 0), and the backward pass sums a column's odd and
/// even entries apart (two chains of dependent subtractions instead of one: CPU samples on
/// thigh13 R=40, 358 -> 283 in the integrator).
void solveInPlace(const ProjectiveWorkspace& w, btVector3* x) {
  const int* start = w.columnStart.data();
  const int* rows = w.rows.data();
  const btScalar* values = w.values.data();
  const auto n = static_cast<int>(w.columnStart.size()) - 1;
#if FIBREMSS_SSE_PARTICLES
  for (int j = 0; j < n; ++j) {
    const __m128 xj = _mm_mul_ps(loadVector(x[j]), _mm_set1_ps(values[start[j]]));
    _mm_store_ps(x[j].m_floats, xj);
    for (int p = start[j] + 1, end = start[j + 1]; p < end; ++p) {
      float* target = x[rows[p]].m_floats;
      _mm_store_ps(target, _mm_sub_ps(_mm_load_ps(target), _mm_mul_ps(xj, _mm_set1_ps(values[p]))));
    }
  }
  const auto term = [&](int p) {  // L(row, j)·z(row) for entry p of column j
    return _mm_mul_ps(loadVector(x[rows[p]]), _mm_set1_ps(values[p]));
  };
  for (int j = n - 1; j >= 0; --j) {
    __m128 sum = loadVector(x[j]), odd = _mm_setzero_ps();
    const int end = start[j + 1];
    int p = start[j] + 1;
    for (; p + 1 < end; p += 2) {
      sum = _mm_sub_ps(sum, term(p));
      odd = _mm_sub_ps(odd, term(p + 1));
    }
    if (p < end) sum = _mm_sub_ps(sum, term(p));
    _mm_store_ps(x[j].m_floats, _mm_mul_ps(_mm_add_ps(sum, odd), _mm_set1_ps(values[start[j]])));
  }
#else
  for (int j = 0; j < n; ++j) {
    const btVector3 xj = x[j] *= values[start[j]];
    for (int p = start[j] + 1; p < start[j + 1]; ++p) x[rows[p]] -= xj * values[p];
  }
  for (int j = n - 1; j >= 0; --j) {
    btVector3 sum = x[j];
    for (int p = start[j] + 1; p < start[j + 1]; ++p) sum -= x[rows[p]] * values[p];
    x[j] = sum * values[start[j]];
  }
#endif
}

/// w.numeric for the factor's ordering and pattern (w.columnStart, w.rows): P·A·Pᵀ's upper
/// triangle, the elimination tree read off L's pattern, the buffers.
void prepareNumeric(const Matrix& lowerA, const Factor& factor, ProjectiveWorkspace& w) {
  NumericCholesky& c = w.numeric;
  Matrix upper(lowerA.rows(), lowerA.cols());
  upper.selfadjointView<Eigen::Upper>() =
      lowerA.selfadjointView<Eigen::Lower>().twistedBy(factor.permutationP());
  upper.makeCompressed();
  const auto n = static_cast<int>(upper.cols());
  c.upperStart.assign(upper.outerIndexPtr(), upper.outerIndexPtr() + n + 1);
  c.upperRows.assign(upper.innerIndexPtr(), upper.innerIndexPtr() + upper.nonZeros());
  c.upperValues.assign(upper.valuePtr(), upper.valuePtr() + upper.nonZeros());
  c.diagonalEntry.assign(n, -1);
  c.parent.assign(n, -1);
  for (int k = 0; k < n; ++k) {
    for (int p = c.upperStart[k]; p < c.upperStart[k + 1]; ++p)
      if (c.upperRows[p] == k) c.diagonalEntry[k] = p;
    if (w.columnStart[k + 1] > w.columnStart[k] + 1) c.parent[k] = w.rows[w.columnStart[k] + 1];
  }
  c.lower.assign(w.rows.size(), 0);
  c.scatter.assign(n, 0);
  c.tags.assign(n, -1);
  c.pattern.assign(n, 0);
  c.stale.assign(n, 1);
  c.rowWork.assign(n, 0);
  c.changedRows.reserve(n);
  c.changedBy.reserve(n);
}

/// Pushes column k of the upper triangle onto c.pattern (from `top` down): the columns i < k
/// whose L(k, i) is non-zero, each path up the elimination tree in topological order; scatters
/// the column's values. Returns the new top.
int rowPattern(NumericCholesky& c, int k, int top) {
  for (int p = c.upperStart[k]; p < c.upperStart[k + 1]; ++p) {
    int i = c.upperRows[p];
    c.scatter[i] += c.upperValues[p];
    int length = 0;
    for (; c.tags[i] != k; i = c.parent[i]) {
      c.pattern[length++] = i;
      c.tags[i] = k;
    }
    while (length > 0) c.pattern[--top] = c.pattern[--length];
  }
  return top;
}

/// Marks `row` and its ancestors in the elimination tree stale (a diagonal change there reaches
/// only them).
void markStale(NumericCholesky& c, int row) {
  for (int i = row; i >= 0 && !c.stale[i]; i = c.parent[i]) c.stale[i] = 1;
}

/// Row k of L of P·(A + W)·Pᵀ into w.numeric.lower: a sparse triangular solve against the rows
/// above (each L(k, i) in column i found by its row, as a column's rows ascend). Records the
/// entries it visited in rowWork[k].
void factorRow(ProjectiveWorkspace& w, int k) {
  NumericCholesky& c = w.numeric;
  const int* start = w.columnStart.data();
  const int* rows = w.rows.data();
  const auto n = static_cast<int>(w.weights.size());
  c.tags[k] = k;
  int top = rowPattern(c, k, n);
  double diagonal = c.scatter[k] + w.weights[k];
  c.scatter[k] = 0;
  long work = 0;
  for (; top < n; ++top) {
    const int i = c.pattern[top];
    const double entry = c.scatter[i] / c.lower[start[i]];
    c.scatter[i] = 0;
    const auto end =
        static_cast<int>(std::lower_bound(rows + start[i] + 1, rows + start[i + 1], k) - rows);
    for (int p = start[i] + 1; p < end; ++p) c.scatter[rows[p]] -= c.lower[p] * entry;
    work += end - start[i];
    diagonal -= entry * entry;
    c.lower[end] = entry;
  }
  c.lower[start[k]] = std::sqrt(diagonal);
  c.rowWork[k] = work;
}

/// w.values from w.numeric.lower in the stale columns (btScalar, each column's diagonal inverted);
/// clears the marks.
void storeStale(ProjectiveWorkspace& w) {
  NumericCholesky& c = w.numeric;
  const double* lower = c.lower.data();
  for (size_t j = 0; j < c.stale.size(); ++j) {
    if (!c.stale[j]) continue;
    c.stale[j] = 0;
    for (int p = w.columnStart[j]; p < w.columnStart[j + 1]; ++p)
      w.values[p] = static_cast<btScalar>(p == w.columnStart[j] ? 1 / lower[p] : lower[p]);
  }
  c.changedRows.clear();
  c.changedBy.clear();
}

/// Recomputes L's stale rows from A + W (the other rows and columns keep their values) and stores
/// them. A + W is positive definite (A is, W ≥ 0).
void refactor(ProjectiveWorkspace& w) {
  NumericCholesky& c = w.numeric;
  std::fill(c.tags.begin(), c.tags.end(), -1);
  for (size_t k = 0; k < c.stale.size(); ++k)
    if (c.stale[k]) factorRow(w, static_cast<int>(k));
  storeStale(w);
}

/// L·Lᵀ + δ·e_s·e_sᵀ in place (δ [N/m] the change of row s's weight): the rank-one update
/// (δ > 0) or downdate of the Cholesky factor by rotations, column by column up s's path in the
/// elimination tree (the only columns it changes). Returns false if a downdate met a pivot that
/// is not positive (rounding; then L is part-updated and the caller refactors).
bool rankOneUpdate(ProjectiveWorkspace& w, int s, double delta) {
  NumericCholesky& c = w.numeric;
  double* x = c.scatter.data();  // zero outside the path walked
  double* lower = c.lower.data();
  const int* start = w.columnStart.data();
  const int* rows = w.rows.data();
  const double sign = delta > 0 ? 1 : -1;
  x[s] = std::sqrt(std::abs(delta));
  bool definite = true;
  for (int k = s; k >= 0; k = c.parent[k]) {
    const double xk = std::exchange(x[k], 0);
    const double pivot = lower[start[k]];
    const double squared = pivot * pivot + sign * xk * xk;
    definite = definite && squared > 0;
    if (!definite) continue;  // walks on to clear x
    const double diagonal = std::sqrt(squared);
    const double cosine = diagonal / pivot, sine = xk / pivot, inverse = pivot / diagonal;
    lower[start[k]] = diagonal;
    for (int p = start[k] + 1; p < start[k + 1]; ++p) {
      double& xi = x[rows[p]];
      const double l = (lower[p] + sign * sine * xi) * inverse;
      xi = cosine * xi - sine * l;
      lower[p] = l;
    }
  }
  return definite;
}

/// The factor of P·(A + W)·Pᵀ after W changed in c.changedRows: a rank-one update per changed row
/// where their paths up the tree visit fewer entries than a new factor of the stale rows would
/// (kUpdateCost each), else the new factor.
void updateFactor(ProjectiveWorkspace& w) {
  NumericCholesky& c = w.numeric;
  long refactorWork = 0, updateWork = 0;
  for (size_t k = 0; k < c.stale.size(); ++k)
    if (c.stale[k]) refactorWork += c.rowWork[k];
  for (int s : c.changedRows)
    for (int k = s; k >= 0; k = c.parent[k]) updateWork += w.columnStart[k + 1] - w.columnStart[k];
  bool updated = kUpdateCost * static_cast<double>(updateWork) < static_cast<double>(refactorWork);
  for (size_t r = 0; updated && r < c.changedRows.size(); ++r)
    updated = rankOneUpdate(w, c.changedRows[r], c.changedBy[r]);
  if (updated)
    storeStale(w);
  else
    refactor(w);
}

/// Puts the particles the last response pushed into W (with `weight` times their diagonal entry,
/// SimulationParameters::projectiveContactWeight) and takes out those kContactHold iterations
/// without a push (clearing the flags it reads). Returns whether W changed.
bool holdContacts(MuscleState& muscle, ProjectiveWorkspace& w, double contactWeight) {
  bool changed = false;
  NumericCholesky& c = w.numeric;
  for (size_t k = 0; k < muscle.freeParticles.size(); ++k) {
    const auto row = static_cast<size_t>(w.order[k]);
    uint8_t& pushed = muscle.pushedLast[muscle.freeParticles[k]];
    double& weight = w.weights[row];
    if (pushed) {
      pushed = 0;
      w.idle[row] = 0;
      if (weight > 0) continue;
      weight = contactWeight * c.upperValues[c.diagonalEntry[row]];
      c.changedBy.push_back(weight);
    } else if (weight > 0 && ++w.idle[row] > kContactHold) {
      c.changedBy.push_back(-weight);
      weight = 0;
    } else {
      continue;
    }
    c.changedRows.push_back(static_cast<int>(row));
    markStale(c, static_cast<int>(row));
    changed = true;
  }
  return changed;
}

/// x⁺ = x + ω·(A + W)⁻¹·F(x) + (ω − 1)·(x − x⁻): the projective step over-relaxed with momentum.
class ProjectiveIntegrator final : public TimeIntegrator {
 public:
  IntegrationResult advance(MuscleState& muscle, const SimulationParameters& parameters, btScalar,
                            btScalar) const override {
    auto& w = static_cast<ProjectiveWorkspace&>(*muscle.workspace);
    if (holdContacts(muscle, w, parameters.projectiveContactWeight)) updateFactor(w);
    const std::vector<uint32_t>& free = muscle.freeParticles;
    const bool held = holdsContacts(parameters);
    for (size_t k = 0; k < free.size(); ++k) {
      const btVector3& force = muscle.forces[free[k]];
      w.solution[w.order[k]] = held ? withoutInto(force, contactNormal(muscle, free[k])) : force;
    }
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
  bool holdsContacts(const SimulationParameters& parameters) const override {
    return parameters.persistentContacts;
  }
  Integrator kind() const override { return Integrator::Projective; }

 protected:
  std::unique_ptr<IntegratorWorkspace> makeWorkspace(const MuscleState& muscle) const override {
    const Matrix matrix = assemble(*muscle.settings, muscle.freeParticles);
    const Factor factor(matrix);
    if (factor.info() != Eigen::Success)
      throw InputError("integrator", "projective",
                       "the muscle's spring matrix is not positive definite");
    auto w = std::make_unique<ProjectiveWorkspace>();
    const Matrix& lower = factor.matrixL().nestedExpression();
    w->columnStart.assign(lower.outerIndexPtr(), lower.outerIndexPtr() + lower.cols() + 1);
    w->rows.assign(lower.innerIndexPtr(), lower.innerIndexPtr() + lower.nonZeros());
    w->values.resize(static_cast<size_t>(lower.nonZeros()));
    const auto& permutation = factor.permutationP().indices();
    w->order.assign(permutation.data(), permutation.data() + permutation.size());
    const size_t n = muscle.freeParticles.size();
    w->solution.assign(n, btVector3(0, 0, 0));
    w->weights.assign(n, 0);
    w->idle.assign(n, 0);
    prepareNumeric(matrix, factor, *w);
    refactor(*w);
    return w;
  }
};

}  // namespace

const TimeIntegrator* projectiveIntegratorFor(Integrator kind) {
  static const ProjectiveIntegrator projective;
  return kind == Integrator::Projective ? &projective : nullptr;
}

}  // namespace fibremss
