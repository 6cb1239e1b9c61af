// Implicit integrators (docs/integrators.md): backward Euler, the implicit midpoint rule and
// BDF2, each one Newton step on the spring forces linearized at x(t): the linear system
// (d·I + s·K)·v′ = b over the free particles' velocities (fixed particles are Dirichlet: they
// only add to the diagonal blocks of their neighbours), K the 3×3-block spring Jacobian
// −∂F/∂x, solved by Jacobi-preconditioned conjugate gradients. The sparsity pattern is built
// once per muscle from the spring list; each iteration refills the values in place.
#include <Eigen/SparseCore>
#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "IntegratorsInternal.h"

namespace fibremss {
namespace {

using Vector = Eigen::VectorXd;
using Matrix = Eigen::SparseMatrix<double>;  // column-major: a block column's rows are contiguous

constexpr uint32_t kFixedRow = UINT32_MAX;

/// The linear system of one muscle and the conjugate-gradient vectors (3 rows per free particle).
struct ImplicitWorkspace final : IntegratorWorkspace {
  Matrix matrix;               ///< d·I + s·K; pattern fixed at prepare, values refilled
  std::vector<uint32_t> rows;  ///< particle → first row of its block (kFixedRow: fixed)
  /// Per free particle: index in the values of its diagonal block's column j, row 3r.
  std::vector<std::array<int32_t, 3>> diagonalBlocks;
  /// Per spring: value indices of blocks (a, b) then (b, a), column j row 0; −1: an end fixed.
  std::vector<std::array<int32_t, 6>> springBlocks;
  Vector rhs;                                 ///< b
  Vector solution;                            ///< v′ (starts at the guess)
  Vector residual;                            ///< r = b − A·v′
  Vector direction;                           ///< CG search direction p
  Vector preconditioned;                      ///< z = D⁻¹·r
  Vector product;                             ///< A·p (and A·w when forming b)
  Vector inverseDiagonal;                     ///< D⁻¹, the Jacobi preconditioner
  Vector known;                               ///< a vector A is applied to when forming b (v or w)
  std::vector<btVector3> previousVelocities;  ///< BDF2: v(t−dt′) of the free particles
  bool history = false;                       ///< BDF2: previousVelocities hold a step
};

/// Index in the values of the entry (row, column) of the compressed column-major matrix.
int32_t valueIndex(const Matrix& matrix, uint32_t row, uint32_t column) {
  const int* begin = matrix.innerIndexPtr() + matrix.outerIndexPtr()[column];
  const int* end = matrix.innerIndexPtr() + matrix.outerIndexPtr()[column + 1];
  const int* found = std::lower_bound(begin, end, static_cast<int>(row));
  return static_cast<int32_t>(found - matrix.innerIndexPtr());
}

/// Adds scale·B to the 3×3 block whose columns start at the value indices `columns`.
void addBlock(double* values, const int32_t* columns, const double (&block)[3][3], double scale) {
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i) values[columns[j] + i] += scale * block[i][j];
}

/// Jacobi-preconditioned conjugate gradients on A·x = b from the guess in `solution`: stops
/// at |r| ≤ tolerance·|b| or after `cap` iterations; allocates nothing.
void conjugateGradient(ImplicitWorkspace& w, double tolerance, int cap, IntegrationResult& result) {
  const double bound = tolerance * w.rhs.norm();
  w.product.noalias() = w.matrix * w.solution;
  w.residual = w.rhs - w.product;
  w.preconditioned = w.residual.cwiseProduct(w.inverseDiagonal);
  w.direction = w.preconditioned;
  double rz = w.residual.dot(w.preconditioned);
  int iteration = 0;
  double norm = w.residual.norm();
  while (norm > bound && iteration < cap) {
    w.product.noalias() = w.matrix * w.direction;
    const double curvature = w.direction.dot(w.product);
    if (!(curvature > 0)) break;  // A not positive along p (or NaN): keep what we have
    const double alpha = rz / curvature;
    w.solution += alpha * w.direction;
    w.residual -= alpha * w.product;
    w.preconditioned = w.residual.cwiseProduct(w.inverseDiagonal);
    const double next = w.residual.dot(w.preconditioned);
    w.direction = w.preconditioned + (next / rz) * w.direction;
    rz = next;
    norm = w.residual.norm();
    ++iteration;
  }
  const double rhsNorm = w.rhs.norm();
  result.solverIterations = iteration;
  result.solverResidual = rhsNorm > 0 ? norm / rhsNorm : norm;
}

/// One Newton step of an implicit method, written for all three as: with x̂ = a₁·x − a₂·x(t−dt′),
/// v̂ = a₁·v − a₂·v(t−dt′) and F(x′) ≈ F(x) − K·(x′ − x),
///   x′ = x̂ + β·v″,  m·v′ = m·v̂ + β·(F(x″) − c·v″)
/// where backward Euler and BDF2 take x″ = x′, v″ = v′ (BDF2: β = dt·(1+ω)/(1+2ω),
/// a₁ = (1+ω)²/(1+2ω), a₂ = ω²/(1+2ω), ω = dt/dt′; backward Euler and BDF2's first step: a₁ = 1,
/// a₂ = 0, β = dt) and the midpoint rule x″ = (x + x′)/2, v″ = (v + v′)/2 with a₁ = 1, a₂ = 0,
/// β = dt. The Jacobian drops the compressive part of the geometric stiffness (l < L0), which
/// keeps A symmetric positive definite for CG.
class ImplicitIntegrator final : public TimeIntegrator {
 public:
  explicit ImplicitIntegrator(Integrator kind) : kind_(kind) {}

  IntegrationResult advance(MuscleState& muscle, btScalar dt, btScalar previousDt) const override {
    auto& w = static_cast<ImplicitWorkspace&>(*muscle.workspace);
    const MuscleSettings& settings = *muscle.settings;
    const SimulationParameters& parameters = solverParameters(muscle);
    const double m = settings.particleMass;
    const double c = settings.damping;
    const double h = dt;
    const bool midpoint = kind_ == Integrator::ImplicitMidpoint;
    const bool bdf2 = kind_ == Integrator::Bdf2 && w.history;
    const double ratio = bdf2 ? h / previousDt : 0;
    const double a1 = bdf2 ? (1 + ratio) * (1 + ratio) / (1 + 2 * ratio) : 1;
    const double a2 = bdf2 ? ratio * ratio / (1 + 2 * ratio) : 0;
    const double beta = bdf2 ? h * (1 + ratio) / (1 + 2 * ratio) : h;
    // Midpoint: (m + c·h/2)·v′ + (h²/4)·K·v′ = (m − c·h/2)·v + h·F − (h²/4)·K·v.
    const double diagonal = midpoint ? m + c * h / 2 : m + c * beta;
    const double stiffnessScale = midpoint ? h * h / 4 : beta * beta;
    fill(w, settings, muscle.positions, diagonal, stiffnessScale, parameters.diagonalJacobian);

    // The vector A is applied to in b: v (midpoint) or w = x̂ − x = a₂·(x − x(t−dt′)) (BDF2).
    const std::vector<uint32_t>& free = muscle.freeParticles;
    for (size_t k = 0; k < free.size(); ++k) {
      const uint32_t i = free[k];
      const btVector3 known = midpoint ? muscle.velocities[i]
                                       : (muscle.positions[i] - muscle.previous[i]) * btScalar(a2);
      for (int j = 0; j < 3; ++j) w.known[3 * k + j] = known[j];
    }
    if (midpoint || bdf2) w.product.noalias() = w.matrix * w.known;
    for (size_t k = 0; k < free.size(); ++k) {
      const uint32_t i = free[k];
      for (int j = 0; j < 3; ++j) {
        const size_t r = 3 * k + j;
        const double v = muscle.velocities[i][j];
        const double force = muscle.forces[i][j];
        if (midpoint) {
          w.rhs[r] = 2 * m * v + h * force - w.product[r];
          w.solution[r] = v;
        } else {
          const double guess = a1 * v - a2 * w.previousVelocities[k][j];
          const double correction = bdf2 ? (w.product[r] - diagonal * w.known[r]) / beta : 0;
          w.rhs[r] = m * guess + beta * force - correction;
          w.solution[r] = guess;
        }
      }
    }
    IntegrationResult result;
    conjugateGradient(w, parameters.solverTolerance, std::max(1, parameters.solverIterations),
                      result);

    for (size_t k = 0; k < free.size(); ++k) {
      const uint32_t i = free[k];
      const btVector3 next(static_cast<btScalar>(w.solution[3 * k]),
                           static_cast<btScalar>(w.solution[3 * k + 1]),
                           static_cast<btScalar>(w.solution[3 * k + 2]));
      const btVector3 x = muscle.positions[i];
      const btVector3 target =
          midpoint ? x + (muscle.velocities[i] + next) * (dt / 2)
                   : x + (x - muscle.previous[i]) * btScalar(a2) + next * btScalar(beta);
      w.previousVelocities[k] = muscle.velocities[i];
      muscle.velocities[i] = next;
      muscle.previous[i] = x;
      muscle.positions[i] = target;
      result.displacement += (target - x).length();
    }
    w.history = true;
    result.finite = std::isfinite(result.displacement) && std::isfinite(result.solverResidual);
    return result;
  }
  bool usesVelocities() const override { return true; }
  Integrator kind() const override { return kind_; }

 protected:
  std::unique_ptr<IntegratorWorkspace> makeWorkspace(const MuscleState& muscle) const override {
    const MuscleSettings& settings = *muscle.settings;
    auto w = std::make_unique<ImplicitWorkspace>();
    w->rows.assign(settings.particleCount(), kFixedRow);
    for (size_t k = 0; k < muscle.freeParticles.size(); ++k)
      w->rows[muscle.freeParticles[k]] = static_cast<uint32_t>(3 * k);
    const auto size = static_cast<Eigen::Index>(3 * muscle.freeParticles.size());

    std::vector<Eigen::Triplet<double>> entries;
    const auto addPattern = [&](uint32_t row, uint32_t column) {
      for (uint32_t j = 0; j < 3; ++j)
        for (uint32_t i = 0; i < 3; ++i)
          entries.emplace_back(static_cast<int>(row + i), static_cast<int>(column + j), 0.0);
    };
    for (uint32_t i : muscle.freeParticles) addPattern(w->rows[i], w->rows[i]);
    for (const Spring& spring : settings.springs)
      if (w->rows[spring.a] != kFixedRow && w->rows[spring.b] != kFixedRow) {
        addPattern(w->rows[spring.a], w->rows[spring.b]);
        addPattern(w->rows[spring.b], w->rows[spring.a]);
      }
    w->matrix.resize(size, size);
    w->matrix.setFromTriplets(entries.begin(), entries.end());
    w->matrix.makeCompressed();

    const auto blockColumns = [&](uint32_t row, uint32_t column, int32_t* out) {
      for (uint32_t j = 0; j < 3; ++j) out[j] = valueIndex(w->matrix, row, column + j);
    };
    w->diagonalBlocks.resize(muscle.freeParticles.size());
    for (size_t k = 0; k < muscle.freeParticles.size(); ++k)
      blockColumns(static_cast<uint32_t>(3 * k), static_cast<uint32_t>(3 * k),
                   w->diagonalBlocks[k].data());
    w->springBlocks.assign(settings.springs.size(), {-1, -1, -1, -1, -1, -1});
    for (size_t s = 0; s < settings.springs.size(); ++s) {
      const uint32_t ra = w->rows[settings.springs[s].a];
      const uint32_t rb = w->rows[settings.springs[s].b];
      if (ra == kFixedRow || rb == kFixedRow) continue;
      blockColumns(ra, rb, w->springBlocks[s].data());
      blockColumns(rb, ra, w->springBlocks[s].data() + 3);
    }
    for (Vector* v : {&w->rhs, &w->solution, &w->residual, &w->direction, &w->preconditioned,
                      &w->product, &w->inverseDiagonal, &w->known})
      v->setZero(size);
    w->previousVelocities.assign(muscle.freeParticles.size(), btVector3(0, 0, 0));
    return w;
  }

 private:
  /// Refills A = diagonal·I + stiffnessScale·K at `positions` (only K's diagonal entries when
  /// `diagonalOnly`, seed 002's approximation) and the preconditioner D⁻¹.
  static void fill(ImplicitWorkspace& w, const MuscleSettings& settings,
                   const std::vector<btVector3>& positions, double diagonal, double stiffnessScale,
                   bool diagonalOnly) {
    double* values = w.matrix.valuePtr();
    std::fill(values, values + w.matrix.nonZeros(), 0.0);
    for (const auto& block : w.diagonalBlocks)
      for (int j = 0; j < 3; ++j) values[block[j] + j] += diagonal;
    for (size_t s = 0; s < settings.springs.size(); ++s) {
      const Spring& spring = settings.springs[s];
      const uint32_t ra = w.rows[spring.a];
      const uint32_t rb = w.rows[spring.b];
      if (ra == kFixedRow && rb == kFixedRow) continue;
      const btVector3 d = positions[spring.b] - positions[spring.a];
      const double length = d.length();
      if (!(length > 0)) continue;
      // K block: k·(g·I + (1 − g)·u·uᵀ), g = (1 − L0/l)⁺ (geometric term, tension only).
      const double g = std::max(0.0, 1 - spring.restLength / length);
      const double u[3] = {d.x() / length, d.y() / length, d.z() / length};
      double block[3][3];
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) block[i][j] = (1 - g) * u[i] * u[j] + (i == j ? g : 0);
      const double scale = stiffnessScale * spring.stiffness;
      if (diagonalOnly) {
        for (uint32_t row : {ra, rb})
          if (row != kFixedRow)
            for (int j = 0; j < 3; ++j)
              values[w.diagonalBlocks[row / 3][j] + j] += scale * block[j][j];
        continue;
      }
      if (ra != kFixedRow) addBlock(values, w.diagonalBlocks[ra / 3].data(), block, scale);
      if (rb != kFixedRow) addBlock(values, w.diagonalBlocks[rb / 3].data(), block, scale);
      if (w.springBlocks[s][0] >= 0) {
        addBlock(values, w.springBlocks[s].data(), block, -scale);
        addBlock(values, w.springBlocks[s].data() + 3, block, -scale);
      }
    }
    for (size_t k = 0; k < w.diagonalBlocks.size(); ++k)
      for (int j = 0; j < 3; ++j)
        w.inverseDiagonal[static_cast<Eigen::Index>(3 * k + j)] =
            1 / values[w.diagonalBlocks[k][j] + j];
  }

  Integrator kind_;  ///< ImplicitEuler, ImplicitMidpoint or Bdf2
};

}  // namespace

const TimeIntegrator* implicitIntegratorFor(Integrator kind) {
  static const ImplicitIntegrator implicitEuler(Integrator::ImplicitEuler);
  static const ImplicitIntegrator implicitMidpoint(Integrator::ImplicitMidpoint);
  static const ImplicitIntegrator bdf2(Integrator::Bdf2);
  switch (kind) {
    case Integrator::ImplicitEuler:
      return &implicitEuler;
    case Integrator::ImplicitMidpoint:
      return &implicitMidpoint;
    case Integrator::Bdf2:
      return &bdf2;
    default:
      return nullptr;
  }
}

}  // namespace fibremss
