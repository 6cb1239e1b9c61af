// Time integrators (docs/integrators.md): order of accuracy on a damped spring against the
// analytic solution, PBD/XPBD statics, implicit stability far beyond the explicit limit on a
// stiff chain, and every integrator inside a MuscleSystem with collision (finite, no allocation
// in step()).
#include "integrators/Integrators.h"

#include <LinearMath/btAlignedAllocator.h>
#include <gtest/gtest.h>

#include <Eigen/SparseCholesky>
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "dynamics/StrainLimit.h"
#include "dynamics/TimeStep.h"
#include "fibremss/Error.h"
#include "fibremss/MuscleSystem.h"
#include "integrators/ProjectiveFactor.h"
#include "kernels/SpringForces.h"
#include "solver/MuscleSystemAccess.h"
#include "support/AllocationCounter.h"
#include "support/GridMuscle.h"
#include "support/SolverFixtures.h"
#include "support/ThighSteps.h"

namespace fibremss {
namespace {

/// Every integrator the core registers, in the enum's order: a new one joins the EveryIntegrator
/// tests.
std::vector<Integrator> everyIntegrator() {
  std::vector<Integrator> kinds;
  for (int value = 0; value <= std::numeric_limits<std::underlying_type_t<Integrator>>::max();
       ++value)
    if (registeredIntegratorName(static_cast<Integrator>(value)))
      kinds.push_back(static_cast<Integrator>(value));
  return kinds;
}

constexpr bool kFloat = sizeof(btScalar) == sizeof(float);

/// Particles at `points`, none colliding, with springs added by link() in (a, b) order.
std::shared_ptr<MuscleSettings> particles(const std::vector<btVector3>& points, btScalar mass,
                                          btScalar damping) {
  auto settings = std::make_shared<MuscleSettings>();
  settings->name = "particles";
  settings->restPositions = points;
  settings->radii.assign(points.size(), 0);
  settings->flags.assign(points.size(), 0);
  settings->fixedBone.assign(points.size(), -1);
  settings->nearestBone.assign(points.size(), -1);
  settings->particleMass = mass;
  settings->damping = damping;
  return settings;
}

/// Spring a–b (a < b) of stiffness k and rest length L0.
void link(MuscleSettings& settings, uint32_t a, uint32_t b, btScalar k, btScalar restLength) {
  settings.springs.push_back({a, b, restLength, k});
}

/// One muscle's state stepped by an integrator alone (no system): forces, then advance.
class Bench {
 public:
  Bench(std::shared_ptr<const MuscleSettings> settings, Integrator kind)
      : integrator_(integratorFor(kind)) {
    const size_t n = settings->particleCount();
    state.settings = settings;
    state.positions = settings->restPositions;
    state.previous = settings->restPositions;
    state.velocities.assign(n, btVector3(0, 0, 0));
    state.forces.assign(n, btVector3(0, 0, 0));
    for (uint32_t i = 0; i < n; ++i)
      if (!settings->isFixed(i)) state.freeParticles.push_back(i);
    parameters.solverTolerance = 1e-12;
    parameters.solverIterations = 200;
    integrator_.prepare(*state.settings, state, state);
  }
  Bench(const Bench&) = delete;
  Bench& operator=(const Bench&) = delete;

  /// Places particle i at x, at rest.
  void place(uint32_t i, const btVector3& x) { state.positions[i] = state.previous[i] = x; }
  /// One iteration of fixed dt; returns the integrator's result.
  IntegrationResult step(btScalar dt) {
    springForces(*state.settings, state);
    return integrator_.advance(state.integrated(false), parameters, dt, dt);
  }
  /// Kinetic plus spring energy; the velocity is v or (x − x_prev)/dt.
  double energy(btScalar dt) const {
    const MuscleSettings& settings = *state.settings;
    double total = 0;
    for (uint32_t i : state.freeParticles) {
      const btVector3 v = integrator_.usesVelocities()
                              ? state.velocities[i]
                              : (state.positions[i] - state.previous[i]) / dt;
      total += 0.5 * settings.particleMass * v.length2();
    }
    for (const Spring& s : settings.springs) {
      const double stretch = (state.positions[s.b] - state.positions[s.a]).length() - s.restLength;
      total += 0.5 * s.stiffness * stretch * stretch;
    }
    return total;
  }

  MuscleState state;           ///< the muscle stepped
  MuscleSystemDef parameters;  ///< solver settings (tight CG tolerance)

 private:
  const TimeIntegrator& integrator_;
};

// --- order of accuracy: one free particle on a damped spring to a fixed one ---------------------

constexpr double kMass = 1, kStiffness = 1;  // ω0 = 1
constexpr double kRest = 0.1, kAmplitude = 0.05, kEndTime = 4;

/// Analytic elongation at t of m·ü + c·u̇ + k·u = 0 from u(0) = A, u̇(0) = 0.
double analyticElongation(double t, double damping) {
  const double decay = damping / (2 * kMass);
  const double omega = std::sqrt(kStiffness / kMass - decay * decay);
  return kAmplitude * std::exp(-decay * t) *
         (std::cos(omega * t) + decay / omega * std::sin(omega * t));
}

/// |x(T) − x_exact(T)| of the free particle after `steps` steps of T/steps.
double springError(Integrator kind, int steps, double damping) {
  auto settings =
      particles({{0, 0, 0}, {kRest + kAmplitude, 0, 0}}, kMass, static_cast<btScalar>(damping));
  testing::fix(*settings, 0, 0);
  link(*settings, 0, 1, kStiffness, kRest);
  Bench bench(settings, kind);
  const auto dt = static_cast<btScalar>(kEndTime / steps);
  // Two-step Verlet starts from the exact x(−dt) (x(−dt) = x(0) would be an O(dt) start).
  bench.state.previous[1].setX(static_cast<btScalar>(kRest + analyticElongation(-dt, damping)));
  for (int s = 0; s < steps; ++s) bench.step(dt);
  return std::abs(bench.state.positions[1].x() - (kRest + analyticElongation(kEndTime, damping)));
}

struct OrderCase {
  Integrator kind;  ///< integrator
  double order;     ///< its classical order
  int steps;        ///< coarsest step count of the refinement
  double damping;   ///< c [N·s/m] (0.2: ζ = 0.1)
};

class OrderOfAccuracy : public ::testing::TestWithParam<OrderCase> {};

TEST_P(OrderOfAccuracy, HalvingDtDividesTheErrorByTwoToTheOrder) {
  const OrderCase& c = GetParam();
  const double coarse = springError(c.kind, c.steps, c.damping);
  const double middle = springError(c.kind, 2 * c.steps, c.damping);
  const double fine = springError(c.kind, 4 * c.steps, c.damping);
  // Below this the float build measures round-off, not truncation.
  const double floor = 200 * std::numeric_limits<btScalar>::epsilon() * (kRest + kAmplitude);
  if (fine < floor)
    GTEST_SKIP() << toString(c.kind) << ": error " << fine << " at the finest dt is round-off "
                 << "of this btScalar (below " << floor << "); the double build checks the order";
  const double measured = std::log2(middle / fine);
  RecordProperty("measured_order", std::to_string(measured));
  EXPECT_NEAR(measured, c.order, 0.3)
      << toString(c.kind) << " errors " << coarse << ", " << middle << ", " << fine
      << " (coarse pair order " << std::log2(coarse / middle) << ")";
}

INSTANTIATE_TEST_SUITE_P(DampedSpring, OrderOfAccuracy,
                         // Verlet damps with the centred velocity (x⁺ − x⁻)/(2dt): second order
                         // damped too (the thesis' backward velocity (x − x⁻)/dt made it first).
                         ::testing::Values(OrderCase{Integrator::ExplicitEuler, 1, 80, 0.2},
                                           OrderCase{Integrator::SemiImplicitEuler, 1, 80, 0.2},
                                           OrderCase{Integrator::ImplicitEuler, 1, 80, 0.2},
                                           OrderCase{Integrator::Verlet, 2, 10, 0},
                                           OrderCase{Integrator::Verlet, 2, 20, 0.2},
                                           OrderCase{Integrator::Rk2, 2, 40, 0.2},
                                           OrderCase{Integrator::ImplicitMidpoint, 2, 40, 0.2},
                                           OrderCase{Integrator::Bdf2, 2, 40, 0.2},
                                           OrderCase{Integrator::Rk4, 4, kFloat ? 4 : 10, 0.2}),
                         [](const auto& param) {
                           std::string name = toString(param.param.kind);
                           std::erase(name, '-');
                           return name + (param.param.damping > 0 ? "Damped" : "Undamped");
                         });

// --- position-based: rest length and static elongation -----------------------------------------

TEST(Registry, EveryKindFromTheFirstIsRegisteredOnceUnderANameThatParsesBack) {
  const std::vector<Integrator> kinds = everyIntegrator();
  ASSERT_FALSE(kinds.empty());
  for (size_t i = 0; i < kinds.size(); ++i) {
    EXPECT_EQ(static_cast<size_t>(kinds[i]), i)
        << "a kind without an integrator before " << toString(kinds[i]);
    EXPECT_EQ(integratorFor(kinds[i]).kind(), kinds[i]) << toString(kinds[i]);
    Integrator parsed{};
    ASSERT_TRUE(fromString(toString(kinds[i]), parsed)) << toString(kinds[i]);
    EXPECT_EQ(parsed, kinds[i]);
  }
  EXPECT_THROW(integratorFor(static_cast<Integrator>(kinds.size())), InputError);
}

TEST(PositionBased, PbdConvergesToTheRestLengths) {
  // A tetrahedron, one corner fixed, the other three displaced: every edge returns to L0.
  const btScalar edge = 0.01;
  auto settings = particles({{0, 0, 0},
                             {edge, 0, 0},
                             {edge / 2, edge * btScalar(0.866), 0},
                             {edge / 2, 0.29f * edge, 0.82f * edge}},
                            1e-3, 2e-2);
  testing::fix(*settings, 0, 0);
  for (uint32_t a = 0; a < 4; ++a)
    for (uint32_t b = a + 1; b < 4; ++b)
      link(*settings, a, b, 100,
           (settings->restPositions[b] - settings->restPositions[a]).length());
  Bench bench(settings, Integrator::Pbd);
  std::mt19937 random(5);
  std::uniform_real_distribution<btScalar> noise(-0.2f * edge, 0.2f * edge);
  for (uint32_t i = 1; i < 4; ++i)
    bench.place(
        i, settings->restPositions[i] + btVector3(noise(random), noise(random), noise(random)));
  for (int s = 0; s < 300; ++s) ASSERT_TRUE(bench.step(1e-3).finite);
  for (const Spring& s : settings->springs)
    EXPECT_NEAR((bench.state.positions[s.b] - bench.state.positions[s.a]).length(), s.restLength,
                1e-4 * s.restLength);
}

TEST(PositionBased, XpbdGivesTheStaticElongationUnderLoad) {
  // Fixed A at 0, free P, fixed B at D: spring 1 (k1, L1) loaded by spring 2 (k2, L2). At rest
  // k1·(x − L1) = k2·(D − x − L2), so x = (k1·L1 + k2·(D − L2)) / (k1 + k2).
  const double k1 = 10, k2 = 30, l1 = 0.01, l2 = 0.01, d = 0.03;
  auto settings = particles({{0, 0, 0}, {0.015f, 0, 0}, {btScalar(d), 0, 0}}, 1e-3, 2e-2);
  testing::fix(*settings, 0, 0);
  testing::fix(*settings, 2, 0);
  link(*settings, 0, 1, btScalar(k1), btScalar(l1));
  link(*settings, 1, 2, btScalar(k2), btScalar(l2));
  const double expected = (k1 * l1 + k2 * (d - l2)) / (k1 + k2);
  for (Integrator kind : {Integrator::Xpbd, Integrator::Pbd}) {
    Bench bench(settings, kind);
    for (int s = 0; s < 3000; ++s) ASSERT_TRUE(bench.step(1e-3).finite);
    const double x = bench.state.positions[1].x();
    if (kind == Integrator::Xpbd)
      EXPECT_NEAR(x - l1, expected - l1, 1e-3 * (expected - l1)) << "elongation of spring 1";
    else  // rigid constraints cannot both hold: PBD ends elsewhere, at neither elongation.
      EXPECT_GT(std::abs(x - expected), 0.1 * (expected - l1));
  }
}

TEST(PositionBased, AnOverstretchedBlockSharesTheStretch) {
  // A 3 × 3 × 5 block (springs to the neighbours within 1.8 spacings) whose bottom and top
  // layers are fixed and pulled 2× apart: rigid constraints cannot all hold; the springs along
  // the pull must take a mean stretch of 2 × L0. Averaged (Jacobi) passes share it: no spring
  // beyond 3 × L0 (the solver's explosion limit); Gauss–Seidel in spring order left the excess
  // in the last springs of each path (the hip sweeps' explosions).
  const btScalar spacing = 0.005;
  std::vector<btVector3> points;
  for (int z = 0; z < 5; ++z)
    for (int y = 0; y < 3; ++y)
      for (int x = 0; x < 3; ++x) points.emplace_back(x * spacing, y * spacing, z * spacing);
  auto settings = particles(points, 3e-5, 1e-3);
  for (uint32_t a = 0; a < points.size(); ++a) {
    if (points[a].z() == 0 || points[a].z() > 3.5f * spacing) testing::fix(*settings, a, 0);
    for (uint32_t b = a + 1; b < points.size(); ++b) {
      const btScalar rest = (points[b] - points[a]).length();
      if (rest <= 1.8f * spacing) link(*settings, a, b, 1 / rest, rest);
    }
  }
  for (Integrator kind : {Integrator::Pbd, Integrator::Xpbd}) {
    Bench bench(settings, kind);
    bench.parameters.constraintIterations = 16;
    for (uint32_t i = 0; i < points.size(); ++i)
      bench.place(i, btVector3(points[i].x(), points[i].y(), 2 * points[i].z()));
    for (int s = 0; s < 300; ++s) ASSERT_TRUE(bench.step(1e-3).finite);
    double worst = 0;
    for (const Spring& s : settings->springs)
      worst = std::max<double>(
          worst, (bench.state.positions[s.b] - bench.state.positions[s.a]).length() / s.restLength);
    EXPECT_LT(worst, 3) << toString(kind);
    RecordProperty(std::string(toString(kind)) + "_worst_stretch", std::to_string(worst));
  }
}

// --- stability: a stiff chain at 50× the explicit limit -----------------------------------------

/// A chain of `free` particles h = 1 cm apart hanging from a fixed one, springs to the next and
/// the one after, stiff (k = 1000 N/m at 1 g), lightly damped; zigzag (every other particle
/// off the axis by h/2: non-linear springs) or straight (motion along the axis: linear springs).
std::shared_ptr<MuscleSettings> stiffChain(int free, bool zigzag) {
  const btScalar h = 0.01;
  std::vector<btVector3> points;
  for (int i = 0; i <= free; ++i) points.emplace_back(h * i, zigzag ? (i % 2) * h / 2 : 0, 0);
  auto settings = particles(points, 1e-3, 1e-3);
  testing::fix(*settings, 0, 0);
  for (uint32_t a = 0; a < points.size(); ++a)
    for (uint32_t b = a + 1; b < std::min<size_t>(a + 3, points.size()); ++b)
      link(*settings, a, b, 1000, (points[b] - points[a]).length());
  return settings;
}

/// Energy of `kind` over 200 steps of `multiple` × the Verlet limit from the chain displaced at
/// random by up to 1 mm (along the axis only when straight): {start, largest, end}, or NaN.
std::array<double, 3> chainEnergies(Integrator kind, bool zigzag, btScalar multiple) {
  auto chain = stiffChain(8, zigzag);
  const btScalar dt = multiple * stableTimeStep(*chain, Integrator::Verlet);
  Bench bench(chain, kind);
  std::mt19937 random(11);
  std::uniform_real_distribution<btScalar> noise(-1e-3f, 1e-3f);
  for (uint32_t i : bench.state.freeParticles) {
    const btVector3 offset(noise(random), noise(random), noise(random));
    bench.place(i, bench.state.positions[i] + (zigzag ? offset : btVector3(offset.x(), 0, 0)));
  }
  std::array<double, 3> energies;
  energies.fill(bench.energy(dt));
  for (int s = 0; s < 200; ++s) {
    if (!bench.step(dt).finite) return {energies[0], NAN, NAN};
    energies[1] = std::max(energies[1], energies[2] = bench.energy(dt));
  }
  return energies;
}

TEST(Stability, ImplicitIntegratorsHoldAtFiftyTimesTheExplicitLimit) {
  // Straight chain: linear springs, where A-stability promises it for all three. Zigzag:
  // non-linear springs; backward Euler and BDF2 damp the stiff modes, the midpoint rule holds
  // through its θ = 1/2 + O(dt) damping (the plain midpoint rule blew up here at 50×).
  struct Case {
    Integrator kind;
    bool zigzag;
    btScalar multiple;
  };
  for (const Case& c :
       {Case{Integrator::ImplicitEuler, false, 50}, Case{Integrator::Bdf2, false, 50},
        Case{Integrator::ImplicitMidpoint, false, 50}, Case{Integrator::ImplicitEuler, true, 50},
        Case{Integrator::Bdf2, true, 50}, Case{Integrator::ImplicitMidpoint, true, 50}}) {
    const auto [start, largest, end] = chainEnergies(c.kind, c.zigzag, c.multiple);
    const std::string label = std::string(toString(c.kind)) + (c.zigzag ? " zigzag" : " straight");
    ASSERT_TRUE(std::isfinite(largest)) << label;
    EXPECT_LE(largest, 1.05 * start) << label << ": energy grew";
    EXPECT_LT(end, start) << label << ": the damping took nothing out";
  }
  for (Integrator kind : {Integrator::ExplicitEuler, Integrator::Verlet})
    for (bool zigzag : {false, true}) {
      const auto [start, largest, end] = chainEnergies(kind, zigzag, 50);
      EXPECT_FALSE(largest < 1e3 * start) << toString(kind) << " should blow up";
    }
}

TEST(Stability, ExplicitBoundsFollowTheStabilityRegions) {
  // Undamped: Euler and RK2 miss the imaginary axis (no stable dt beyond the round-off margin
  // of the test), RK4 reaches 2√2/ω, beyond Verlet's 2/ω; implicit and position-based ones have
  // no bound.
  auto chain = stiffChain(4, true);
  chain->damping = 0;
  const btScalar verlet = stableTimeStep(*chain, Integrator::Verlet);
  EXPECT_LT(stableTimeStep(*chain, Integrator::ExplicitEuler), 0.01 * verlet);
  EXPECT_LT(stableTimeStep(*chain, Integrator::Rk2), 0.01 * verlet);
  EXPECT_NEAR(stableTimeStep(*chain, Integrator::Rk4) / verlet, std::sqrt(2.0), 1e-3);
  for (Integrator kind : {Integrator::ImplicitEuler, Integrator::ImplicitMidpoint, Integrator::Bdf2,
                          Integrator::Pbd, Integrator::Xpbd, Integrator::Projective})
    EXPECT_TRUE(std::isinf(stableTimeStep(*chain, kind))) << toString(kind);
}

// --- Verlet's step particle by particle -----------------------------------------------------

TEST(VerletStep, EveryParticleTakesTheFormulasStepBitForBit) {
  // x⁺ = x + ((x − x⁻)·keep + F·scale) with btVector3's operators, particle by particle in the
  // order of the free list (the plain loop), against advance (its vector path and scalar tail):
  // positions and previous (x with its w lane) bit for bit and the displacement sum, for 0 to 17
  // free particles in shuffled order out of 24; fixed ones untouched.
  std::mt19937 random(23);
  std::normal_distribution<double> normal;
  const auto vector = [&](double scale) {
    btVector3 v;
    for (int axis = 0; axis < 4; ++axis) v.m_floats[axis] = btScalar(scale * normal(random));
    return v;
  };
  const auto same = [](const btVector3& a, const btVector3& b) {
    return std::memcmp(a.m_floats, b.m_floats, sizeof(a.m_floats)) == 0;
  };
  constexpr uint32_t kParticles = 24;
  std::vector<uint32_t> order(kParticles);
  for (uint32_t i = 0; i < kParticles; ++i) order[i] = i;
  for (size_t count = 0; count < 18; ++count) {
    const btScalar mass = btScalar(1e-3), damping = count % 3 ? btScalar(2e-3) : 0;
    const btScalar dt = btScalar(1e-3), previousDt = count % 2 ? btScalar(1.3e-3) : dt;
    MuscleState muscle;
    muscle.settings =
        particles(std::vector<btVector3>(kParticles, btVector3(0, 0, 0)), mass, damping);
    for (uint32_t i = 0; i < kParticles; ++i) {
      muscle.positions.push_back(vector(0.1));
      muscle.previous.push_back(muscle.positions.back() + vector(1e-4));
      muscle.forces.push_back(vector(1e-2));
    }
    std::shuffle(order.begin(), order.end(), random);
    muscle.freeParticles.assign(order.begin(), order.begin() + static_cast<ptrdiff_t>(count));
    const btScalar gamma = damping * dt / (2 * mass);
    const btScalar forceScale = dt * dt / (mass * (1 + gamma));
    const btScalar keep = (1 - gamma) / (1 + gamma) * dt / previousDt;
    std::vector<btVector3> positions = muscle.positions, previous = muscle.previous;
    double displacement = 0;
    for (uint32_t i : muscle.freeParticles) {
      const btVector3 step = (positions[i] - previous[i]) * keep + muscle.forces[i] * forceScale;
      previous[i] = positions[i];
      positions[i] = positions[i] + step;
      displacement += step.length();
    }
    const IntegrationResult result =
        integratorFor(Integrator::Verlet)
            .advance(muscle.integrated(false), MuscleSystemDef{}, dt, previousDt);
    EXPECT_TRUE(result.finite);
    // The vector path sums in four partial sums: equal up to the rounding of the sums.
    EXPECT_NEAR(result.displacement, displacement, 1e-14 * displacement) << count << " free";
    for (uint32_t i = 0; i < kParticles; ++i) {
      EXPECT_TRUE(same(muscle.positions[i], positions[i])) << "particle " << i << " of " << count;
      EXPECT_TRUE(same(muscle.previous[i], previous[i])) << "particle " << i << " of " << count;
    }
  }
}

// --- eq 5.1 for Verlet's centred damping ---------------------------------------------------

TEST(AdaptiveStep, CentredBoundIsTightForVerletsStep) {
  // Force along the velocity: Verlet's step at the bound's dt moves the particle exactly r,
  // |Δx| = ((1 − γ)·v·dt + F·dt²/m)/(1 + γ), γ = c·dt/(2m); the uncentred bound lets it
  // overshoot when v·dt > r (here by 0.5 %).
  const double force = 1e-3, speed = 0.3, radius = 1e-3, mass = 1e-4, damping = 5e-3;
  for (bool centred : {true, false}) {
    const double dt = largestSafeTimeStep(btScalar(force), btScalar(speed), btScalar(radius),
                                          btScalar(mass), btScalar(damping), centred);
    const double gamma = damping * dt / (2 * mass);
    const double step = ((1 - gamma) * speed * dt + force * dt * dt / mass) / (1 + gamma);
    if (centred)
      EXPECT_NEAR(step, radius, 1e-4 * radius);
    else
      EXPECT_GT(step, radius);
  }
}

/// Eq 5.1's minimum the plain way: largestSafeTimeStep particle by particle, in order.
btScalar referenceTimeStep(const MuscleState& muscle, btScalar previousDt) {
  const MuscleSettings& settings = *muscle.settings;
  const btScalar inversePreviousDt = previousDt > 0 ? 1 / previousDt : 0;
  btScalar dt = muscle.stableTimeStep;
  for (uint32_t i : muscle.freeParticles)
    dt = std::min(dt, largestSafeTimeStep(
                          muscle.forces[i].length(),
                          (muscle.positions[i] - muscle.previous[i]).length() * inversePreviousDt,
                          muscle.stepRadius[i], settings.particleMass, settings.damping,
                          muscle.preparedFor == Integrator::Verlet));
  return dt;
}

/// The bits of a value, so that ±0 and NaN compare exactly.
auto bits(btScalar value) {
  return std::bit_cast<std::conditional_t<kFloat, uint32_t, uint64_t>>(value);
}

/// The kernels adaptiveTimeStep can run on in this build on this CPU.
std::vector<SpringKernel> availableKernels() {
  std::vector<SpringKernel> kernels;
  for (SpringKernel kernel : {SpringKernel::scalar, SpringKernel::sse2, SpringKernel::avx2})
    if (springKernelAvailable(kernel)) kernels.push_back(kernel);
  return kernels;
}

/// adaptiveTimeStep bit for bit against the reference on `muscle`, on every available kernel:
/// the minimum over its free particles, and each particle's own bound (the particle 8 to 15
/// times over, so that every lane of the AVX2 and SSE2 paths and the scalar tail compute it).
/// Returns how many bounds were finite.
size_t expectReferenceTimeSteps(MuscleState& muscle, btScalar previousDt) {
  EXPECT_EQ(bits(adaptiveTimeStep(*muscle.settings, muscle, muscle.centredDamping(), previousDt)),
            bits(referenceTimeStep(muscle, previousDt)));
  const std::vector<uint32_t> free = muscle.freeParticles;
  const btScalar stable = muscle.stableTimeStep;
  muscle.stableTimeStep = std::numeric_limits<btScalar>::infinity();
  size_t finite = 0;
  for (size_t k = 0; k < free.size(); ++k) {
    muscle.freeParticles.assign(8 + k % 8, free[k]);
    const btScalar own = referenceTimeStep(muscle, previousDt);
    for (SpringKernel kernel : availableKernels())
      EXPECT_EQ(bits(adaptiveTimeStep(*muscle.settings, muscle, muscle.centredDamping(), previousDt,
                                      kernel)),
                bits(own))
          << "particle " << free[k] << " kernel " << springKernelName(kernel);
    finite += std::isfinite(own);
  }
  muscle.freeParticles = free;
  muscle.stableTimeStep = stable;
  return finite;
}

TEST(AdaptiveStep, EveryParticlesBoundIsTheReferencesBitForBit) {
  // Forces, displacements, radii, masses and damping over orders of magnitude (a < 0, b < 0 and a
  // negative discriminant all occur), zeros, a NaN force; Verlet (centred) and not; no previous
  // dt; 0 to 17 free particles for the minimum.
  std::mt19937 random(51);
  const auto magnitude = [&](double low, double high) {
    return btScalar(std::pow(10.0, std::uniform_real_distribution<double>(low, high)(random)));
  };
  const auto vector = [&](double low, double high) {  // draws in sequence: any compiler, one run
    std::normal_distribution<double> normal;
    btVector3 v;
    for (int axis = 0; axis < 3; ++axis) v[axis] = btScalar(normal(random));
    return v * magnitude(low, high);
  };
  constexpr uint32_t kParticles = 64;
  size_t finite = 0, bounds = 0;
  for (int round = 0; round < 40; ++round) {
    MuscleState muscle;
    const btScalar mass = magnitude(-6, -2);
    const btScalar damping = round % 5 == 0 ? 0 : magnitude(-5, 0);
    muscle.settings =
        particles(std::vector<btVector3>(kParticles, btVector3(0, 0, 0)), mass, damping);
    muscle.preparedFor = round % 2 ? Integrator::Verlet : Integrator::SemiImplicitEuler;
    muscle.stableTimeStep =
        round % 3 ? std::numeric_limits<btScalar>::infinity() : magnitude(-5, -3);
    for (uint32_t i = 0; i < kParticles; ++i) {
      muscle.positions.push_back(vector(-3, 0));
      muscle.previous.push_back(muscle.positions.back() -
                                (i % 7 ? vector(-9, -3) : btVector3(0, 0, 0)));
      muscle.forces.push_back(i % 11 ? vector(-8, 1) : btVector3(0, 0, 0));
      muscle.stepRadius.push_back(i % 13 ? magnitude(-4, -2) : 0);
      muscle.freeParticles.push_back(i);
    }
    if (round == 7) muscle.forces[5].setX(std::numeric_limits<btScalar>::quiet_NaN());
    const btScalar previousDt = round % 4 ? magnitude(-5, -2) : 0;
    finite += expectReferenceTimeSteps(muscle, previousDt);
    bounds += kParticles;
    for (size_t count = 0; count < 18; ++count) {
      muscle.freeParticles.resize(count);
      for (SpringKernel kernel : availableKernels())
        EXPECT_EQ(bits(adaptiveTimeStep(*muscle.settings, muscle, muscle.centredDamping(),
                                        previousDt, kernel)),
                  bits(referenceTimeStep(muscle, previousDt)))
            << count << " particles, kernel " << springKernelName(kernel);
    }
  }
  EXPECT_GT(finite, bounds / 4);   // roots taken
  EXPECT_LT(finite, bounds - 40);  // and bounds that hold for every dt
}

/// The grid muscle's particles (GridMuscle.h) with the free ones moved by up to 40 % of the
/// spacing at random (`seed`), none pushed.
void scatterGrid(const MuscleSettings& settings, unsigned seed, ParticleState& particles,
                 ContactState& contact) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> offset(-0.0016f, 0.0016f);
  particles.positions = settings.restPositions;
  for (uint32_t i = 0; i < settings.particleCount(); ++i)
    if (!settings.isFixed(i))
      particles.positions[i] += btVector3(offset(random), offset(random), offset(random));
  contact.pushedLast.assign(settings.particleCount(), 0);
}

TEST(StrainLimit, EveryKernelShortensTheSameSpringsToTheSameBits) {
  // Some of the grid's springs beyond a limit of 1.3 (free–free, free–fixed and fixed–fixed ones,
  // in blocks of eight with and without one, and in the tail after the last eight), shortened in
  // up to four passes on each kernel against the scalar one, bit for bit.
  auto settings = std::make_shared<MuscleSettings>(*testing::gridMuscle());
  settings->strainLimit = btScalar(1.3);
  for (unsigned seed = 1; seed <= 20; ++seed) {
    ParticleState reference;
    ContactState referenceContact;
    scatterGrid(*settings, seed, reference, referenceContact);
    size_t quietBlocks = 0;
    for (size_t first = 0; first + 8 <= settings->springs.size(); first += 8) {
      bool beyond = false;
      for (size_t s = first; s < first + 8; ++s) {
        const Spring& spring = settings->springs[s];
        beyond = beyond || reference.positions[spring.a].distance(reference.positions[spring.b]) >
                               settings->strainLimit * spring.restLength;
      }
      quietBlocks += !beyond;
    }
    EXPECT_GT(quietBlocks, 0u) << "seed " << seed;
    const size_t shortened =
        limitStrain(*settings, reference, referenceContact, 4, SpringKernel::scalar);
    EXPECT_GT(shortened, 0u) << "seed " << seed;
    for (SpringKernel kernel : availableKernels()) {
      ParticleState particles;
      ContactState contact;
      scatterGrid(*settings, seed, particles, contact);
      EXPECT_EQ(limitStrain(*settings, particles, contact, 4, kernel), shortened);
      for (uint32_t i = 0; i < settings->particleCount(); ++i) {
        for (int axis = 0; axis < 3; ++axis)
          EXPECT_EQ(bits(particles.positions[i][axis]), bits(reference.positions[i][axis]))
              << "seed " << seed << " particle " << i << " kernel " << springKernelName(kernel);
        EXPECT_EQ(contact.pushedLast[i], referenceContact.pushedLast[i]);
      }
    }
  }
}

TEST(AdaptiveStep, ThighStatesGiveTheReferencesBoundsBitForBit) {
  // The states thigh13 leaves after two poses (every muscle, spring forces and displacements of
  // a real run), at the system's last dt.
  LoadedScene scene;
  const PreparedScene& prepared = testing::preparedThigh(scene);
  MuscleSystemDef parameters = scene.simulation;
  parameters.threads = 1;
  parameters.stepSettings.iterations = 20;
  MuscleSystem system(parameters);
  std::vector<BoneHandle> bones;
  for (const auto& bone : prepared.bones) bones.push_back(system.addBone(bone));
  for (const auto& muscle : prepared.muscles) system.addMuscle(muscle, bones);
  for (int pose = 1; pose <= 2; ++pose) {
    for (size_t b = 0; b < bones.size(); ++b)
      system.setBoneTransform(bones[b], scene.bonePose(b, pose % scene.poseCount));
    system.step();
  }
  auto& impl = MuscleSystemAccess::impl(system);
  ASSERT_GT(impl.previousDt, 0);
  size_t finite = 0, bounds = 0;
  for (auto& muscle : impl.muscles.states) {
    finite += expectReferenceTimeSteps(*muscle, impl.previousDt);
    bounds += muscle->freeParticles.size();
  }
  EXPECT_GT(finite, bounds / 2);
}

// --- BDF2's remembered velocity: pre-transform and contacts ----------------------------------

TEST(Bdf2History, FollowsThePretransformAndContacts) {
  // One free particle without forces or damping coasting at v0: BDF2 is exact for it. The
  // bones' pre-transform turns x, x(t−dt′) and v (as MuscleSystem does); a contact sets
  // x(t−dt′) = x and v = 0. BDF2's own v(t−dt′) must follow, or it pushes the particle off.
  auto settings = particles({{0, 0, 0}, {0.01f, 0, 0}}, 1e-3, 0);
  testing::fix(*settings, 0, 0);
  settings->nearestBone[1] = 0;
  Bench bench(settings, Integrator::Bdf2);
  const btVector3 v0(0.1f, 0.02f, 0);
  const btScalar dt = 1e-3f;
  bench.state.velocities[1] = v0;
  for (int s = 0; s < 3; ++s) bench.step(dt);
  const btTransform turn(btQuaternion(btVector3(0, 0, 1), 0.3f));
  bench.state.boneDeltas.assign(1, turn);
  bench.state.positions[1] = turn * bench.state.positions[1];
  bench.state.previous[1] = turn * bench.state.previous[1];
  bench.state.velocities[1] = turn.getBasis() * v0;
  bench.step(dt);
  const btVector3 turned = turn.getBasis() * v0;
  EXPECT_NEAR((bench.state.velocities[1] - turned).length(), 0, 1e-5 * v0.length());
  const btVector3 moved = bench.state.positions[1] - bench.state.previous[1];
  EXPECT_NEAR((moved - turned * dt).length(), 0, 1e-5 * v0.length() * dt);

  bench.state.boneDeltas.assign(1, btTransform::getIdentity());
  bench.state.previous[1] = bench.state.positions[1];
  bench.state.velocities[1].setZero();
  const btVector3 stopped = bench.state.positions[1];
  bench.step(dt);
  EXPECT_EQ(bench.state.velocities[1], btVector3(0, 0, 0));
  EXPECT_EQ(bench.state.positions[1], stopped);
}

// --- projective: near the equilibrium in far fewer iterations ----------------------------------

/// fusiform (resolution 40: 2 560 particles, springs by volume and the volume terms), prepared
/// once.
const PreparedScene& preparedFusiform(LoadedScene& scene) {
  static const LoadedScene loaded = loadScene("fusiform");
  static const PreparedScene prepared =
      prepareScene(loaded.bones, loaded.muscles, loaded.simulation.seed);
  scene = loaded;
  return prepared;
}

/// fusiform stepped from rest to pose 1 by `kind` in `iterations` iterations, the bones moving
/// over the first `motion` of them, stop `rule` (epsilon 10 nm for Converged, which must stop the
/// step before its cap): the particles.
std::vector<btVector3> fusiformPose(Integrator kind, StopRule rule, int iterations, int motion) {
  LoadedScene scene;
  const PreparedScene& prepared = preparedFusiform(scene);
  MuscleSystemDef parameters = scene.simulation;
  parameters.threads = 1;
  parameters.integrator = kind;
  parameters.stepSettings.stopRule = rule;
  parameters.stepSettings.epsilon = 1e-8;
  parameters.stepSettings.iterations = iterations;
  parameters.stepSettings.motionFraction =
      static_cast<btScalar>(motion) / static_cast<btScalar>(iterations);
  MuscleSystem system(parameters);
  std::vector<BoneHandle> bones;
  for (const auto& bone : prepared.bones) bones.push_back(system.addBone(bone));
  const MuscleHandle muscle = system.addMuscle(prepared.muscles[0], bones);
  for (size_t b = 0; b < bones.size(); ++b) system.setBoneTransform(bones[b], scene.bonePose(b, 1));
  system.step();
  EXPECT_FALSE(system.lastStep().nan || system.lastStep().exploded) << toString(kind);
  if (rule == StopRule::Converged) {
    EXPECT_LT(system.lastStep().iterations, iterations);
  }
  const auto x = system.positions(muscle);
  return {x.begin(), x.end()};
}

/// RMS distance between two sets of the same particles [m].
double rmsDistance(const std::vector<btVector3>& a, const std::vector<btVector3>& b) {
  double sum = 0;
  for (size_t i = 0; i < a.size(); ++i) sum += (a[i] - b[i]).length2();
  return std::sqrt(sum / static_cast<double>(a.size()));
}

/// The largest |z_i − zRef_i| over x, y, z (zRef from Eigen in double, particle order) relative
/// to the largest |zRef_i|; z in the factor's row order.
double factorSolveError(ProjectiveFactor& factor, const Eigen::SparseMatrix<double>& lower,
                        const Eigen::MatrixX3d& b) {
  const Eigen::SimplicialLLT<Eigen::SparseMatrix<double>> reference(lower);
  const Eigen::MatrixX3d expected = reference.solve(b);
  std::vector<btVector3> z(factor.size());
  for (size_t k = 0; k < factor.size(); ++k)
    z[factor.row(k)] = btVector3(static_cast<btScalar>(b(k, 0)), static_cast<btScalar>(b(k, 1)),
                                 static_cast<btScalar>(b(k, 2)));
  factor.solveInPlace(z.data());
  double error = 0;
  for (size_t k = 0; k < factor.size(); ++k)
    for (int c = 0; c < 3; ++c)
      error = std::max(error, std::abs(z[factor.row(k)][c] - expected(static_cast<int>(k), c)));
  return error / expected.cwiseAbs().maxCoeff();
}

TEST(ProjectiveFactor, SolvesAsEigensFactorThroughWeightsThatComeAndGo) {
  // A random sparse graph's Laplacian plus a small diagonal (positive definite; condition about
  // 10³), its pattern unlike a grid's: the factor's own elimination-tree analysis, its float solve
  // and its updates must match Eigen's double factor of A + W to float precision (about 1e-7 ×
  // the condition). A wrong pattern or a missed update is off by order 1.
  constexpr int kSize = 300;
  std::mt19937 random(7);
  std::uniform_int_distribution<int> other(0, kSize - 1);
  std::uniform_real_distribution<double> weight(0.5, 2);
  std::vector<Eigen::Triplet<double>> entries;
  for (int i = 0; i < kSize; ++i) {
    entries.emplace_back(i, i, 0.01);
    for (int e = 0; e < 3; ++e) {
      const int j = other(random);
      if (j == i) continue;
      const double k = weight(random);
      entries.emplace_back(i, i, k);
      entries.emplace_back(j, j, k);
      entries.emplace_back(std::max(i, j), std::min(i, j), -k);
    }
  }
  Eigen::SparseMatrix<double> lower(kSize, kSize);
  lower.setFromTriplets(entries.begin(), entries.end());
  Eigen::MatrixX3d b(kSize, 3);
  std::uniform_real_distribution<double> unit(-1, 1);
  for (int i = 0; i < kSize; ++i)
    for (int c = 0; c < 3; ++c) b(i, c) = unit(random);
  ProjectiveFactor factor(lower);
  EXPECT_LT(factorSolveError(factor, lower, b), 1e-4);
  // W on rows of particles 0, 10, ..., 290: one by one (updates), then half of them leave
  // (downdates), then all rows at once (new values).
  Eigen::SparseMatrix<double> withWeights = lower;
  const auto setWeight = [&](int particle, double w) {
    withWeights.coeffRef(particle, particle) += w - factor.weight(factor.row(particle));
    factor.setWeight(factor.row(particle), w);
  };
  for (int i = 0; i < kSize; i += 10) setWeight(i, 10 * factor.matrixDiagonal(factor.row(i)));
  factor.update();
  EXPECT_LT(factorSolveError(factor, withWeights, b), 1e-4);
  for (int i = 0; i < kSize; i += 20) setWeight(i, 0);
  factor.update();
  EXPECT_LT(factorSolveError(factor, withWeights, b), 1e-4);
  for (int i = 0; i < kSize; ++i) setWeight(i, 3 * factor.matrixDiagonal(factor.row(i)));
  factor.update();
  EXPECT_LT(factorSolveError(factor, withWeights, b), 1e-4);
  EXPECT_GT(factorSolveError(factor, lower, b), 0.1);  // the check sees W
}

TEST(ProjectiveFactor, SolvesThroughColumnsThatShareTheirRows) {
  // Two dense blocks joined by a chain: each block's columns form one run that reads one list of
  // rows (each column from one further on), the chain's columns their own. A column reading
  // another run's rows, or one off in its list, is off by order 1.
  constexpr int kBlock = 12, kSize = 2 * kBlock + 6;
  std::vector<Eigen::Triplet<double>> entries;
  const auto couple = [&](int i, int j, double k) {
    entries.emplace_back(i, i, k);
    entries.emplace_back(j, j, k);
    entries.emplace_back(std::max(i, j), std::min(i, j), -k);
  };
  for (int base : {0, kBlock + 6})
    for (int i = base; i < base + kBlock; ++i)
      for (int j = i + 1; j < base + kBlock; ++j) couple(i, j, 1 + 0.1 * ((i * 7 + j) % 5));
  for (int i = kBlock - 1; i < kBlock + 6; ++i) couple(i, i + 1, 2);
  for (int i = 0; i < kSize; ++i) entries.emplace_back(i, i, 0.05);
  Eigen::SparseMatrix<double> lower(kSize, kSize);
  lower.setFromTriplets(entries.begin(), entries.end());
  Eigen::MatrixX3d b(kSize, 3);
  for (int i = 0; i < kSize; ++i)
    for (int c = 0; c < 3; ++c) b(i, c) = std::sin(1.0 + i + 7.0 * c);
  ProjectiveFactor factor(lower);
  EXPECT_LT(factorSolveError(factor, lower, b), 1e-4);
  Eigen::SparseMatrix<double> withWeights = lower;
  for (int i = 0; i < kSize; i += 3) {
    withWeights.coeffRef(i, i) += 4;
    factor.setWeight(factor.row(i), 4);
  }
  factor.update();
  EXPECT_LT(factorSolveError(factor, withWeights, b), 1e-4);
}

/// The Laplacian of a grid of side³ particles, each tied to its six neighbours (stiffness 1 to
/// 1.4), plus 0.05 on the diagonal: a pattern like a muscle's, whose factor has runs of columns
/// of every length with many rows below them.
Eigen::SparseMatrix<double> gridLaplacian(int side) {
  std::vector<Eigen::Triplet<double>> entries;
  const auto index = [side](int i, int j, int k) { return (i * side + j) * side + k; };
  for (int i = 0; i < side; ++i)
    for (int j = 0; j < side; ++j)
      for (int k = 0; k < side; ++k) {
        const int a = index(i, j, k);
        entries.emplace_back(a, a, 0.05);
        for (const int b :
             {i + 1 < side ? index(i + 1, j, k) : -1, j + 1 < side ? index(i, j + 1, k) : -1,
              k + 1 < side ? index(i, j, k + 1) : -1}) {
          if (b < 0) continue;
          const double stiffness = 1 + 0.1 * ((a * 7 + b) % 5);
          entries.emplace_back(a, a, stiffness);
          entries.emplace_back(b, b, stiffness);
          entries.emplace_back(b, a, -stiffness);
        }
      }
  Eigen::SparseMatrix<double> lower(side * side * side, side * side * side);
  lower.setFromTriplets(entries.begin(), entries.end());
  return lower;
}

TEST(ProjectiveFactor, SolvesWithTheSameBitsOnSseAndAvx2) {
  // The AVX2 solve takes a run's columns in blocks of 8, 4, 2 and 1 onto the rows below it and
  // gathers those rows for the backward pass; per row it must subtract the same products in the
  // same order as the SSE solve, to the bit.
  if (!springKernelAvailable(SpringKernel::avx2) || !springKernelAvailable(SpringKernel::sse2))
    GTEST_SKIP() << "needs SSE2 and AVX2";
  const Eigen::SparseMatrix<double> lower = gridLaplacian(9);
  Eigen::MatrixX3d b(lower.rows(), 3);
  for (int i = 0; i < lower.rows(); ++i)
    for (int c = 0; c < 3; ++c) b(i, c) = std::cos(0.3 * i + 2.0 * c);
  ProjectiveFactor factor(lower);
  std::vector<btVector3> sse(factor.size());
  for (size_t k = 0; k < factor.size(); ++k)
    sse[factor.row(k)] = btVector3(static_cast<btScalar>(b(k, 0)), static_cast<btScalar>(b(k, 1)),
                                   static_cast<btScalar>(b(k, 2)));
  const std::vector<btVector3> input = sse;
  std::vector<btVector3> avx2 = sse;
  factor.solveInPlace(sse.data(), SpringKernel::sse2);
  factor.solveInPlace(avx2.data(), SpringKernel::avx2);
  EXPECT_NE(bits(sse[0][0]), bits(input[0][0]));  // solved
  EXPECT_LT(factorSolveError(factor, lower, b), 1e-4);
  size_t differing = 0;
  for (size_t r = 0; r < factor.size(); ++r)
    for (int c = 0; c < 3; ++c) differing += bits(sse[r][c]) != bits(avx2[r][c]);
  EXPECT_EQ(differing, 0u);
}

TEST(ProjectiveFactor, RefusesAMatrixThatIsNotPositiveDefinite) {
  Eigen::SparseMatrix<double> lower(2, 2);
  const std::vector<Eigen::Triplet<double>> entries{{0, 0, 1}, {1, 1, 1}, {1, 0, 2}};
  lower.setFromTriplets(entries.begin(), entries.end());
  EXPECT_THROW(ProjectiveFactor{lower}, InputError);
}

TEST(Projective, ComesWithinTheEquilibriumToleranceInTenIterations) {
  // The equilibrium does not depend on the iteration that finds it: the projective step run
  // until its mean step is below 10 nm is the reference (about 650 iterations; a step
  // (A + W)⁻¹·F that small leaves forces F ≈ 0 whatever the matrix). Its 20 000-iteration state
  // lies 0.041 mm from Verlet run to 1 nm, the reference before, which took 50 times as long.
  // The target is a pose within 0.5 mm of it; the projective step must come within half
  // that in 10 iterations (the bones jump in the first), where Verlet with ten times as many
  // (the bones over 10) must not: the whole-muscle modes that a local step needs thousands of
  // iterations for are what the global step solves.
  const auto equilibrium = fusiformPose(Integrator::Projective, StopRule::Converged, 20000, 1);
  const double projective =
      rmsDistance(fusiformPose(Integrator::Projective, StopRule::Iterations, 10, 1), equilibrium);
  const double verlet =
      rmsDistance(fusiformPose(Integrator::Verlet, StopRule::Iterations, 100, 10), equilibrium);
  RecordProperty("projective_mm", std::to_string(1e3 * projective));
  RecordProperty("verlet_mm", std::to_string(1e3 * verlet));
  EXPECT_LT(projective, 0.25e-3);
  EXPECT_GT(verlet, 0.5e-3);
}

/// The projective step's residual |(A + W)·Δ − F| at its largest over the free particles [N]:
/// A the springs' matrix (a spring to a fixed particle adds to its free end's diagonal), W
/// 10·A_ii on the `held` particles (projectiveContactWeight 10).
double projectiveResidual(const MuscleState& state, const std::vector<btVector3>& step,
                          const std::vector<bool>& held) {
  const MuscleSettings& settings = *state.settings;
  std::vector<btVector3> product(step.size(), btVector3(0, 0, 0));
  std::vector<double> diagonal(step.size(), 0);
  for (const Spring& spring : settings.springs) {
    const btVector3 difference = step[spring.a] - step[spring.b];
    product[spring.a] += difference * spring.stiffness;
    product[spring.b] -= difference * spring.stiffness;
    diagonal[spring.a] += spring.stiffness;
    diagonal[spring.b] += spring.stiffness;
  }
  double worst = 0;
  for (uint32_t i : state.freeParticles) {
    const btScalar weight = held[i] ? static_cast<btScalar>(10 * diagonal[i]) : 0;
    worst = std::max<double>(worst, (product[i] + step[i] * weight - state.forces[i]).length());
  }
  return worst;
}

TEST(Projective, TheStepSolvesWithTheContactsHeldAfterUpdatesAndNewRows) {
  // Contacts that come and go change A + W's diagonal, and the factor follows by rank-one
  // updates and downdates (a few rows) or by new rows of L (many): whichever, the step from a
  // fixed configuration with ρ = 0 must be Δ = (A + W)⁻¹·F for the contacts held at the time.
  // A 7 × 7 × 7 grid, its z = 0 layer fixed: the top two layers pushed at once (98 rows: new
  // rows of L, cheaper than 98 updates), then five single particles (updates), which leave one by
  // one 1 000 iterations later (downdates) while the top layers stay pushed.
  constexpr int kSide = 7;
  std::vector<btVector3> points;
  for (int z = 0; z < kSide; ++z)
    for (int y = 0; y < kSide; ++y)
      for (int x = 0; x < kSide; ++x) points.emplace_back(x * 0.01f, y * 0.01f, z * 0.01f);
  auto settings = particles(points, 1e-4, 0);
  for (uint32_t a = 0; a < points.size(); ++a) {
    if (points[a].z() == 0) testing::fix(*settings, a, 0);
    for (uint32_t b = a + 1; b < points.size(); ++b) {
      const btScalar rest = (points[b] - points[a]).length();
      if (rest < 0.015f) link(*settings, a, b, 100 / rest, rest);
    }
  }
  Bench bench(settings, Integrator::Projective);
  bench.parameters.projectiveRho = 0;
  bench.parameters.projectiveHistory = 0;  // the plain step Δ = (A + W)⁻¹·F
  bench.parameters.projectiveContactWeight = 10;
  bench.state.pushedLast.assign(points.size(), 0);
  // A configuration off rest (a shear growing with height), the same before every step.
  std::vector<btVector3> displaced = points;
  for (btVector3& x : displaced) x += btVector3(0.2f * x.z() * x.z() / 0.06f, 0, 0.001f * x.x());
  std::vector<bool> held(points.size(), false);
  const auto stepWith = [&](const std::vector<uint32_t>& pushed) {
    for (uint32_t i = 0; i < points.size(); ++i) bench.place(i, displaced[i]);
    for (uint32_t i : pushed) bench.state.pushedLast[i] = 1;
    bench.step(1e-3f);
    std::vector<btVector3> step(points.size());
    for (uint32_t i = 0; i < points.size(); ++i) step[i] = bench.state.positions[i] - displaced[i];
    return step;
  };
  std::vector<uint32_t> top;
  for (uint32_t i = 0; i < points.size(); ++i)
    if (i >= (kSide - 2) * kSide * kSide) top.push_back(i);
  for (uint32_t i : top) held[i] = true;
  double force = 0;
  auto step = stepWith(top);
  for (uint32_t i : bench.state.freeParticles)
    force = std::max<double>(force, bench.state.forces[i].length());
  // Float positions hold the step to about 1e-7 of their size: the residual to about 1e-4 of F.
  const double tolerance = 1e-3 * force;
  EXPECT_LT(projectiveResidual(bench.state, step, held), tolerance);
  EXPECT_GT(projectiveResidual(bench.state, step, std::vector<bool>(points.size(), false)),
            100 * tolerance);                           // the check sees W
  const uint32_t singles[] = {60, 117, 171, 200, 222};  // below the top layers
  for (uint32_t single : singles) {
    std::vector<uint32_t> pushed = top;
    pushed.push_back(single);
    held[single] = true;
    step = stepWith(pushed);
    EXPECT_LT(projectiveResidual(bench.state, step, held), tolerance) << single;
  }
  for (int k = 0; k < 1001; ++k) step = stepWith(top);  // each single idles past the hold
  const std::vector<bool> stillHeld = held;
  for (uint32_t single : singles) held[single] = false;
  const double residual = projectiveResidual(bench.state, step, held);
  RecordProperty("residual_of_force", std::to_string(residual / force));
  EXPECT_LT(residual, tolerance);
  EXPECT_GT(projectiveResidual(bench.state, step, stillHeld), 100 * tolerance);
}

// --- every integrator in a MuscleSystem with collision ------------------------------------------

/// A 3 × 3 × 5 block of particles 5 mm apart from z = `base` up, springs between all pairs closer
/// than 1.8 spacings (k = κ/L0, κ = `kappa` N), layer `fixedLayer` (0: the lowest) fixed to bone
/// 0, every particle a 2.5 mm sphere.
std::shared_ptr<MuscleSettings> block(btScalar base = 0, uint32_t fixedLayer = 0,
                                      btScalar kappa = 1) {
  const btScalar spacing = 0.005;
  std::vector<btVector3> points;
  for (int z = 0; z < 5; ++z)
    for (int y = 0; y < 3; ++y)
      for (int x = 0; x < 3; ++x) points.emplace_back(x * spacing, y * spacing, base + z * spacing);
  auto settings = particles(points, 3e-5, 0);
  double stiffnessSum = 0;
  for (uint32_t a = 0; a < points.size(); ++a) {
    settings->flags[a] = kBoundary;
    settings->radii[a] = spacing / 2;
    settings->boundaryParticles.push_back(a);
    settings->nearestBone[a] = 0;
    if (a / 9 == fixedLayer) testing::fix(*settings, a, 0);
    for (uint32_t b = a + 1; b < points.size(); ++b) {
      const btScalar rest = (points[b] - points[a]).length();
      if (rest > 1.8f * spacing) continue;
      link(*settings, a, b, kappa / rest, rest);
      stiffnessSum += kappa / rest;
    }
  }
  // Half the critical damping of the mean spring (as the scenes' dampingScale does).
  settings->damping = static_cast<btScalar>(
      0.5 * std::sqrt(8 * stiffnessSum / settings->springs.size() * settings->particleMass));
  return settings;
}

TEST(Projective, ProvesAnEquilibriumAgainstABone) {
  // A bone sphere inside one side of the block pushes its particles out, and the springs press
  // them back into it: an equilibrium with contacts. The contacts persist (a slop deep) and hold
  // the force into them, so the projective step's fixed point is that equilibrium and the force
  // residual falls to its float floor (below 1e-5 mm here) within the cap. With contacts as
  // projections only (persistent_contacts off) the neighbours of a pushed particle keep a force at
  // the fixed point, and the residual stalls at 5.9e-3 mm at the cap.
  MuscleSystemDef parameters;
  parameters.integrator = Integrator::Projective;
  parameters.projectiveHistory = 0;  // the fixed point of the projective step
  parameters.projectiveContactWeight = 10;
  parameters.persistentContacts = true;
  parameters.stepSettings.stopRule = StopRule::Residual;
  parameters.stepSettings.tolerance = 1e-8;
  parameters.stepSettings.iterations = 3000;
  MuscleSystem system(parameters);
  const BoneHandle bone = system.addBone(testing::makeBone({{0.005, -0.002, 0.012}}, {0.005}));
  const MuscleHandle muscle = system.addMuscle(block(), std::span(&bone, 1));
  system.step();
  const ForceResidual residual = system.forceResidual(muscle);
  RecordProperty("iterations", system.lastStep().iterations);
  RecordProperty("residual_mm", std::to_string(1e3 * residual.rmsDisplacement));
  EXPECT_GT(residual.contactParticles, 0u);
  EXPECT_LT(system.lastStep().iterations, parameters.stepSettings.iterations);
  EXPECT_LT(residual.rmsDisplacement, parameters.stepSettings.tolerance);
  // No particle deeper in the bone than the slop (1 % of its 2.5 mm radius) and rounding.
  for (const btVector3& x : system.positions(muscle))
    EXPECT_GT((x - btVector3(0.005f, -0.002f, 0.012f)).length(), 0.0075f - 0.03f * 0.0025f);
}

/// The force residual (RMS equivalent displacement [m]) of two blocks pressed into each other,
/// solved by the projective integrator with persistent contacts and `pairReactions`: a stiff
/// block fixed at its bottom (z = 0) and one a quarter as stiff fixed at its top, whose bottom
/// layer starts 3 mm into the first block's top layer.
double pressedBlocksResidual(bool pairReactions, int& iterations) {
  MuscleSystemDef parameters;
  parameters.integrator = Integrator::Projective;
  parameters.projectiveHistory = 0;  // the fixed point of the projective step
  parameters.persistentContacts = true;
  parameters.pairReactions = pairReactions;
  parameters.projectiveContactWeight = 1;
  parameters.stepSettings.stopRule = StopRule::Residual;
  parameters.stepSettings.tolerance = 1e-8;
  parameters.stepSettings.iterations = 3000;
  MuscleSystem system(parameters);
  const BoneHandle bone = system.addBone(testing::makeBone({{0.1, 0.1, -0.1}}, {0.001}));
  system.addMuscle(block(), std::span(&bone, 1));
  system.addMuscle(block(0.022f, 4, 0.25f), std::span(&bone, 1));
  system.step();
  iterations = system.lastStep().iterations;
  const ForceResidual residual = system.forceResidual();
  EXPECT_GT(residual.contactParticles, 0u);
  return residual.rmsDisplacement;
}

TEST(Projective, ProvesAnEquilibriumOfTwoMusclesPressedTogether) {
  // Two blocks of unequal stiffness press into each other. The residual holds a contact pair's
  // reaction only where its two particles' pushes balance (equal and opposite along the pair's
  // normal). With pair reactions in the solve the step's fixed point is that equilibrium and the
  // residual reaches its float floor within the cap. With each particle holding its own force
  // into its push, any touching state is a fixed point: the stiff block keeps pressing harder
  // than the soft one pushes back, and the residual stays far above the tolerance.
  int iterations = 0;
  const double paired = pressedBlocksResidual(true, iterations);
  RecordProperty("paired_iterations", iterations);
  RecordProperty("paired_residual_mm", std::to_string(1e3 * paired));
  EXPECT_LT(iterations, 3000);
  EXPECT_LT(paired, 1e-8);
  const double own = pressedBlocksResidual(false, iterations);
  RecordProperty("own_residual_mm", std::to_string(1e3 * own));
  EXPECT_EQ(iterations, 3000);
  EXPECT_GT(own, 100e-8);
}

class EveryIntegrator : public ::testing::TestWithParam<Integrator> {};

TEST_P(EveryIntegrator, StepsWithCollisionFiniteAndWithoutAllocating) {
  MuscleSystemDef parameters;
  parameters.integrator = GetParam();
  parameters.stepSettings.iterations = 10;
  MuscleSystem system(parameters);
  // A bone sphere inside one side of the block, so its particles are pushed out.
  const BoneHandle bone = system.addBone(testing::makeBone({{0.005, -0.002, 0.012}}, {0.005}));
  const MuscleHandle muscle = system.addMuscle(block(), std::span(&bone, 1));
  system.step();
  size_t contacts = system.lastStep().contacts;
  btAlignedAllocSetCustom(testing::countingAlloc, std::free);
  testing::allocationCount = 0;
  testing::countingArmed = true;
  for (int s = 1; s <= 4; ++s) {
    system.setBoneTransform(bone, btTransform(btQuaternion(btVector3(0, 0, 1), 0.03f * s)));
    system.step();
    contacts += system.lastStep().contacts;
    if (system.lastStep().nan) break;
  }
  testing::countingArmed = false;
  btAlignedAllocSetCustom(nullptr, nullptr);
  EXPECT_EQ(testing::allocationCount.load(), 0) << "allocations in step()";
  EXPECT_FALSE(system.lastStep().nan);
  EXPECT_FALSE(system.lastStep().exploded);
  EXPECT_GT(contacts, 0u) << "collision never ran";
  for (const btVector3& x : system.positions(muscle))
    ASSERT_TRUE(std::isfinite(x.x()) && std::isfinite(x.y()) && std::isfinite(x.z()));
}

INSTANTIATE_TEST_SUITE_P(All, EveryIntegrator, ::testing::ValuesIn(everyIntegrator()),
                         [](const auto& param) {
                           std::string name = toString(param.param);
                           std::erase(name, '-');
                           return name;
                         });

}  // namespace
}  // namespace fibremss
