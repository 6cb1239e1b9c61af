// Implicit integrators (docs/integrators.md): backward Euler, the implicit midpoint rule and
// BDF2, each one Newton step on the forces linearized at x(t): the linear system
// (d·I + s·K)·v′ = b over the free particles' velocities (fixed particles are Dirichlet: they
// only add to the diagonal blocks of their neighbours), K = −∂F/∂x the 3×3-block spring Jacobian
// plus the volume terms' rank-one products (VolumeForces.h, localVolumeJacobian and
// enclosedVolumeJacobian), solved by Jacobi-preconditioned conjugate gradients. The springs'
// sparsity pattern is built once per muscle from the spring list; each iteration refills the
// values in place and the volume terms' gradients, which multiply without a matrix.
#include <Eigen/SparseCore>
#include <algorithm>
#include <array>
#include <cmath>
#include <span>
#include <vector>

#include "IntegratorsInternal.h"
#include "dynamics/TimeStep.h"
#include "kernels/MuscleSystemPretransform.h"
#include "kernels/VolumeForces.h"

namespace fibremss {
namespace {

using Vector = Eigen::VectorXd;
using Matrix = Eigen::SparseMatrix<double>;  // column-major: a block column's rows are contiguous

constexpr uint32_t kFixedRow = UINT32_MAX;

/// The linear system of one muscle and the conjugate-gradient vectors (3 rows per free particle).
struct ImplicitWorkspace final : IntegratorWorkspace {
  Matrix matrix;               ///< d·I + s·K of the springs; pattern fixed at prepare, refilled
  std::vector<uint32_t> rows;  ///< particle → first row of its block (kFixedRow: fixed)
  /// Per free particle: index in the values of its diagonal block's column j, row 3r.
  std::vector<std::array<int32_t, 3>> diagonalBlocks;
  /// Per spring: value indices of blocks (a, b) then (b, a), column j row 0; −1: an end fixed.
  std::vector<std::array<int32_t, 6>> springBlocks;
  /// The volume terms' part of s·K (VolumeForces.h), multiplied as s·Σ w·g·(gᵀ·p): per fan
  /// particle its ∂(6V)/∂x_i (settings.fanParticles' layout), per fan its weight, per particle
  /// the enclosed volume's ∂V/∂x_i (empty without that term) and its weight.
  std::vector<btVector3> fanGradients;
  std::vector<double> fanWeights;
  std::vector<btVector3> enclosedGradient;
  double enclosedWeight = 0;
  double volumeScale = 0;    ///< s on the volume products; 0 when `diagonalJacobian` put them in A
  Vector rhs;                ///< b
  Vector solution;           ///< v′ (starts at the guess)
  Vector residual;           ///< r = b − A·v′
  Vector direction;          ///< CG search direction p
  Vector preconditioned;     ///< z = D⁻¹·r
  Vector product;            ///< A·p (and A·w when forming b)
  Vector inverseDiagonal;    ///< D⁻¹, the Jacobi preconditioner
  Vector known;              ///< e of G(v′) (see ImplicitIntegrator)
  Vector guess;              ///< CG's start: v (midpoint) or v̂
  double explicitLimit = 0;  ///< Verlet's stable dt of the muscle [s]
  std::vector<btVector3> previousVelocities;  ///< BDF2: v(t−dt′) of the free particles
  std::vector<btVector3> writtenVelocities;   ///< the v′ advance() last wrote (BDF2)
  bool history = false;                       ///< BDF2: previousVelocities hold a step
};

/// The coefficients of G(v′) = d·v′ − e − φ·F(p + σ·v′) (see ImplicitIntegrator).
struct Newton {
  double diagonal;  ///< d
  double phi;       ///< φ, the factor on the forces
  double sigma;     ///< σ, the factor on v′ in the evaluation point
};

/// Midpoint: θ = 1/2 + min(1/2, dt / (kThetaScale · Verlet's stable dt)) — 0.55 at 50× it.
constexpr double kThetaScale = 1000;

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

/// Adds s·w·g·(gᵀ·in) over the free rows of one rank-one volume term into `out`: g(v) the
/// gradient of particle particles[v].
template <class Gradient>
void addRankOne(const ImplicitWorkspace& w, std::span<const uint32_t> particles, Gradient g,
                double weight, const Vector& in, Vector& out) {
  double dot = 0;
  for (size_t v = 0; v < particles.size(); ++v) {
    const uint32_t row = w.rows[particles[v]];
    if (row == kFixedRow) continue;
    const btVector3& gradient = g(v);
    for (uint32_t j = 0; j < 3; ++j) dot += double(gradient[j]) * in[row + j];
  }
  const double scale = w.volumeScale * weight * dot;
  for (size_t v = 0; v < particles.size(); ++v) {
    const uint32_t row = w.rows[particles[v]];
    if (row == kFixedRow) continue;
    const btVector3& gradient = g(v);
    for (uint32_t j = 0; j < 3; ++j) out[row + j] += scale * double(gradient[j]);
  }
}

/// out = A·in, A the springs' matrix plus the volume terms' products; allocates nothing.
void multiply(const ImplicitWorkspace& w, const IntegratedMuscle& muscle, const Vector& in,
              Vector& out) {
  out.noalias() = w.matrix * in;
  if (w.volumeScale == 0) return;
  const MuscleSettings& settings = muscle.settings;
  for (size_t k = 0; k < w.fanWeights.size(); ++k) {
    const btVector3* g = w.fanGradients.data() + settings.fanOffsets[k];
    addRankOne(
        w, fanParticles(settings, k), [g](size_t v) -> const btVector3& { return g[v]; },
        w.fanWeights[k], in, out);
  }
  if (w.enclosedWeight > 0) {
    const std::vector<uint32_t>& free = muscle.particles.freeParticles;
    addRankOne(
        w, free, [&](size_t v) -> const btVector3& { return w.enclosedGradient[free[v]]; },
        w.enclosedWeight, in, out);
  }
}

/// Jacobi-preconditioned conjugate gradients on A·x = b from the guess in `solution`: stops
/// at |r| ≤ tolerance·|b| or after `cap` iterations; allocates nothing.
void conjugateGradient(ImplicitWorkspace& w, const IntegratedMuscle& muscle, double tolerance,
                       int cap, IntegrationResult& result) {
  const double bound = tolerance * w.rhs.norm();
  multiply(w, muscle, w.solution, w.product);
  w.residual = w.rhs - w.product;
  w.preconditioned = w.residual.cwiseProduct(w.inverseDiagonal);
  w.direction = w.preconditioned;
  double rz = w.residual.dot(w.preconditioned);
  int iteration = 0;
  double norm = w.residual.norm();
  while (norm > bound && iteration < cap) {
    multiply(w, muscle, w.direction, w.product);
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
/// v̂ = a₁·v − a₂·v(t−dt′),
///   x′ = x̂ + β·v″,  m·v′ = m·v̂ + β·(F(x″) − c·v″)
/// where backward Euler and BDF2 take x″ = x′, v″ = v′ (BDF2: β = dt·(1+ω)/(1+2ω),
/// a₁ = (1+ω)²/(1+2ω), a₂ = ω²/(1+2ω), ω = dt/dt′; backward Euler and BDF2's first step: a₁ = 1,
/// a₂ = 0, β = dt) and the midpoint rule, as the one-leg θ-method, v″ = (1−θ)·v + θ·v′,
/// x′ = x + dt·v″, x″ = x + θ·(x′ − x), a₁ = 1, a₂ = 0, β = dt. θ = 1/2 is the midpoint rule,
/// which has no numerical damping: far beyond the explicit limit the linearization error of
/// rotating springs feeds its stiff modes (a zigzag chain at 50× the limit blew up, also with up
/// to 8 safeguarded Newton steps, which tripled the cost). θ = 1/2 + min(1/2,
/// dt/(kThetaScale·h_e)), h_e Verlet's stable dt, damps them (θ = 0.55 at 50×) and keeps
/// second order (θ − 1/2 = O(dt)).
/// Each is G(v′) = d·v′ − e − φ·F(p + σ·v′) = 0 (midpoint: d = m + c·θ·dt,
/// e = (m − c·(1−θ)·dt)·v, φ = dt, p = x + θ(1−θ)·dt·v, σ = θ²·dt; the others: d = m + c·β,
/// e = m·v̂, φ = β, p = x̂, σ = β), and the Newton step from v′₀ with p + σ·v′₀ = x, with
/// F(y) ≈ F(x) − K·(y − x), is (d·I + φσ·K)·v′ = e + φ·F(x) + φσ·K·v′₀. The Jacobian drops the
/// compressive part of the geometric stiffness (l < L0), which keeps A symmetric positive
/// definite for CG.
class ImplicitIntegrator final : public TimeIntegrator {
 public:
  explicit ImplicitIntegrator(Integrator kind) : kind_(kind) {}

  IntegrationResult advance(const IntegratedMuscle& muscle, const MuscleSystemDef& def, btScalar dt,
                            btScalar previousDt) const override {
    auto& w = static_cast<ImplicitWorkspace&>(*muscle.workspace);
    const MuscleSettings& settings = muscle.settings;
    const double m = settings.particleMass;
    const double c = settings.damping;
    const double h = dt;
    const bool midpoint = kind_ == Integrator::ImplicitMidpoint;
    const bool bdf2 = kind_ == Integrator::Bdf2 && w.history;
    const double ratio = bdf2 ? h / previousDt : 0;
    const double a1 = bdf2 ? (1 + ratio) * (1 + ratio) / (1 + 2 * ratio) : 1;
    const double a2 = bdf2 ? ratio * ratio / (1 + 2 * ratio) : 0;
    const double beta = bdf2 ? h * (1 + ratio) / (1 + 2 * ratio) : h;
    const double theta = midpoint ? 0.5 + std::min(0.5, h / (kThetaScale * w.explicitLimit)) : 1;
    const Newton newton{midpoint ? m + c * theta * h : m + c * beta, midpoint ? h : beta,
                        midpoint ? theta * theta * h : beta};
    const std::vector<uint32_t>& free = muscle.particles.freeParticles;
    if (kind_ == Integrator::Bdf2) followVelocityHistory(w, muscle, def);
    for (size_t k = 0; k < free.size(); ++k) {
      const uint32_t i = free[k];
      const btVector3 x = muscle.particles.positions[i];
      const btVector3 v = muscle.particles.velocities[i];
      const btVector3 offset = midpoint ? v * btScalar(theta * (1 - theta) * h)
                                        : (x - muscle.particles.previous[i]) * btScalar(a2);
      for (int j = 0; j < 3; ++j) {
        const size_t r = 3 * k + j;
        w.known[r] = midpoint ? (m - c * (1 - theta) * h) * v[j]
                              : m * (a1 * v[j] - a2 * w.previousVelocities[k][j]);
        // v′₀ with p + σ·v′₀ = x: the step linearizes at the iteration's positions; CG
        // starts from v (midpoint) or v̂.
        w.solution[r] = -offset[j] / newton.sigma;
        w.guess[r] = midpoint ? v[j] : w.known[r] / m;
      }
    }
    IntegrationResult result;
    newtonStep(w, muscle, newton, def, result);

    for (size_t k = 0; k < free.size(); ++k) {
      const uint32_t i = free[k];
      const btVector3 next(static_cast<btScalar>(w.solution[3 * k]),
                           static_cast<btScalar>(w.solution[3 * k + 1]),
                           static_cast<btScalar>(w.solution[3 * k + 2]));
      const btVector3 x = muscle.particles.positions[i];
      const btVector3 target =
          midpoint ? x + (muscle.particles.velocities[i] * btScalar(1 - theta) +
                          next * btScalar(theta)) *
                             dt
                   : x + (x - muscle.particles.previous[i]) * btScalar(a2) + next * btScalar(beta);
      w.previousVelocities[k] = muscle.particles.velocities[i];
      w.writtenVelocities[k] = next;
      muscle.particles.velocities[i] = next;
      muscle.particles.previous[i] = x;
      muscle.particles.positions[i] = target;
      result.displacement += (target - x).length();
    }
    w.history = true;
    result.finite = std::isfinite(result.displacement) && std::isfinite(result.solverResidual);
    return result;
  }
  bool usesVelocities() const override { return true; }
  Integrator kind() const override { return kind_; }

 protected:
  std::unique_ptr<IntegratorWorkspace> makeWorkspace(
      const MuscleSettings& settings, const ParticleState& particles) const override {
    auto w = std::make_unique<ImplicitWorkspace>();
    w->rows.assign(settings.particleCount(), kFixedRow);
    for (size_t k = 0; k < particles.freeParticles.size(); ++k)
      w->rows[particles.freeParticles[k]] = static_cast<uint32_t>(3 * k);
    const auto size = static_cast<Eigen::Index>(3 * particles.freeParticles.size());

    std::vector<Eigen::Triplet<double>> entries;
    const auto addPattern = [&](uint32_t row, uint32_t column) {
      for (uint32_t j = 0; j < 3; ++j)
        for (uint32_t i = 0; i < 3; ++i)
          entries.emplace_back(static_cast<int>(row + i), static_cast<int>(column + j), 0.0);
    };
    for (uint32_t i : particles.freeParticles) addPattern(w->rows[i], w->rows[i]);
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
    w->diagonalBlocks.resize(particles.freeParticles.size());
    for (size_t k = 0; k < particles.freeParticles.size(); ++k)
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
                      &w->product, &w->inverseDiagonal, &w->known, &w->guess})
      v->setZero(size);
    w->fanGradients.assign(settings.fanParticles.size(), btVector3(0, 0, 0));
    w->fanWeights.assign(settings.fanInverseVolume.size(), 0);
    if (!settings.enclosedFaces.empty())
      w->enclosedGradient.assign(settings.particleCount(), btVector3(0, 0, 0));
    w->explicitLimit = stableTimeStep(settings, Integrator::Verlet);
    w->previousVelocities.assign(particles.freeParticles.size(), btVector3(0, 0, 0));
    w->writtenVelocities.assign(particles.freeParticles.size(), btVector3(0, 0, 0));
    return w;
  }

 private:
  /// The Newton step from v′₀ in w.solution, linearized at the muscle's positions (= p + σ·v′₀)
  /// with their forces: refills A, forms b = e + φ·F + (A − d·I)·v′₀, solves A·v′ = b into
  /// w.solution from w.guess.
  static void newtonStep(ImplicitWorkspace& w, const IntegratedMuscle& muscle, const Newton& newton,
                         const MuscleSystemDef& def, IntegrationResult& result) {
    fill(w, muscle, newton.diagonal, newton.phi * newton.sigma, def.diagonalJacobian);
    multiply(w, muscle, w.solution, w.product);
    const std::vector<uint32_t>& free = muscle.particles.freeParticles;
    for (size_t k = 0; k < free.size(); ++k)
      for (int j = 0; j < 3; ++j) {
        const size_t r = 3 * k + j;
        w.rhs[r] = w.known[r] + newton.phi * muscle.particles.forces[free[k]][j] + w.product[r] -
                   newton.diagonal * w.solution[r];
      }
    w.solution = w.guess;
    conjugateGradient(w, muscle, def.solverTolerance, std::max(1, def.solverIterations), result);
  }

  /// BDF2's v(t−dt′) follows what happened to the velocity advance() last wrote: unchanged, it
  /// stays; turned by the bones' pre-transform (the same turn of the written velocity gives the
  /// present one bit for bit), it turns alike; anything else (a contact zeroed it, a rollback
  /// or preparation restored another) drops the history: v(t−dt′) = v, so v̂ = v.
  static void followVelocityHistory(ImplicitWorkspace& w, const IntegratedMuscle& muscle,
                                    const MuscleSystemDef& def) {
    const MuscleSettings& settings = muscle.settings;
    for (size_t k = 0; k < muscle.particles.freeParticles.size(); ++k) {
      const uint32_t i = muscle.particles.freeParticles[k];
      const btVector3& v = muscle.particles.velocities[i];
      if (v == w.writtenVelocities[k]) continue;
      if (pretransformDirection(settings, muscle.particles.boneDeltas, i, w.writtenVelocities[k],
                                def.blendedPretransform, def.pretransformBlend) == v)
        w.previousVelocities[k] =
            pretransformDirection(settings, muscle.particles.boneDeltas, i, w.previousVelocities[k],
                                  def.blendedPretransform, def.pretransformBlend);
      else
        w.previousVelocities[k] = v;
    }
  }

  /// Refills A = diagonal·I + stiffnessScale·K at the muscle's positions (only K's diagonal
  /// entries when `diagonalOnly`, seed 002's approximation: the volume terms' then go into the
  /// matrix, else they multiply as rank-one products) and the preconditioner D⁻¹.
  static void fill(ImplicitWorkspace& w, const IntegratedMuscle& muscle, double diagonal,
                   double stiffnessScale, bool diagonalOnly) {
    const MuscleSettings& settings = muscle.settings;
    const std::vector<btVector3>& positions = muscle.particles.positions;
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
            values[w.diagonalBlocks[k][j] + j];
    // The volume terms' diagonal: into the matrix when it keeps only its diagonal, else into D
    // alone (their products add the rest in multiply()).
    localVolumeJacobian(settings, positions, w.fanGradients, w.fanWeights);
    w.enclosedWeight = enclosedVolumeJacobian(settings, positions, w.enclosedGradient);
    w.volumeScale = diagonalOnly ? 0 : stiffnessScale;
    const auto addDiagonal = [&](uint32_t particle, const btVector3& g, double weight) {
      const uint32_t row = w.rows[particle];
      if (row == kFixedRow) return;
      for (uint32_t j = 0; j < 3; ++j) {
        const double entry = stiffnessScale * weight * double(g[j]) * double(g[j]);
        w.inverseDiagonal[row + j] += entry;
        if (diagonalOnly) values[w.diagonalBlocks[row / 3][j] + j] += entry;
      }
    };
    for (size_t k = 0; k < w.fanWeights.size(); ++k) {
      const std::span<const uint32_t> p = fanParticles(settings, k);
      for (size_t v = 0; v < p.size(); ++v)
        addDiagonal(p[v], w.fanGradients[settings.fanOffsets[k] + v], w.fanWeights[k]);
    }
    if (w.enclosedWeight > 0)
      for (uint32_t i : muscle.particles.freeParticles)
        addDiagonal(i, w.enclosedGradient[i], w.enclosedWeight);
    w.inverseDiagonal = w.inverseDiagonal.cwiseInverse();
  }

  Integrator kind_;  ///< ImplicitEuler, ImplicitMidpoint or Bdf2
};

const ImplicitIntegrator implicitEuler(Integrator::ImplicitEuler);
const ImplicitIntegrator implicitMidpoint(Integrator::ImplicitMidpoint);
const ImplicitIntegrator bdf2(Integrator::Bdf2);
const IntegratorRegistration registrations[] = {
    {implicitEuler, "implicit-euler"}, {implicitMidpoint, "implicit-midpoint"}, {bdf2, "bdf2"}};

}  // namespace

}  // namespace fibremss
