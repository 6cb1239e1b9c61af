#include "ProjectiveFactor.h"

#include <Eigen/OrderingMethods>
#include <algorithm>
#include <cmath>
#include <utility>

#include "fibremss/Error.h"
#include "kernels/ParticleSimd.h"
#include "kernels/SpringForces.h"

namespace fibremss {
namespace {

using Matrix = Eigen::SparseMatrix<double>;
using Permutation = Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int>;

/// A rank-one update's rotation of one column: (sign·sine, cosine, sine, pivot / new diagonal).
struct Rotation {
  double signedSine, cosine, sine, inverse;
};

/// Rotates L's entries [begin, end) of a column and the update's vector x at their rows.
void rotate(const Rotation& r, int begin, int end, const int* rows, double* lower, double* x) {
  for (int p = begin; p < end; ++p) {
    double& xi = x[rows[p]];
    const double l = (lower[p] + r.signedSine * xi) * r.inverse;
    xi = r.cosine * xi - r.sine * l;
    lower[p] = l;
  }
}

#if FIBREMSS_AVX2_PARTICLES
/// rotate four entries at a time (x loaded and stored back per row: a column's rows differ), the
/// same operations per lane without FMA, so the same bits.
FIBREMSS_AVX2_PASS void rotateAvx2(const Rotation& r, int begin, int end, const int* rows,
                                   double* lower, double* x) {
  const __m256d signedSine = _mm256_set1_pd(r.signedSine), cosine = _mm256_set1_pd(r.cosine),
                sine = _mm256_set1_pd(r.sine), inverse = _mm256_set1_pd(r.inverse);
  int p = begin;
  for (; p + 3 < end; p += 4) {
    const __m256d xi = _mm256_setr_pd(x[rows[p]], x[rows[p + 1]], x[rows[p + 2]], x[rows[p + 3]]);
    const __m256d l = _mm256_mul_pd(
        _mm256_add_pd(_mm256_loadu_pd(lower + p), _mm256_mul_pd(signedSine, xi)), inverse);
    const __m256d next = _mm256_sub_pd(_mm256_mul_pd(cosine, xi), _mm256_mul_pd(sine, l));
    _mm256_storeu_pd(lower + p, l);
    const __m128d low = _mm256_castpd256_pd128(next), high = _mm256_extractf128_pd(next, 1);
    _mm_storel_pd(x + rows[p], low);
    _mm_storeh_pd(x + rows[p + 1], low);
    _mm_storel_pd(x + rows[p + 2], high);
    _mm_storeh_pd(x + rows[p + 3], high);
  }
  rotate(r, p, end, rows, lower, x);
}
#endif

/// What a rank-one update costs per entry of L it visits, in entries a new factor visits [1]
/// (the inner loops as compiled for x86-64 with SSE2: 15 instructions per entry against 10). The
/// AVX2 rotations are cheaper still; one constant for every CPU keeps the choice, and so the
/// bits, the same everywhere.
constexpr double kUpdateCost = 1.5;

/// Values past L's last entry in solveValues_ (zero): the AVX2 solve reads eight from its last
/// pair's first.
constexpr size_t kSolvePadding = 8;

}  // namespace

ProjectiveFactor::ProjectiveFactor(const Matrix& lowerA) {
  // The ordering and P·A·Pᵀ as Eigen's SimplicialLLT finds them (AMD returns P⁻¹).
  const Matrix full = lowerA.selfadjointView<Eigen::Lower>();
  Permutation inverse;
  Eigen::AMDOrdering<int>()(full, inverse);
  const Permutation permutation = inverse.inverse();
  order_.assign(permutation.indices().data(),
                permutation.indices().data() + permutation.indices().size());
  Matrix upper(lowerA.rows(), lowerA.cols());
  upper.selfadjointView<Eigen::Upper>() =
      lowerA.selfadjointView<Eigen::Lower>().twistedBy(permutation);
  upper.makeCompressed();
  analyse(upper);
  refactor();
  for (size_t k = 0; k < size(); ++k)
    if (!(lower_[columnStart_[k]] > 0))
      throw InputError("integrator", "projective",
                       "the muscle's spring matrix is not positive definite");
}

/// The pattern of L from P·A·Pᵀ's upper triangle: the elimination tree and the column counts in
/// one pass (row k of L holds the columns on the tree paths from column k's entries up to k),
/// the rows of each column in a second; the buffers, L all stale.
void ProjectiveFactor::analyse(const Matrix& upper) {
  const auto n = static_cast<int>(upper.cols());
  upperStart_.assign(upper.outerIndexPtr(), upper.outerIndexPtr() + n + 1);
  upperRows_.assign(upper.innerIndexPtr(), upper.innerIndexPtr() + upper.nonZeros());
  upperValues_.assign(upper.valuePtr(), upper.valuePtr() + upper.nonZeros());
  diagonal_.assign(n, 0);
  parent_.assign(n, -1);
  tags_.assign(n, -1);
  std::vector<int> next(n, 1);  // first the column counts (the diagonal included)
  for (int k = 0; k < n; ++k) {
    tags_[k] = k;
    for (int p = upperStart_[k]; p < upperStart_[k + 1]; ++p) {
      if (upperRows_[p] == k) diagonal_[k] = upperValues_[p];
      for (int i = upperRows_[p]; tags_[i] != k; i = parent_[i]) {
        if (parent_[i] == -1) parent_[i] = k;
        ++next[i];
        tags_[i] = k;
      }
    }
  }
  columnStart_.assign(n + 1, 0);
  for (int j = 0; j < n; ++j) {
    columnStart_[j + 1] = columnStart_[j] + next[j];
    next[j] = columnStart_[j] + 1;
  }
  rows_.resize(static_cast<size_t>(columnStart_[n]));
  std::fill(tags_.begin(), tags_.end(), -1);
  for (int k = 0; k < n; ++k) {
    rows_[columnStart_[k]] = k;
    tags_[k] = k;
    for (int p = upperStart_[k]; p < upperStart_[k + 1]; ++p)
      for (int i = upperRows_[p]; tags_[i] != k; i = parent_[i]) {
        rows_[next[i]++] = k;
        tags_[i] = k;
      }
  }
  weights_.assign(n, 0);
  lower_.assign(rows_.size(), 0);
  solveValues_.assign(rows_.size() + kSolvePadding, 0);
  shareSolveRows();
  solveGathered_.assign(n, btVector3(0, 0, 0));
  scatter_.assign(n, 0);
  pattern_.assign(n, 0);
  stale_.assign(n, 1);
  rowWork_.assign(n, 0);
  changedRows_.reserve(n);
  changedBy_.reserve(n);
}

/// solveRows_, solveRowStart_ and solveRuns_ from the pattern: a column whose parent is the next
/// column and which has one entry more reads the next column's rows, its predecessor's list one
/// further on, in its predecessor's run.
void ProjectiveFactor::shareSolveRows() {
  const auto n = static_cast<int>(size());
  solveRowStart_.assign(n, 0);
  solveRows_.clear();
  solveRuns_.clear();
  for (int j = 0; j < n; ++j) {
    const int count = columnStart_[j + 1] - columnStart_[j];
    if (j > 0 && parent_[j - 1] == j && columnStart_[j] - columnStart_[j - 1] == count + 1) {
      solveRowStart_[j] = solveRowStart_[j - 1] + 1;
      continue;
    }
    solveRuns_.push_back(j);
    solveRowStart_[j] = static_cast<int>(solveRows_.size());
    for (int p = columnStart_[j] + 1; p < columnStart_[j + 1]; ++p)
      solveRows_.push_back(static_cast<uint32_t>(rows_[p]) * uint32_t(sizeof(btVector3)));
  }
  solveRuns_.push_back(n);
}

void ProjectiveFactor::setWeight(int row, double weight) {
  changedRows_.push_back(row);
  changedBy_.push_back(weight - weights_[row]);
  weights_[row] = weight;
  markStale(row);
}

/// Pushes column k of the upper triangle onto pattern_ (from `top` down): the columns i < k
/// whose L(k, i) is non-zero, each path up the elimination tree in topological order; scatters
/// the column's values. Returns the new top.
int ProjectiveFactor::rowPattern(int k, int top) {
  for (int p = upperStart_[k]; p < upperStart_[k + 1]; ++p) {
    int i = upperRows_[p];
    scatter_[i] += upperValues_[p];
    int length = 0;
    for (; tags_[i] != k; i = parent_[i]) {
      pattern_[length++] = i;
      tags_[i] = k;
    }
    while (length > 0) pattern_[--top] = pattern_[--length];
  }
  return top;
}

/// Marks `row` and its ancestors in the elimination tree stale (a diagonal change there reaches
/// only them).
void ProjectiveFactor::markStale(int row) {
  for (int i = row; i >= 0 && !stale_[i]; i = parent_[i]) stale_[i] = 1;
}

/// Row k of L of P·(A + W)·Pᵀ into lower_ (up-looking, as Eigen's SimplicialLLT and CSparse's
/// cs_chol do it): a sparse triangular solve against the rows above (each L(k, i) in column i
/// where the rows above k end, as a column's rows ascend). Records the entries it visited in
/// rowWork_[k].
void ProjectiveFactor::factorRow(int k) {
  const int* start = columnStart_.data();
  const int* rows = rows_.data();
  const auto n = static_cast<int>(size());
  tags_[k] = k;
  int top = rowPattern(k, n);
  double diagonal = scatter_[k] + weights_[k];
  scatter_[k] = 0;
  long work = 0;
  for (; top < n; ++top) {
    const int i = pattern_[top];
    const double entry = scatter_[i] / lower_[start[i]];
    scatter_[i] = 0;
    int p = start[i] + 1;  // up to row k, which column i holds (k is in row k's pattern)
    for (; rows[p] < k; ++p) scatter_[rows[p]] -= lower_[p] * entry;
    work += p - start[i];
    diagonal -= entry * entry;
    lower_[p] = entry;
  }
  lower_[start[k]] = std::sqrt(diagonal);
  rowWork_[k] = work;
}

/// solveValues_ from lower_ in the stale columns (btScalar, each column's diagonal inverted);
/// clears the marks and the changes.
void ProjectiveFactor::storeStale() {
  for (size_t j = 0; j < stale_.size(); ++j) {
    if (!stale_[j]) continue;
    stale_[j] = 0;
    for (int p = columnStart_[j]; p < columnStart_[j + 1]; ++p)
      solveValues_[p] = static_cast<btScalar>(p == columnStart_[j] ? 1 / lower_[p] : lower_[p]);
  }
  changedRows_.clear();
  changedBy_.clear();
}

/// Recomputes L's stale rows from A + W (the other rows and columns keep their values) and
/// stores them. A + W is positive definite (A is, W ≥ 0).
void ProjectiveFactor::refactor() {
  std::fill(tags_.begin(), tags_.end(), -1);
  for (size_t k = 0; k < stale_.size(); ++k)
    if (stale_[k]) factorRow(static_cast<int>(k));
  storeStale();
}

void ProjectiveFactor::clearMatrix() {
  std::fill(upperValues_.begin(), upperValues_.end(), 0.0);
}

void ProjectiveFactor::addToMatrix(int k, int l, double value) {
  const int column = std::max(order_[k], order_[l]), row = std::min(order_[k], order_[l]);
  for (int p = upperStart_[column]; p < upperStart_[column + 1]; ++p)
    if (upperRows_[p] == row) upperValues_[p] += value;
}

void ProjectiveFactor::refactorAll() {
  for (size_t k = 0; k < size(); ++k)
    for (int p = upperStart_[k]; p < upperStart_[k + 1]; ++p)
      if (upperRows_[p] == static_cast<int>(k)) diagonal_[k] = upperValues_[p];
  std::fill(stale_.begin(), stale_.end(), 1);
  refactor();
}

/// L·Lᵀ + δ·e_s·e_sᵀ in place (δ [N/m] the change of row s's weight): the rank-one update
/// (δ > 0) or downdate of the Cholesky factor by rotations, column by column up s's path in the
/// elimination tree (the only columns it changes). Returns false if a downdate met a pivot that
/// is not positive (rounding; then L is part-updated and the caller refactors).
bool ProjectiveFactor::rankOneUpdate(int s, double delta) {
  double* x = scatter_.data();  // zero outside the path walked
  double* lower = lower_.data();
  const int* start = columnStart_.data();
  const int* rows = rows_.data();
  const double sign = delta > 0 ? 1 : -1;
  x[s] = std::sqrt(std::abs(delta));
  bool definite = true;
  for (int k = s; k >= 0; k = parent_[k]) {
    const double xk = std::exchange(x[k], 0);
    const double pivot = lower[start[k]];
    const double squared = pivot * pivot + sign * xk * xk;
    definite = definite && squared > 0;
    if (!definite) continue;  // walks on to clear x
    const double diagonal = std::sqrt(squared);
    const double cosine = diagonal / pivot, sine = xk / pivot, inverse = pivot / diagonal;
    lower[start[k]] = diagonal;
    const Rotation rotation{sign * sine, cosine, sine, inverse};
#if FIBREMSS_AVX2_PARTICLES
    if (fastestSpringKernel() == SpringKernel::avx2) {
      rotateAvx2(rotation, start[k] + 1, start[k + 1], rows, lower, x);
      continue;
    }
#endif
    rotate(rotation, start[k] + 1, start[k + 1], rows, lower, x);
  }
  return definite;
}

void ProjectiveFactor::update() {
  if (changedRows_.empty()) return;
  long refactorWork = 0, updateWork = 0;
  for (size_t k = 0; k < stale_.size(); ++k)
    if (stale_[k]) refactorWork += rowWork_[k];
  for (int s : changedRows_)
    for (int k = s; k >= 0; k = parent_[k]) updateWork += columnStart_[k + 1] - columnStart_[k];
  bool updated = kUpdateCost * static_cast<double>(updateWork) < static_cast<double>(refactorWork);
  for (size_t r = 0; updated && r < changedRows_.size(); ++r)
    updated = rankOneUpdate(changedRows_[r], changedBy_[r]);
  if (updated)
    storeStale();
  else
    refactor();
}

namespace {

/// Column j of L as the solve reads it: its inverted diagonal, then `count` entries below it,
/// each a value and its row's byte offset in the solved vector.
struct SolveColumn {
  btScalar inverse;
  const btScalar* values;
  const uint32_t* rows;
  int count;
};

/// L's arrays as the solve reads them (ProjectiveFactor's solveValues_, solveRows_ and
/// solveRowStart_), passed by value so that the compiler keeps them in registers across the
/// solve's stores.
struct SolveFactor {
  const int* start;
  const btScalar* values;
  const uint32_t* rows;
  const int* rowStart;
  int n;
  const int* runs;  ///< each run's first column, then n (ProjectiveFactor's solveRuns_)
  int runCount;

  SolveColumn column(int j) const {
    return {values[start[j]], values + start[j] + 1, rows + rowStart[j],
            start[j + 1] - start[j] - 1};
  }
};

#if FIBREMSS_SSE_PARTICLES
/// L·Lᵀ·z = b in place with SSE (ProjectiveFactor::solveInPlace).
void solveLanes(const SolveFactor factor, btVector3* x) {
  const int n = factor.n;
  for (int j = 0; j < n; ++j) {
    const SolveColumn c = factor.column(j);
    const __m128 xj = _mm_mul_ps(loadVector(x[j]), _mm_set1_ps(c.inverse));
    _mm_store_ps(x[j].m_floats, xj);
    int p = 0;
    for (; p + 1 < c.count; p += 2) {  // x(row) − xj·L(row, j)
      float* a = at(x, c.rows[p]).m_floats;
      float* b = at(x, c.rows[p + 1]).m_floats;
      const __m128 newA = _mm_sub_ps(_mm_load_ps(a), _mm_mul_ps(xj, _mm_set1_ps(c.values[p])));
      const __m128 newB = _mm_sub_ps(_mm_load_ps(b), _mm_mul_ps(xj, _mm_set1_ps(c.values[p + 1])));
      _mm_store_ps(a, newA);
      _mm_store_ps(b, newB);
    }
    if (p < c.count) {
      float* a = at(x, c.rows[p]).m_floats;
      _mm_store_ps(a, _mm_sub_ps(_mm_load_ps(a), _mm_mul_ps(xj, _mm_set1_ps(c.values[p]))));
    }
  }
  for (int j = n - 1; j >= 0; --j) {  // sum − L(row, j)·z(row)
    const SolveColumn c = factor.column(j);
    const auto entry = [&](int p) {
      return _mm_mul_ps(loadVector(at(x, c.rows[p])), _mm_set1_ps(c.values[p]));
    };
    __m128 s0 = loadVector(x[j]), s1 = _mm_setzero_ps(), s2 = s1, s3 = s1;
    int p = 0;
    for (; p + 3 < c.count; p += 4) {
      s0 = _mm_sub_ps(s0, entry(p));
      s1 = _mm_sub_ps(s1, entry(p + 1));
      s2 = _mm_sub_ps(s2, entry(p + 2));
      s3 = _mm_sub_ps(s3, entry(p + 3));
    }
    if (p + 1 < c.count) {
      s0 = _mm_sub_ps(s0, entry(p));
      s1 = _mm_sub_ps(s1, entry(p + 1));
      p += 2;
    }
    if (p < c.count) (p % 4 == 0 ? s0 : s2) = _mm_sub_ps(p % 4 == 0 ? s0 : s2, entry(p));
    const __m128 sum = _mm_add_ps(_mm_add_ps(s0, s2), _mm_add_ps(s1, s3));
    _mm_store_ps(x[j].m_floats, _mm_mul_ps(sum, _mm_set1_ps(c.inverse)));
  }
}
#endif

#if FIBREMSS_AVX2_PARTICLES
/// Entries p and p + 1's values, each in all four lanes of its half: [v_p ×4, v_{p+1} ×4]. Reads
/// eight values from `values` (solveValues_ is padded).
FIBREMSS_AVX2_PASS inline __m256 valuePair(const btScalar* values) {
  return _mm256_permutevar8x32_ps(_mm256_loadu_ps(values),
                                  _mm256_setr_epi32(0, 0, 0, 0, 1, 1, 1, 1));
}

/// v in both halves.
FIBREMSS_AVX2_PASS inline __m256 twice(__m128 v) {
  return _mm256_insertf128_ps(_mm256_castps128_ps256(v), v, 1);
}

/// The forward pass inside the run of columns [first, last]: each column scaled by its inverted
/// diagonal and taken from the run's rows below it, which are the next rows (two per
/// instruction, read and written in place).
FIBREMSS_AVX2_PASS void forwardRun(const SolveFactor& factor, btVector3* x, int first, int last) {
  for (int j = first; j <= last; ++j) {
    const btScalar* values = factor.values + factor.start[j];
    const __m128 xj = _mm_mul_ps(loadVector(x[j]), _mm_set1_ps(values[0]));
    _mm_store_ps(x[j].m_floats, xj);
    const __m256 both = twice(xj);
    int r = j + 1;
#pragma GCC unroll 4
    for (; r < last; r += 2) {  // x(r, r + 1) − xj·L(r .. r + 1, j)
      float* a = x[r].m_floats;
      _mm256_storeu_ps(
          a, _mm256_sub_ps(_mm256_loadu_ps(a), _mm256_mul_ps(both, valuePair(values + r - j))));
    }
    if (r == last)
      _mm_store_ps(x[r].m_floats,
                   _mm_sub_ps(loadVector(x[r]), _mm_mul_ps(xj, _mm_set1_ps(values[r - j]))));
  }
}

/// The forward pass of the run [first, last]'s columns c .. c + B − 1 (solved) on the rows below
/// the run, which they share: each pair of rows read and written once for the B columns, taken
/// from them in column order.
template <int B>
FIBREMSS_AVX2_PASS void forwardBelow(const SolveFactor& factor, btVector3* x, int last, int c) {
  const SolveColumn below = factor.column(last);
  __m256 both[B];
  const btScalar* values[B];
  for (int b = 0; b < B; ++b) {
    both[b] = twice(loadVector(x[c + b]));
    values[b] = factor.values + factor.start[c + b] + 1 + (last - c - b);
  }
  int m = 0;
  for (; m + 1 < below.count; m += 2) {
    btVector3& a = at(x, below.rows[m]);
    btVector3& d = at(x, below.rows[m + 1]);
    __m256 next = loadPair(a, d);
#pragma GCC unroll 8
    for (int b = 0; b < B; ++b)
      next = _mm256_sub_ps(next, _mm256_mul_ps(both[b], valuePair(values[b] + m)));
    _mm_store_ps(a.m_floats, _mm256_castps256_ps128(next));
    _mm_store_ps(d.m_floats, _mm256_extractf128_ps(next, 1));
  }
  if (m < below.count) {
    float* a = at(x, below.rows[m]).m_floats;
    __m128 next = _mm_load_ps(a);
    for (int b = 0; b < B; ++b)
      next =
          _mm_sub_ps(next, _mm_mul_ps(_mm256_castps256_ps128(both[b]), _mm_set1_ps(values[b][m])));
    _mm_store_ps(a, next);
  }
}

/// forwardBelow of the run's last `count` (0 to 7) columns from c, in one sweep.
template <int... B>
FIBREMSS_AVX2_PASS inline void forwardLast(const SolveFactor& factor, btVector3* x, int last, int c,
                                           int count, std::integer_sequence<int, B...>) {
  ((count == B + 1 ? forwardBelow<B + 1>(factor, x, last, c) : void()), ...);
}

/// Entries p and p + 1's products with their rows' x, read from `rows` in the column's order.
FIBREMSS_AVX2_PASS inline __m256 products(const btVector3* rows, const btScalar* values, int p) {
  return _mm256_mul_ps(_mm256_loadu_ps(rows[p].m_floats), valuePair(values + p));
}

/// The backward pass of the run [first, last], column `last` down to `first`: each column's
/// entries summed as solveLanes sums them (`front` entries 0 and 1 modulo 4, `back` 2 and 3), its
/// rows read from `gathered`, which holds x at the rows of column `first` in its order (the rows
/// below the run gathered first, each solved row of the run added as it is solved).
FIBREMSS_AVX2_PASS void backwardRun(const SolveFactor& factor, btVector3* x, int first, int last,
                                    btVector3* gathered) {
  const SolveColumn below = factor.column(last);
  btVector3* tail = gathered + (last - first);
  int m = 0;
#pragma GCC unroll 4
  for (; m + 1 < below.count; m += 2)
    _mm256_storeu_ps(tail[m].m_floats, loadPair(at(x, below.rows[m]), at(x, below.rows[m + 1])));
  if (m < below.count) tail[m] = at(x, below.rows[m]);
  for (int j = last; j >= first; --j) {
    const SolveColumn c = factor.column(j);
    const btVector3* rows = gathered + (j - first);
    __m256 front = _mm256_insertf128_ps(_mm256_setzero_ps(), loadVector(x[j]), 0);
    __m256 back = _mm256_setzero_ps();
    int p = 0;
#pragma GCC unroll 2
    for (; p + 3 < c.count; p += 4) {
      front = _mm256_sub_ps(front, products(rows, c.values, p));
      back = _mm256_sub_ps(back, products(rows, c.values, p + 2));
    }
    if (p + 1 < c.count) front = _mm256_sub_ps(front, products(rows, c.values, p)), p += 2;
    if (p < c.count) {  // one entry: its sum's lanes, the other half less 0
      const __m256 single = _mm256_insertf128_ps(
          _mm256_setzero_ps(), _mm_mul_ps(loadVector(rows[p]), _mm_set1_ps(c.values[p])), 0);
      (p % 4 == 0 ? front : back) = _mm256_sub_ps(p % 4 == 0 ? front : back, single);
    }
    const __m256 halves = _mm256_add_ps(front, back);
    const __m128 xj =
        _mm_mul_ps(_mm_add_ps(_mm256_castps256_ps128(halves), _mm256_extractf128_ps(halves, 1)),
                   _mm_set1_ps(c.inverse));
    _mm_store_ps(x[j].m_floats, xj);
    if (j > first) _mm_store_ps(gathered[j - first - 1].m_floats, xj);
  }
}

/// solveLanes with AVX2 by runs of columns that share their rows (SolveFactor::runs), two entries
/// per instruction (low half entry p, high half p + 1; the backward pass's two registers entries
/// 0, 1 and 2, 3 modulo 4): per row the same products and differences in the same order, so the
/// same bits. The forward pass takes each pair of rows
/// below a run from up to eight of its columns at once; the backward pass gathers the rows below a
/// run once for all its columns.
FIBREMSS_AVX2_PASS void solveLanesAvx2(const SolveFactor factor, btVector3* x,
                                       btVector3* gathered) {
  for (int r = 0; r < factor.runCount; ++r) {
    const int first = factor.runs[r], last = factor.runs[r + 1] - 1;
    forwardRun(factor, x, first, last);
    int c = first;
    for (; c + 8 <= last + 1; c += 8) forwardBelow<8>(factor, x, last, c);
    forwardLast(factor, x, last, c, last + 1 - c, std::make_integer_sequence<int, 7>());
  }
  for (int r = factor.runCount - 1; r >= 0; --r)
    backwardRun(factor, x, factor.runs[r], factor.runs[r + 1] - 1, gathered);
}
#endif

}  // namespace

// With SSE each entry is one vector product and difference over x, y, z (and w, which stays 0;
// the scalar code's operations per lane), and the backward pass sums a column's entries in four
// chains by their index modulo 4, added as (0 + 2) + (1 + 3) (one chain of dependent
// subtractions is slower: two chains against one, CPU samples on thigh13 R=40, 358 -> 283 in the
// integrator; four against two, cylinder-twist's task-clock 1.06x less, docs/performance.md). The
// values stream alone (4 bytes per entry) and the rows come from the shared lists (solveRows_),
// which stay in cache: cylinder-twist's solve reads 0.86 MB instead of 1.48 MB with a row offset
// beside each value (a simulated 1 MB L2 misses 1.78 M lines over its 130 solves against 3.98 M).
// The forward pass takes a column's entries two at a time (its rows differ, so the order of their
// loads and stores does not matter). With AVX2 (solveLanesAvx2) two per instruction and by runs: a
// pair of rows below a run is read and written once per eight of its columns, and the rows below a
// run are gathered once for the backward pass of all its columns. cylinder-twist's 130 solves:
// 159.2 M instructions (162.4 M before a run's last columns took one sweep, 166.3 M with the
// backward sums in two chains), against 260.9 M column by column (302.5 M not unrolled, 395.3 M
// with SSE over value–offset pairs). A supernodal solve with four rows in the lanes (other sums,
// other bits) took 14 % fewer instructions than column by column but 12 % more CPU time
// (docs/decisions.md, "Solver").
void ProjectiveFactor::solveInPlace(btVector3* x, SpringKernel kernel) {
  const SolveFactor factor{columnStart_.data(),
                           solveValues_.data(),
                           solveRows_.data(),
                           solveRowStart_.data(),
                           static_cast<int>(size()),
                           solveRuns_.data(),
                           static_cast<int>(solveRuns_.size()) - 1};
#if FIBREMSS_AVX2_PARTICLES
  if (kernel == SpringKernel::avx2) return solveLanesAvx2(factor, x, solveGathered_.data());
#else
  (void)kernel;
#endif
#if FIBREMSS_SSE_PARTICLES
  solveLanes(factor, x);
#else
  for (int j = 0; j < factor.n; ++j) {
    const SolveColumn c = factor.column(j);
    const btVector3 xj = x[j] *= c.inverse;
    for (int p = 0; p < c.count; ++p) at(x, c.rows[p]) -= xj * c.values[p];
  }
  for (int j = factor.n - 1; j >= 0; --j) {
    const SolveColumn c = factor.column(j);
    btVector3 sum = x[j];
    for (int p = 0; p < c.count; ++p) sum -= at(x, c.rows[p]) * c.values[p];
    x[j] = sum * c.inverse;
  }
#endif
}

}  // namespace fibremss
