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
// iteration. With persistent contacts (MuscleSystemDef::persistentContacts) a particle the
// last response pushed also gives up the part of its force into the push (what the contact holds,
// contactNormal: the force residual's rule) before the solve, while the response leaves every
// contact a slop deep (kContactSlop) so that it is found again: the step's fixed point is then the
// equilibrium with contacts, where the residual is 0 (the force a pushed particle kept would
// otherwise be spread over its neighbours by (A + W)⁻¹ and moved back by the next push, every
// iteration). A + W acts alike on x, y and z, so one sparse Cholesky factor serves all three
// (ProjectiveFactor.h).
#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "IntegratorsInternal.h"
#include "ProjectiveFactor.h"
#include "collision/CollisionPairs.h"
#include "dynamics/Residual.h"
#include "kernels/ParticleSimd.h"
#include "kernels/SpringForces.h"
#include "kernels/VolumeForces.h"

namespace fibremss {
namespace {

using Matrix = Eigen::SparseMatrix<double>;

/// c, the weight of the volume terms' stand-in in A [1]. Measured on fusiform at 10 iterations
/// per pose (docs/decisions.md, "Solver"): 1.5, 2 and 3 ended 0.108, 0.136 and 0.334
/// mm from the equilibrium; 1 let the volume terms overshoot (+59 % volume).
constexpr double kVolumeWeight = 1.5;

/// A particle leaves W after this many iterations without a push [iterations]. Measured on
/// thigh13 at resolution 20, 10 iterations per pose: a hold of 1 000 refactors in 156 of 1 690
/// muscle-iterations, a hold of 10 in 634, at the same distance to Verlet's equilibrium run.
constexpr uint16_t kContactHold = 1000;
/// kContactHold in a duration step (IntegratedMuscle::movingContacts): a particle leaves W at the
/// first iteration without a push. The haptic probe's far field (2 iterations every 4th tick)
/// held the particles its tool and bed had pushed for 1 000 iterations, the whole run: the
/// muscle stayed where the tool had pressed it and let go of the tool for the slide's last 94
/// ticks; leaving at once, 14 (docs/decisions.md, "The probe's far field lets go").
constexpr uint16_t kMovingContactHold = 0;

/// The last iterations' steps s = x⁺ − x and force changes y = F − F⁺ by row, newest last in a
/// ring (MuscleSystemDef::projectiveHistory): L-BFGS's pairs.
struct StepHistory {
  explicit StepHistory(size_t rows)
      : steps(kMaxProjectiveHistory, std::vector<btVector3>(rows)),
        changes(kMaxProjectiveHistory, std::vector<btVector3>(rows)),
        lastPositions(rows),
        lastForces(rows) {}
  std::vector<std::vector<btVector3>> steps;     ///< s of each pair [m]
  std::vector<std::vector<btVector3>> changes;   ///< y of each pair [N]
  double curvature[kMaxProjectiveHistory] = {};  ///< y·s of each pair [N·m]
  double alpha[kMaxProjectiveHistory] = {};      ///< the two-loop recursion's coefficients [1]
  int size = 0;                                  ///< the ring's length (projectiveHistory)
  int count = 0;                                 ///< pairs held
  int newest = -1;                               ///< ring index of the newest pair
  std::vector<btVector3> lastPositions;          ///< x at the last iteration's forces [m]
  std::vector<btVector3> lastForces;             ///< the forces F there [N]
  bool hasLast = false;                          ///< lastPositions/lastForces hold an iteration

  /// Forgets every pair (the next iteration is the plain projective step).
  void restart() { count = 0; }
};

/// The factor of A + W, the contact weights' hold, the solve's buffer and the L-BFGS history. A
/// rollback of the guard keeps W: it shapes the iteration's path, not its fixed point.
struct ProjectiveWorkspace final : IntegratorWorkspace {
  ProjectiveWorkspace(std::vector<int> freeRows, const Matrix& lowerA)
      : rows(std::move(freeRows)),
        factor(lowerA),
        solution(factor.size(), btVector3(0, 0, 0)),
        forces(factor.size(), btVector3(0, 0, 0)),
        idle(factor.size(), 0),
        pushed(factor.size(), 0),
        history(factor.size()) {}
  std::vector<int> rows;            ///< each particle's free row (freeRows)
  ProjectiveFactor factor;          ///< L of P·(A + W)·Pᵀ
  std::vector<btVector3> solution;  ///< per row: the forces [N], then the step A⁻¹·F [m]
  std::vector<btVector3> forces;    ///< per row: the forces F of this iteration [N]
  std::vector<uint16_t> idle;       ///< per row: iterations since its particle's last push
  std::vector<uint8_t> pushed;      ///< per row: 1 if the last response pushed its particle
  StepHistory history;              ///< L-BFGS's pairs
};

/// Each particle's row among the free particles `free` (−1: fixed).
std::vector<int> freeRows(const MuscleSettings& settings, const std::vector<uint32_t>& free) {
  std::vector<int> rows(settings.particleCount(), -1);
  for (size_t k = 0; k < free.size(); ++k) rows[free[k]] = static_cast<int>(k);
  return rows;
}

/// The entries of the scalar matrix A over the free particles (the 3n × 3n one is A ⊗ I₃) [N/m],
/// `rows` a particle's free row (freeRows), as entry(i, j, value) with i ≥ j; the entries of one
/// place add up, in this order.
template <class Entry>
void matrixEntries(const MuscleSettings& settings, const std::vector<int>& rows, size_t freeCount,
                   Entry&& entry) {
  double trace = 0;
  const auto add = [&](int i, int j, double value) {
    if (i == j) trace += value;
    entry(i, j, value);
  };
  const auto couple = [&](uint32_t a, uint32_t b, double weight) {
    const int ra = rows[a], rb = rows[b];
    if (ra >= 0) add(ra, ra, weight);
    if (rb >= 0) add(rb, rb, weight);
    if (ra >= 0 && rb >= 0) add(std::max(ra, rb), std::min(ra, rb), -weight);
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
  // A tiny shift keeps A definite for particles no spring ties to a fixed one; 1 N/m where no
  // particle has a spring (a muscle of one sphere: it moves by its forces in newtons, as metres).
  const double shift =
      trace > 0 ? 1e-9 * trace / static_cast<double>(std::max<size_t>(1, freeCount)) : 1.0;
  for (size_t k = 0; k < freeCount; ++k) entry(static_cast<int>(k), static_cast<int>(k), shift);
}

/// The lower triangle of A [N/m].
Matrix assemble(const MuscleSettings& settings, const std::vector<int>& rows, size_t freeCount) {
  std::vector<Eigen::Triplet<double>> entries;
  matrixEntries(settings, rows, freeCount,
                [&](int i, int j, double value) { entries.emplace_back(i, j, value); });
  Matrix matrix(static_cast<Eigen::Index>(freeCount), static_cast<Eigen::Index>(freeCount));
  matrix.setFromTriplets(entries.begin(), entries.end());
  return matrix;
}

/// Puts the particles the last response pushed into W (with `contactWeight` times their diagonal
/// entry, MuscleSystemDef::projectiveContactWeight) and takes out those kContactHold
/// (kMovingContactHold in a duration step) iterations without a push (clearing the flags it
/// reads). Returns whether W changed.
bool holdContacts(const IntegratedMuscle& muscle, ProjectiveWorkspace& w, double contactWeight) {
  bool changed = false;
  ProjectiveFactor& factor = w.factor;
  const std::vector<uint32_t>& free = muscle.particles.freeParticles;
  std::vector<uint8_t>& pushedLast = muscle.contact.pushedLast;
  const uint16_t hold = muscle.movingContacts ? kMovingContactHold : kContactHold;
  for (size_t k = 0; k < free.size(); ++k) {
    const int row = factor.row(k);
    uint8_t& pushed = pushedLast[free[k]];
    const bool held = factor.weight(row) > 0;
    w.pushed[row] = pushed;
    if (pushed) {
      pushed = 0;
      w.idle[row] = 0;
      if (held) continue;
      factor.setWeight(row, contactWeight * factor.matrixDiagonal(row));
    } else if (held && ++w.idle[row] > hold) {
      factor.setWeight(row, 0);
    } else {
      continue;
    }
    changed = true;
  }
  return changed;
}

/// w.forces by row: each free particle's force, less the part into its contact where the step
/// holds the contacts (`held`, withoutInto).
void gatherForces(const IntegratedMuscle& muscle, ProjectiveWorkspace& w, bool held) {
  const std::vector<uint32_t>& free = muscle.particles.freeParticles;
  const btVector3* forces = muscle.particles.forces.data();
  const int* rows = w.factor.rows();
  btVector3* gathered = w.forces.data();
  if (!held) {
    for (size_t k = 0; k < free.size(); ++k) gathered[rows[k]] = forces[free[k]];
    return;
  }
  for (size_t k = 0; k < free.size(); ++k)
    gathered[rows[k]] =
        withoutInto(forces[free[k]], contactNormal(muscle.contact, muscle.residual, free[k]));
}

/// The mean spring rest length of `muscle` [m], 0 without springs.
double meanRestLength(const IntegratedMuscle& muscle) {
  const size_t springs = muscle.settings.springs.size();
  return springs == 0 ? 0 : muscle.particles.restLengthSum / static_cast<double>(springs);
}

/// The square of the rounding a particle's force may carry at `x` [N²], `stiffness` its diagonal
/// entry of A [N/m]: each spring force k·(|x_b − x_a| − L0) rounds by about k·ε·(|x| + L0), ε
/// btScalar's epsilon. A curvature pair whose s·y this rounding can reach measures nothing: with
/// such pairs at rest (the double build, a box carried rigidly by its bone) the L-BFGS step moved
/// particles 1.5 mm off their bone while every spring was exact (aboveRounding).
double forceNoise(double stiffness, const btVector3& x, double restLength) {
  constexpr double kEpsilon = std::numeric_limits<btScalar>::epsilon();
  return kEpsilon * kEpsilon * stiffness * stiffness *
         (double(x.length2()) + restLength * restLength);
}

#if FIBREMSS_AVX2_PARTICLES
/// The dots of two rows' products `p` (one row per half) in lanes 0 and 4, each summed as
/// btVector3::dot sums it: (x + y) + z.
FIBREMSS_AVX2_PASS inline __m256 rowDots(__m256 p) {
  return _mm256_add_ps(_mm256_add_ps(p, _mm256_movehdup_ps(p)), _mm256_unpackhi_ps(p, p));
}

/// Row k's and row k + 1's dots of the products `p` (rowDots) added to `sum` in row order.
FIBREMSS_AVX2_PASS inline double addDots(double sum, __m256 p) {
  const __m256 dots = rowDots(p);
  sum += double(_mm256_cvtss_f32(dots));
  return sum + double(_mm_cvtss_f32(_mm256_extractf128_ps(dots, 1)));
}

/// Two rows of `v` (one per half).
FIBREMSS_AVX2_PASS inline __m256 rowPair(const btVector3* v, size_t k) {
  return _mm256_loadu_ps(v[k].m_floats);
}

/// dot() two rows per instruction (the same bits).
FIBREMSS_AVX2_PASS double dotAvx2(const btVector3* a, const btVector3* b, size_t rows) {
  double sum = 0;
  size_t k = 0;
  for (; k + 1 < rows; k += 2) sum = addDots(sum, _mm256_mul_ps(rowPair(a, k), rowPair(b, k)));
  if (k < rows) sum += double(a[k].dot(b[k]));
  return sum;
}
#endif

double dot(const std::vector<btVector3>& a, const std::vector<btVector3>& b) {
#if FIBREMSS_AVX2_PARTICLES
  if (fastestSpringKernel() == SpringKernel::avx2) return dotAvx2(a.data(), b.data(), a.size());
#endif
  double sum = 0;
  for (size_t k = 0; k < a.size(); ++k) sum += double(a[k].dot(b[k]));
  return sum;
}

/// A pair's products, each summed over the rows in order as dot() sums it (the same bits).
struct PairProducts {
  double curvature = 0;  ///< s·y [N·m]
  double steps = 0;      ///< s·s [m²]
  double changes = 0;    ///< y·y [N²]
};

#if FIBREMSS_AVX2_PARTICLES
/// The dots of the products p1, p2 and p3 of two rows (one row per half), each summed as
/// btVector3::dot sums it, as doubles: row k's [p1, p2, p3, p3] in `low`, row k + 1's in `high`.
FIBREMSS_AVX2_PASS inline void threeDots(__m256 p1, __m256 p2, __m256 p3, __m256d& low,
                                         __m256d& high) {
  const __m256 a = _mm256_unpacklo_ps(p1, p2), b = _mm256_unpackhi_ps(p1, p2);
  const __m256 c = _mm256_unpacklo_ps(p3, p3), d = _mm256_unpackhi_ps(p3, p3);
  const __m256 x = _mm256_shuffle_ps(a, c, 0x44), y = _mm256_shuffle_ps(a, c, 0xee);
  const __m256 dots = _mm256_add_ps(_mm256_add_ps(x, y), _mm256_shuffle_ps(b, d, 0x44));
  low = _mm256_cvtps_pd(_mm256_castps256_ps128(dots));
  high = _mm256_cvtps_pd(_mm256_extractf128_ps(dots, 1));
}

/// pairProducts two rows per instruction, the three sums side by side in one register (each
/// lane its own sum in row order): the same bits.
FIBREMSS_AVX2_PASS PairProducts pairProductsAvx2(const btVector3* s, const btVector3* y,
                                                 const btVector3* forces, btVector3* lastForces,
                                                 size_t rows) {
  __m256d sums = _mm256_setzero_pd();  // s·y, s·s, y·y (and y·y again)
  size_t r = 0;
  for (; r + 1 < rows; r += 2) {
    const __m256 step = rowPair(s, r), change = rowPair(y, r);
    __m256d low, high;
    threeDots(_mm256_mul_ps(step, change), _mm256_mul_ps(step, step), _mm256_mul_ps(change, change),
              low, high);
    sums = _mm256_add_pd(_mm256_add_pd(sums, low), high);
    _mm256_storeu_ps(lastForces[r].m_floats, rowPair(forces, r));
  }
  alignas(32) double lanes[4];
  _mm256_store_pd(lanes, sums);
  PairProducts products{lanes[0], lanes[1], lanes[2]};
  if (r < rows) {
    products.curvature += double(s[r].dot(y[r]));
    products.steps += double(s[r].dot(s[r]));
    products.changes += double(y[r].dot(y[r]));
    lastForces[r] = forces[r];
  }
  return products;
}
#endif

/// The products of the pair s, y in one pass, which also keeps `forces` in `lastForces`.
PairProducts pairProducts(const std::vector<btVector3>& s, const std::vector<btVector3>& y,
                          const std::vector<btVector3>& forces,
                          std::vector<btVector3>& lastForces) {
#if FIBREMSS_AVX2_PARTICLES
  if (fastestSpringKernel() == SpringKernel::avx2)
    return pairProductsAvx2(s.data(), y.data(), forces.data(), lastForces.data(), s.size());
#endif
  PairProducts sums;
  for (size_t r = 0; r < s.size(); ++r) {
    sums.curvature += double(s[r].dot(y[r]));
    sums.steps += double(s[r].dot(s[r]));
    sums.changes += double(y[r].dot(y[r]));
    lastForces[r] = forces[r];
  }
  return sums;
}

/// What the rounding of floats can put into a pair, summed over its rows (fillPair).
struct PairRounding {
  double forces = 0;     ///< Σ forceNoise over the rows, the forces' rounding squared [N²]
  double curvature = 0;  ///< Σ |s_row|²·(forceNoise of the row), s·y's rounding squared [N²·m²]
  double positions = 0;  ///< Σ |x_row|², over ε² the positions' own rounding squared [m²]
  bool pushed = false;   ///< some row was left out, its particle pushed by the last response
};

/// The arrays fillPair reads (by free particle k or by row) and writes (by row).
struct PairRows {
  const btVector3* positions;   ///< x by particle [m]
  const uint32_t* free;         ///< the particle of k
  const int* rows;              ///< the row of k (ProjectiveFactor::rows)
  const double* diagonal;       ///< A's diagonal by row [N/m]
  const uint8_t* pushed;        ///< 1 where the last response pushed the row's particle
  const btVector3* forces;      ///< F [N]
  const btVector3* lastForces;  ///< F at the last iteration [N]
  btVector3* lastPositions;     ///< x at the last iteration [m], becomes x
  btVector3* steps;             ///< s [m]
  btVector3* changes;           ///< y [N]
  double restLength;            ///< the muscle's mean spring rest length [m]
};

/// fillPair's work for free particle k: its row of s and y, its share of the rounding.
void fillRow(const PairRows& p, size_t k, PairRounding& rounding) {
  const int row = p.rows[k];
  const btVector3& x = p.positions[p.free[k]];
  btVector3& last = p.lastPositions[row];
  if (p.pushed[row] != 0) {
    p.steps[row] = p.changes[row] = btVector3(0, 0, 0);
    rounding.pushed = true;
  } else {
    const btVector3 s = p.steps[row] = x - last;
    p.changes[row] = p.lastForces[row] - p.forces[row];
    const double noise = forceNoise(p.diagonal[row], x, p.restLength);
    rounding.forces += noise;
    rounding.curvature += double(s.length2()) * noise;
    rounding.positions += double(x.length2());
  }
  last = x;
}

#if FIBREMSS_AVX2_PARTICLES
/// v's halves stored into rows a and b.
FIBREMSS_AVX2_PASS inline void storePair(btVector3* rows, int a, int b, __m256 v) {
  _mm_storeu_ps(rows[a].m_floats, _mm256_castps256_ps128(v));
  _mm_storeu_ps(rows[b].m_floats, _mm256_extractf128_ps(v, 1));
}

/// Lanes 0 and 4 of `v` (rowDots' two dots) as doubles.
FIBREMSS_AVX2_PASS inline __m128d dotPair(__m256 v) {
  return _mm_cvtps_pd(_mm_unpacklo_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1)));
}

/// `sum` plus v's low lane, then its high lane.
FIBREMSS_AVX2_PASS inline double addLanes(double sum, __m128d v) {
  sum += _mm_cvtsd_f64(v);
  return sum + _mm_cvtsd_f64(_mm_unpackhi_pd(v, v));
}

/// fillPair two particles per instruction: per lane fillRow's differences (w set to 0, as
/// btVector3's arithmetic sets it), its products in doubles, and its sums in k's order, so the
/// same bits. A pair with a pushed row goes through fillRow.
FIBREMSS_AVX2_PASS PairRounding fillPairAvx2(const PairRows& p, size_t count) {
  constexpr double kEpsilon = std::numeric_limits<btScalar>::epsilon();
  const __m256 xyz = xyzMask8();
  const __m128d epsilonSquare = _mm_set1_pd(kEpsilon * kEpsilon);
  const __m128d restSquare = _mm_set1_pd(p.restLength * p.restLength);
  PairRounding rounding;
  size_t k = 0;
  for (; k + 1 < count; k += 2) {
    const int a = p.rows[k], b = p.rows[k + 1];
    if ((p.pushed[a] | p.pushed[b]) != 0) {
      fillRow(p, k, rounding);
      fillRow(p, k + 1, rounding);
      continue;
    }
    const __m256 x = loadPair(p.positions[p.free[k]], p.positions[p.free[k + 1]]);
    const __m256 s =
        _mm256_and_ps(_mm256_sub_ps(x, loadPair(p.lastPositions[a], p.lastPositions[b])), xyz);
    const __m256 y = _mm256_and_ps(_mm256_sub_ps(loadPair(p.lastForces[a], p.lastForces[b]),
                                                 loadPair(p.forces[a], p.forces[b])),
                                   xyz);
    storePair(p.steps, a, b, s);
    storePair(p.changes, a, b, y);
    storePair(p.lastPositions, a, b, x);
    const __m128d positions = dotPair(rowDots(_mm256_mul_ps(x, x)));
    const __m128d stiffness = _mm_setr_pd(p.diagonal[a], p.diagonal[b]);
    const __m128d noise = _mm_mul_pd(_mm_mul_pd(_mm_mul_pd(epsilonSquare, stiffness), stiffness),
                                     _mm_add_pd(positions, restSquare));
    rounding.forces = addLanes(rounding.forces, noise);
    rounding.curvature =
        addLanes(rounding.curvature, _mm_mul_pd(dotPair(rowDots(_mm256_mul_ps(s, s))), noise));
    rounding.positions = addLanes(rounding.positions, positions);
  }
  if (k < count) fillRow(p, k, rounding);
  return rounding;
}
#endif

/// Writes the pair s = x − x_last, y = F_last − F by row (zero in the rows the last response
/// pushed) and keeps x in lastPositions. Returns what rounding can put into the pair.
PairRounding fillPair(StepHistory& h, const IntegratedMuscle& muscle,
                      const std::vector<uint32_t>& free, const ProjectiveFactor& factor,
                      const std::vector<btVector3>& forces, const std::vector<uint8_t>& pushedRows,
                      int slot) {
  const PairRows p{muscle.particles.positions.data(),
                   free.data(),
                   factor.rows(),
                   factor.matrixDiagonals(),
                   pushedRows.data(),
                   forces.data(),
                   h.lastForces.data(),
                   h.lastPositions.data(),
                   h.steps[slot].data(),
                   h.changes[slot].data(),
                   meanRestLength(muscle)};
#if FIBREMSS_AVX2_PARTICLES
  if (fastestSpringKernel() == SpringKernel::avx2) return fillPairAvx2(p, free.size());
#endif
  PairRounding rounding;
  for (size_t k = 0; k < free.size(); ++k) fillRow(p, k, rounding);
  return rounding;
}

/// Whether the pair `p` measures more than rounding (`r`): its s·y above three times the likely
/// share of the forces' rounding, √(2·Σ |s_row|²·ε_y,row²) (rounding independent from row to row,
/// y's both forces'), and its step above ten times the positions' rounding. The bound |s|·|ε_y|
/// (all the rows' rounding along s) refused every pair once the bones stopped in cylinder-twist's
/// poses at 400 and 1 000 iterations: the plain step alone left them 0.506 and 0.121 mm from the
/// converged state. A pair across a push keeps that bound: its other rows hold the force change
/// the push made, which no rounding covers (with the likely share there too, the hard-case matrix
/// at 200 iterations per pose failed a hip-extension cell; docs/decisions.md, "Solver").
bool aboveRounding(const PairProducts& p, const PairRounding& r) {
  // y's rounding is both forces': √2·the noise of one.
  if (r.pushed) return p.curvature > std::sqrt(2 * p.steps * r.forces);
  constexpr double kEpsilon = std::numeric_limits<btScalar>::epsilon();
  return p.curvature > 3 * std::sqrt(2 * r.curvature) &&
         p.steps > 100 * kEpsilon * kEpsilon * r.positions;
}

/// Adds the pair from the last iteration to this one (x, F by row) unless it shows no positive
/// curvature or no more than rounding can (aboveRounding), and keeps x and F for the next. Rows
/// the last response pushed are left out of the pair: a projection's move is not the forces'
/// answer to the step (with them in, the hard-case matrix's hip-extension and pinch cells tore).
void recordPair(StepHistory& h, const IntegratedMuscle& muscle, const std::vector<uint32_t>& free,
                const ProjectiveFactor& factor, const std::vector<btVector3>& forces,
                const std::vector<uint8_t>& pushedRows, int size) {
  if (!(h.hasLast && size > 0)) {
    const std::vector<btVector3>& positions = muscle.particles.positions;
    for (size_t k = 0; k < free.size(); ++k) h.lastPositions[factor.row(k)] = positions[free[k]];
    h.lastForces = forces;
    h.hasLast = true;
    return;
  }
  const int slot = (h.newest + 1) % size;
  const PairRounding rounding = fillPair(h, muscle, free, factor, forces, pushedRows, slot);
  const PairProducts p = pairProducts(h.steps[slot], h.changes[slot], forces, h.lastForces);
  if (p.curvature > 1e-12 * std::sqrt(p.steps * p.changes) && aboveRounding(p, rounding)) {
    h.curvature[slot] = p.curvature;
    h.newest = slot;
    h.count = std::min(h.count + 1, size);
  } else {
    h.restart();
  }
}

#if FIBREMSS_AVX2_PARTICLES
/// addThenDot two rows per instruction: per lane the scalar code's products and sums (the w
/// lanes too, which no product reads), so the same bits.
FIBREMSS_AVX2_PASS double addThenDotAvx2(btVector3* q, const btVector3* d, btScalar c,
                                         const btVector3* next, size_t rows) {
  const __m256 scale = _mm256_set1_ps(c);
  double sum = 0;
  size_t k = 0;
  for (; k + 1 < rows; k += 2) {
    const __m256 updated = _mm256_add_ps(rowPair(q, k), _mm256_mul_ps(rowPair(d, k), scale));
    _mm256_storeu_ps(q[k].m_floats, updated);
    if (next) sum = addDots(sum, _mm256_mul_ps(rowPair(next, k), updated));
  }
  if (k < rows) {
    q[k] += d[k] * c;
    if (next) sum += double(next[k].dot(q[k]));
  }
  return sum;
}
#endif

/// q += d·c, then Σ next·q over the rows as dot() sums it (0 without `next`): the recursion's
/// update and its next product in one pass.
double addThenDot(std::vector<btVector3>& q, const std::vector<btVector3>& d, btScalar c,
                  const std::vector<btVector3>* next) {
#if FIBREMSS_AVX2_PARTICLES
  if (fastestSpringKernel() == SpringKernel::avx2)
    return addThenDotAvx2(q.data(), d.data(), c, next ? next->data() : nullptr, q.size());
#endif
  double sum = 0;
  for (size_t k = 0; k < q.size(); ++k) {
    q[k] += d[k] * c;
    if (next) sum += double((*next)[k].dot(q[k]));
  }
  return sum;
}

#if FIBREMSS_AVX2_PARTICLES
/// copyThenDot two rows per instruction (the same bits).
FIBREMSS_AVX2_PASS double copyThenDotAvx2(btVector3* q, const btVector3* forces,
                                          const btVector3* next, size_t rows) {
  double sum = 0;
  size_t k = 0;
  for (; k + 1 < rows; k += 2) {
    const __m256 f = rowPair(forces, k);
    _mm256_storeu_ps(q[k].m_floats, f);
    if (next) sum = addDots(sum, _mm256_mul_ps(rowPair(next, k), f));
  }
  if (k < rows) {
    q[k] = forces[k];
    if (next) sum += double(next[k].dot(q[k]));
  }
  return sum;
}
#endif

/// q = F, then Σ next·q as dot() sums it (0 without `next`), in one pass.
double copyThenDot(std::vector<btVector3>& q, const std::vector<btVector3>& forces,
                   const std::vector<btVector3>* next) {
#if FIBREMSS_AVX2_PARTICLES
  if (fastestSpringKernel() == SpringKernel::avx2)
    return copyThenDotAvx2(q.data(), forces.data(), next ? next->data() : nullptr, q.size());
#endif
  double sum = 0;
  for (size_t k = 0; k < q.size(); ++k) {
    q[k] = forces[k];
    if (next) sum += double((*next)[k].dot(q[k]));
  }
  return sum;
}

/// L-BFGS's two-loop recursion: `q` becomes H·F, H the inverse Hessian its pairs and (A + W)⁻¹
/// estimate. Each update of q is fused with the next pair's product (q − y·a as q + y·(−a), the
/// same bits).
void twoLoop(StepHistory& h, ProjectiveFactor& factor, const std::vector<btVector3>& forces,
             std::vector<btVector3>& q, int size) {
  const auto newer = [size](int j) { return (j + 1) % size; };
  const auto older = [size](int j) { return (j + size - 1) % size; };
  double product = copyThenDot(q, forces, h.count > 0 ? &h.steps[h.newest] : nullptr);
  for (int n = 0, j = h.newest; n < h.count; ++n, j = older(j)) {
    h.alpha[j] = product / h.curvature[j];
    const auto a = static_cast<btScalar>(h.alpha[j]);
    product = addThenDot(q, h.changes[j], -a, n + 1 < h.count ? &h.steps[older(j)] : nullptr);
  }
  factor.solveInPlace(q.data());
  const int oldest = (h.newest + size - h.count + 1) % size;
  product = h.count > 0 ? dot(h.changes[oldest], q) : 0;
  for (int n = 0, j = oldest; n < h.count; ++n, j = newer(j)) {
    const auto b = static_cast<btScalar>(h.alpha[j] - product / h.curvature[j]);
    product = addThenDot(q, h.steps[j], b, n + 1 < h.count ? &h.changes[newer(j)] : nullptr);
  }
}

/// The largest |d| over `step` [m].
double longestMove(const std::vector<btVector3>& step) {
  btScalar longest = 0;
  for (const btVector3& d : step) longest = std::max(longest, d.length2());
  return std::sqrt(double(longest));
}

/// Σ step·F over the rows as dot() sums it, and the largest |d|² over `step` as longestMove()
/// finds it.
struct StepSums {
  double downhill = 0;   ///< [N·m]
  btScalar longest = 0;  ///< [m²]
};

#if FIBREMSS_AVX2_PARTICLES
/// stepSums two rows per instruction (the same bits).
FIBREMSS_AVX2_PASS StepSums stepSumsAvx2(const btVector3* step, const btVector3* forces,
                                         size_t rows) {
  StepSums sums;
  size_t k = 0;
  for (; k + 1 < rows; k += 2) {
    const __m256 d = rowPair(step, k);
    sums.downhill = addDots(sums.downhill, _mm256_mul_ps(d, rowPair(forces, k)));
    const __m256 lengths = rowDots(_mm256_mul_ps(d, d));
    sums.longest = std::max(sums.longest, _mm256_cvtss_f32(lengths));
    sums.longest = std::max(sums.longest, _mm_cvtss_f32(_mm256_extractf128_ps(lengths, 1)));
  }
  if (k < rows) {
    sums.downhill += double(step[k].dot(forces[k]));
    sums.longest = std::max(sums.longest, step[k].length2());
  }
  return sums;
}
#endif

StepSums stepSums(const std::vector<btVector3>& step, const std::vector<btVector3>& forces) {
#if FIBREMSS_AVX2_PARTICLES
  if (fastestSpringKernel() == SpringKernel::avx2)
    return stepSumsAvx2(step.data(), forces.data(), step.size());
#endif
  StepSums sums;
  for (size_t k = 0; k < step.size(); ++k) {
    sums.downhill += double(step[k].dot(forces[k]));
    sums.longest = std::max(sums.longest, step[k].length2());
  }
  return sums;
}

/// Whether the L-BFGS step `step` is kept: it points down the forces (step·F > 0) and moves no
/// particle farther than the muscle's mean spring rest length, more than an L-BFGS step may (the
/// pairs learnt from float noise near the equilibrium, or from a state the contacts keep
/// changing): both in one pass (stepSums). real-hip-gait tore without the bound (three muscles
/// frozen at 70 iterations per pose) and runs with it; fusiform and the cylinders never reach it.
bool keepsStep(const IntegratedMuscle& muscle, const std::vector<btVector3>& step,
               const std::vector<btVector3>& forces) {
  const StepSums sums = stepSums(step, forces);
  return sums.downhill > 0 && (muscle.settings.springs.empty() ||
                               !(std::sqrt(double(sums.longest)) > meanRestLength(muscle)));
}

/// Shortens `step` as a whole (its direction kept) so that no particle moves farther than the
/// muscle's mean spring rest length. The plain projective step is unbounded where the volume
/// terms' forces outrun their stand-in in A: in pinch's first iteration of a pose at 2 iterations
/// per pose (the blades 7 mm on) it moved a particle 10.9 mm and stretched a spring from 1.09 to
/// 2.44 × L0 before any contact (docs/decisions.md, "Solver").
void boundStep(const IntegratedMuscle& muscle, std::vector<btVector3>& step) {
  if (muscle.settings.springs.empty()) return;
  const double longest = longestMove(step), limit = meanRestLength(muscle);
  if (!(longest > limit)) return;
  const auto scale = static_cast<btScalar>(limit / longest);
  for (btVector3& d : step) d *= scale;
}

#if FIBREMSS_AVX2_PARTICLES
/// moveParticles two particles per instruction: per lane heavyBallStep's products and sums (w
/// set to 0, as btVector3's arithmetic sets it), the lengths summed in k's order: the same bits.
FIBREMSS_AVX2_PASS double moveParticlesAvx2(ParticleState& particles, const int* rows,
                                            const btVector3* solution, btScalar keep,
                                            btScalar scale) {
  const uint32_t* free = particles.freeParticles.data();
  const size_t count = particles.freeParticles.size();
  btVector3* positions = particles.positions.data();
  btVector3* previous = particles.previous.data();
  const __m256 xyz = xyzMask8(), keepAll = _mm256_set1_ps(keep), scaleAll = _mm256_set1_ps(scale);
  double displacement = 0;
  size_t k = 0;
  for (; k + 1 < count; k += 2) {
    const auto a = static_cast<int>(free[k]), b = static_cast<int>(free[k + 1]);
    const __m256 x = loadPair(positions[a], positions[b]);
    const __m256 push = loadPair(solution[rows[k]], solution[rows[k + 1]]);
    const __m256 step = _mm256_and_ps(
        _mm256_add_ps(_mm256_mul_ps(_mm256_sub_ps(x, loadPair(previous[a], previous[b])), keepAll),
                      _mm256_mul_ps(push, scaleAll)),
        xyz);
    storePair(previous, a, b, x);
    storePair(positions, a, b, _mm256_and_ps(_mm256_add_ps(x, step), xyz));
    const __m256 lengths = _mm256_sqrt_ps(rowDots(_mm256_mul_ps(step, step)));
    displacement += double(_mm256_cvtss_f32(lengths));
    displacement += double(_mm_cvtss_f32(_mm256_extractf128_ps(lengths, 1)));
  }
  if (k < count) displacement += heavyBallStep(particles, free[k], solution[rows[k]], keep, scale);
  return displacement;
}
#endif

/// Every free particle k moved by heavyBallStep with row k of `solution` as its push. Returns the
/// sum of their moves in k's order [m].
double moveParticles(ParticleState& particles, const ProjectiveFactor& factor,
                     const std::vector<btVector3>& solution, btScalar keep, btScalar scale) {
#if FIBREMSS_AVX2_PARTICLES
  if (fastestSpringKernel() == SpringKernel::avx2)
    return moveParticlesAvx2(particles, factor.rows(), solution.data(), keep, scale);
#endif
  const std::vector<uint32_t>& free = particles.freeParticles;
  double displacement = 0;
  for (size_t k = 0; k < free.size(); ++k)
    displacement += heavyBallStep(particles, free[k], solution[factor.row(k)], keep, scale);
  return displacement;
}

/// x⁺ = x + H·F(x) with F in w.forces; a step that does not point down the forces (H·F·F ≤ 0)
/// or moves a particle too far (keepsStep) is replaced by the plain projective one, bounded
/// (boundStep), and the history restarts.
IntegrationResult quasiNewtonStep(const IntegratedMuscle& muscle, const MuscleSystemDef& def,
                                  ProjectiveWorkspace& w) {
  ParticleState& particles = muscle.particles;
  const std::vector<uint32_t>& free = particles.freeParticles;
  const int size = def.projectiveHistory;
  StepHistory& h = w.history;
  if (particles.bonesMoving || h.size != size) h.restart();
  h.size = size;
  recordPair(h, muscle, free, w.factor, w.forces, w.pushed, particles.bonesMoving ? 0 : size);
  twoLoop(h, w.factor, w.forces, w.solution, size);
  if (h.count > 0 && !keepsStep(muscle, w.solution, w.forces)) {
    h.restart();
    w.solution = w.forces;
    w.factor.solveInPlace(w.solution.data());
  }
  if (h.count == 0) boundStep(muscle, w.solution);  // an L-BFGS step kept is within the bound
  IntegrationResult result;
  result.displacement = moveParticles(particles, w.factor, w.solution, 0, 1);
  result.finite = std::isfinite(result.displacement);
  return result;
}

/// x⁺ = x + ω·(A + W)⁻¹·F(x) + (ω − 1)·(x − x⁻): the projective step over-relaxed with momentum;
/// or, with a history, x⁺ = x + H·F(x), H L-BFGS's inverse Hessian from (A + W)⁻¹.
class ProjectiveIntegrator final : public TimeIntegrator {
 public:
  IntegrationResult advance(const IntegratedMuscle& muscle, const MuscleSystemDef& def, btScalar,
                            btScalar) const override {
    auto& w = static_cast<ProjectiveWorkspace&>(*muscle.workspace);
    if (holdContacts(muscle, w, def.projectiveContactWeight)) w.factor.update();
    ParticleState& particles = muscle.particles;
    // With pair reactions the step added the contacts' reactions to the forces already.
    gatherForces(muscle, w, holdsContacts(def) && !def.pairReactions);
    if (def.projectiveHistory > 0) return quasiNewtonStep(muscle, def, w);
    w.solution = w.forces;
    w.factor.solveInPlace(w.solution.data());
    const double rho = def.projectiveRho;
    const auto omega = static_cast<btScalar>(2 / (1 + std::sqrt(1 - rho * rho)));
    IntegrationResult result;
    result.displacement = moveParticles(particles, w.factor, w.solution, omega - 1, omega);
    result.finite = std::isfinite(result.displacement);
    return result;
  }
  bool usesVelocities() const override { return false; }
  bool holdsContacts(const MuscleSystemDef& def) const override { return def.persistentContacts; }

  Integrator kind() const override { return Integrator::Projective; }
  /// A anew over its pattern (a broken spring or volume term adds zeros) and factored anew; the
  /// L-BFGS pairs, learnt from the old forces, forgotten.
  void springsChanged(const MuscleSettings& settings, const ParticleState& particles,
                      IntegratorWorkspace* workspace) const override {
    auto& w = static_cast<ProjectiveWorkspace&>(*workspace);
    w.factor.clearMatrix();
    matrixEntries(settings, w.rows, particles.freeParticles.size(),
                  [&](int i, int j, double value) { w.factor.addToMatrix(i, j, value); });
    w.factor.refactorAll();
    w.history.restart();
    w.history.hasLast = false;
  }

 protected:
  std::unique_ptr<IntegratorWorkspace> makeWorkspace(
      const MuscleSettings& settings, const ParticleState& particles) const override {
    std::vector<int> rows = freeRows(settings, particles.freeParticles);
    const Matrix lowerA = assemble(settings, rows, particles.freeParticles.size());
    return std::make_unique<ProjectiveWorkspace>(std::move(rows), lowerA);
  }
};

const ProjectiveIntegrator projective;
const IntegratorRegistration registration(projective, "projective");

}  // namespace

}  // namespace fibremss
