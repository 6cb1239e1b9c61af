// Explicit integrators (docs/integrators.md): damped Verlet, semi-implicit Euler and the explicit
// Runge–Kutta family (explicit Euler, midpoint RK2, classic RK4).
#include <algorithm>
#include <array>
#include <cmath>
#include <span>
#include <vector>

#include "IntegratorsInternal.h"
#include "contact/BodyContacts.h"
#include "kernels/ParticleSimd.h"
#include "kernels/SpringForces.h"
#include "kernels/VolumeForces.h"

namespace fibremss {
namespace {

/// Acceleration of the damped spring model: (F − c·v)/m.
btVector3 acceleration(const btVector3& force, const btVector3& velocity, btScalar damping,
                       btScalar inverseMass) {
  return (force - velocity * damping) * inverseMass;
}

/// Verlet's step of the free particles but the last (count mod 4) on the SSE2 path (none in
/// builds without it), one particle per register with the scalar loop's operations in its
/// order (no FMA), so positions and previous get the same bits (w lanes: x's kept in previous,
/// 0 in positions as btVector3's operators leave it). Adds Σ|step| to `displacement`: lengths
/// four at a time into four double partial sums (one long chain of additions would bound the
/// loop), so it differs from the particle-order sum in the last bits only, the same for any
/// thread count. Returns how many particles it moved.
size_t advanceVerletVector(ParticleState& particles, btScalar keep, btScalar forceScale,
                           double& displacement) {
#if FIBREMSS_SSE_PARTICLES
  const size_t count = particles.freeParticles.size() & ~size_t{3};
  const uint32_t* indices = particles.freeParticles.data();
  btVector3* x = particles.positions.data();
  btVector3* previous = particles.previous.data();
  const btVector3* f = particles.forces.data();
  const __m128 keepAll = _mm_set1_ps(keep), scaleAll = _mm_set1_ps(forceScale);
  const __m128 xyz = xyzMask();
  __m128d low = _mm_setzero_pd(), high = _mm_setzero_pd();  // four partial sums of lengths
  for (size_t k = 0; k < count; k += 4) {
    __m128 steps[4];
    for (size_t j = 0; j < 4; ++j) {
      const uint32_t i = indices[k + j];
      const __m128 position = loadVector(x[i]);
      steps[j] = _mm_add_ps(_mm_mul_ps(_mm_sub_ps(position, loadVector(previous[i])), keepAll),
                            _mm_mul_ps(loadVector(f[i]), scaleAll));
      _mm_store_ps(previous[i].m_floats, position);
      _mm_store_ps(x[i].m_floats, _mm_and_ps(_mm_add_ps(position, steps[j]), xyz));
    }
    const __m128 lengths = _mm_sqrt_ps(squaredLengths(steps[0], steps[1], steps[2], steps[3]));
    low = _mm_add_pd(low, _mm_cvtps_pd(lengths));
    high = _mm_add_pd(high, _mm_cvtps_pd(_mm_movehl_ps(lengths, lengths)));
  }
  alignas(16) double sums[4];
  _mm_store_pd(sums, low);
  _mm_store_pd(sums + 2, high);
  displacement += (sums[0] + sums[1]) + (sums[2] + sums[3]);
  return count;
#else
  return 0;
#endif
}

/// Verlet with centred velocity damping (method.md §4), time-corrected for a changing dt:
/// x⁺ − x = v⁻·dt + dt²/m·(F − c·v) with v⁻ = (x − x⁻)/dt′ (dt′ the previous step) and the
/// damped velocity centred at t, v = ((x⁺ − x)/dt + v⁻)/2. Solved for x⁺ with γ = c·dt/(2m):
/// x⁺ = x + ((x − x⁻)·(dt/dt′)·(1 − γ) + dt²/m·F)/(1 + γ). With a fixed dt this is
/// x⁺ = x + (x − x⁻)·(1 − γ)/(1 + γ) + dt²/m·F/(1 + γ), second order also when damped (the
/// backward velocity alone made it first order); without the dt/dt′ correction a shrinking
/// adaptive dt would raise the velocity and pump energy in.
class VerletIntegrator final : public TimeIntegrator {
 public:
  IntegrationResult advance(const IntegratedMuscle& muscle, const MuscleSystemDef&, btScalar dt,
                            btScalar previousDt) const override {
    const MuscleSettings& settings = muscle.settings;
    const btScalar gamma = settings.damping * dt / (2 * settings.particleMass);
    const btScalar forceScale = dt * dt / (settings.particleMass * (1 + gamma));
    const btScalar keep = (1 - gamma) / (1 + gamma) * dt / previousDt;
    IntegrationResult result;
    for (size_t k = advanceVerletVector(muscle.particles, keep, forceScale, result.displacement);
         k < muscle.particles.freeParticles.size(); ++k) {
      const uint32_t i = muscle.particles.freeParticles[k];
      result.displacement +=
          heavyBallStep(muscle.particles, i, muscle.particles.forces[i], keep, forceScale);
    }
    result.finite = std::isfinite(result.displacement);
    return result;
  }
  bool usesVelocities() const override { return false; }
  Integrator kind() const override { return Integrator::Verlet; }
};

/// Semi-implicit (symplectic) Euler: v += dt/m·(F − c·v); x += dt·v.
class SemiImplicitEulerIntegrator final : public TimeIntegrator {
 public:
  IntegrationResult advance(const IntegratedMuscle& muscle, const MuscleSystemDef&, btScalar dt,
                            btScalar) const override {
    const MuscleSettings& settings = muscle.settings;
    const btScalar inverseMass = 1 / settings.particleMass;
    IntegrationResult result;
    for (uint32_t i : muscle.particles.freeParticles) {
      btVector3& v = muscle.particles.velocities[i];
      v += acceleration(muscle.particles.forces[i], v, settings.damping, inverseMass) * dt;
      const btVector3 step = v * dt;
      muscle.particles.previous[i] = muscle.particles.positions[i];
      muscle.particles.positions[i] += step;
      result.displacement += step.length();
    }
    result.finite = std::isfinite(result.displacement);
    return result;
  }
  bool usesVelocities() const override { return true; }
  Integrator kind() const override { return Integrator::SemiImplicitEuler; }
};

/// Stage buffers of an explicit Runge–Kutta method, one entry per particle.
struct StageWorkspace final : IntegratorWorkspace {
  std::vector<btVector3> positions;    ///< positions of the running stage (fixed ones: x)
  std::vector<btVector3> velocities;   ///< velocities of the running stage
  std::vector<btVector3> forces;       ///< spring forces at `positions`
  std::vector<btVector3> positionSum;  ///< Σ b_s·k_s of the positions so far
  std::vector<btVector3> velocitySum;  ///< Σ b_s·k_s of the velocities so far
};

/// Explicit Runge–Kutta on y = (x, v), y′ = (v, (F(x) − c·v)/m) with a tableau whose stage s+1
/// is evaluated at y + offsets[s]·dt·k_s, and y(t+dt) = y + dt·Σ weights[s]·k_s: explicit Euler
/// (one stage), midpoint RK2, classic RK4. The first stage uses the forces of the step.
class RungeKuttaIntegrator final : public TimeIntegrator {
 public:
  /// `offsets` has one entry less than `weights` (static storage).
  RungeKuttaIntegrator(Integrator kind, std::span<const btScalar> offsets,
                       std::span<const btScalar> weights)
      : kind_(kind), offsets_(offsets), weights_(weights) {}

  IntegrationResult advance(const IntegratedMuscle& muscle, const MuscleSystemDef& def, btScalar dt,
                            btScalar) const override {
    const MuscleSettings& settings = muscle.settings;
    const btScalar inverseMass = 1 / settings.particleMass;
    const btScalar damping = settings.damping;
    IntegrationResult result;
    if (weights_.size() == 1) {  // explicit Euler: x += dt·v; v += dt·a(x, v)
      for (uint32_t i : muscle.particles.freeParticles) {
        btVector3& v = muscle.particles.velocities[i];
        const btVector3 step = v * dt;
        v += acceleration(muscle.particles.forces[i], v, damping, inverseMass) * dt;
        muscle.particles.previous[i] = muscle.particles.positions[i];
        muscle.particles.positions[i] += step;
        result.displacement += step.length();
      }
      result.finite = std::isfinite(result.displacement);
      return result;
    }
    auto& stage = static_cast<StageWorkspace&>(*muscle.workspace);
    std::copy(muscle.particles.positions.begin(), muscle.particles.positions.end(),
              stage.positions.begin());
    const btScalar firstOffset = offsets_[0] * dt;
    for (uint32_t i : muscle.particles.freeParticles) {
      const btVector3 v = muscle.particles.velocities[i];
      const btVector3 a = acceleration(muscle.particles.forces[i], v, damping, inverseMass);
      stage.positionSum[i] = v * weights_[0];
      stage.velocitySum[i] = a * weights_[0];
      stage.positions[i] = muscle.particles.positions[i] + v * firstOffset;
      stage.velocities[i] = v + a * firstOffset;
    }
    for (size_t s = 1; s < weights_.size(); ++s) {
      springForces(settings, stage.positions, stage.forces);
      addLocalVolumeForces(settings, stage.positions, stage.forces);
      addEnclosedVolumeForces(settings, stage.positions, stage.forces);
      addExternalForces(muscle.settings, muscle.particles, muscle.interaction, def.gravity,
                        stage.forces);
      const btScalar weight = weights_[s];
      const bool last = s + 1 == weights_.size();
      const btScalar offset = last ? 0 : offsets_[s] * dt;
      for (uint32_t i : muscle.particles.freeParticles) {
        const btVector3 v = stage.velocities[i];
        const btVector3 a = acceleration(stage.forces[i], v, damping, inverseMass);
        stage.positionSum[i] += v * weight;
        stage.velocitySum[i] += a * weight;
        if (last) continue;
        stage.positions[i] = muscle.particles.positions[i] + v * offset;
        stage.velocities[i] = muscle.particles.velocities[i] + a * offset;
      }
    }
    for (uint32_t i : muscle.particles.freeParticles) {
      const btVector3 step = stage.positionSum[i] * dt;
      muscle.particles.previous[i] = muscle.particles.positions[i];
      muscle.particles.positions[i] += step;
      muscle.particles.velocities[i] += stage.velocitySum[i] * dt;
      result.displacement += step.length();
    }
    result.finite = std::isfinite(result.displacement);
    return result;
  }
  bool usesVelocities() const override { return true; }
  Integrator kind() const override { return kind_; }

 protected:
  std::unique_ptr<IntegratorWorkspace> makeWorkspace(
      const MuscleSettings&, const ParticleState& particles) const override {
    if (weights_.size() == 1) return nullptr;
    auto stage = std::make_unique<StageWorkspace>();
    const size_t n = particles.positions.size();
    for (auto* buffer : {&stage->positions, &stage->velocities, &stage->forces, &stage->positionSum,
                         &stage->velocitySum})
      buffer->assign(n, btVector3(0, 0, 0));
    return stage;
  }

 private:
  Integrator kind_;                    ///< which method the tableau is
  std::span<const btScalar> offsets_;  ///< stage offsets c (one per stage after the first)
  std::span<const btScalar> weights_;  ///< final weights b (one per stage)
};

constexpr std::array<btScalar, 1> kEulerWeights{1};
constexpr std::array<btScalar, 1> kMidpointOffsets{btScalar(0.5)};
constexpr std::array<btScalar, 2> kMidpointWeights{0, 1};
constexpr std::array<btScalar, 3> kClassicOffsets{btScalar(0.5), btScalar(0.5), 1};
constexpr std::array<btScalar, 4> kClassicWeights{btScalar(1) / 6, btScalar(1) / 3, btScalar(1) / 3,
                                                  btScalar(1) / 6};

const VerletIntegrator verlet;
const SemiImplicitEulerIntegrator semiImplicitEuler;
const RungeKuttaIntegrator explicitEuler(Integrator::ExplicitEuler, {}, kEulerWeights);
const RungeKuttaIntegrator rk2(Integrator::Rk2, kMidpointOffsets, kMidpointWeights);
const RungeKuttaIntegrator rk4(Integrator::Rk4, kClassicOffsets, kClassicWeights);
const IntegratorRegistration registrations[] = {{verlet, "verlet"},
                                                {semiImplicitEuler, "semi-implicit-euler"},
                                                {explicitEuler, "explicit-euler"},
                                                {rk2, "rk2"},
                                                {rk4, "rk4"}};

}  // namespace

}  // namespace fibremss
