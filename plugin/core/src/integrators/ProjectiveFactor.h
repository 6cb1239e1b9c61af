#pragma once
// The sparse Cholesky factor of the projective integrator's matrix (internal to the integrators):
// L·Lᵀ = P·(A + W)·Pᵀ over a muscle's free particles, A fixed (springs and volume terms), W a
// diagonal that changes as contacts come and go. P is AMD's fill-reducing ordering: on thigh13
// R=40 METIS' nested dissection gives 1.61 M entries of L against AMD's 1.19 M, more on every
// muscle, and SuiteSparse's AMD 1.19 M too (docs/decisions.md, "Solver"). The pattern
// is found once by walking the elimination tree (as Eigen's SimplicialLLT analyses it, without
// its numeric factor: one factorisation at start-up, not two); the values are computed in double,
// and again only in the rows a changed W reaches, or by rank-one updates up the tree. The solve
// reads them in btScalar: L only preconditions, the forces alone set the iteration's fixed point.
#include <LinearMath/btVector3.h>

#include <Eigen/SparseCore>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "kernels/SpringForces.h"

namespace fibremss {

/// L of P·(A + W)·Pᵀ and what keeps it up to date without allocating. A + W acts alike on x, y
/// and z, so one scalar factor serves the three.
class ProjectiveFactor {
 public:
  /// Orders and factors `lowerA`, the lower triangle of A over the free particles [N/m], with
  /// W = 0. Throws InputError if A is not positive definite.
  explicit ProjectiveFactor(const Eigen::SparseMatrix<double>& lowerA);

  /// The number of rows (free particles).
  size_t size() const { return order_.size(); }
  /// The row P·k of L that free particle k is solved in.
  int row(size_t k) const { return order_[k]; }
  /// row(k) for every free particle k, in k's order.
  const int* rows() const { return order_.data(); }
  /// A's diagonal entry in `row` of P·A·Pᵀ [N/m].
  double matrixDiagonal(int row) const { return diagonal_[row]; }
  /// matrixDiagonal(row) for every row, in row order [N/m].
  const double* matrixDiagonals() const { return diagonal_.data(); }
  /// W's entry in `row` [N/m].
  double weight(int row) const { return weights_[row]; }
  /// Sets W's entry in `row` [N/m], at most once per row between updates (the change lists are
  /// sized for one change per row); L follows at the next update().
  void setWeight(int row, double weight);
  /// Brings L up to date with the weights set since the last update: a rank-one update per
  /// changed row where their paths up the elimination tree visit fewer entries than new values
  /// for the rows they reach would, else those rows anew.
  void update();
  /// Sets A's entries to zero, its pattern kept, before they are added anew (addToMatrix).
  void clearMatrix();
  /// Adds `value` to A's entry of free particles k and l, which its pattern holds [N/m].
  void addToMatrix(int k, int l, double value);
  /// Factors P·(A + W)·Pᵀ anew from A's entries as added and W, without allocating.
  void refactorAll();
  /// Solves L·Lᵀ·z = b in place for the three coordinates of `x` together (indexed by row),
  /// using the factor's own scratch (one solve at a time): with AVX2 if `kernel` is avx2, else
  /// with SSE where the build has it (the same bits either way), else in scalar code.
  void solveInPlace(btVector3* x, SpringKernel kernel = fastestSpringKernel());

 private:
  void analyse(const Eigen::SparseMatrix<double>& upper);
  int rowPattern(int k, int top);
  void markStale(int row);
  void factorRow(int k);
  void shareSolveRows();
  void storeStale();
  void refactor();
  bool rankOneUpdate(int s, double delta);

  // The pattern, found once.
  std::vector<int> order_;        ///< free particle k → its row P·k in the factor
  std::vector<int> columnStart_;  ///< L by columns: entries [columnStart_[j], columnStart_[j+1])
  std::vector<int> rows_;         ///< row of each entry (a column's first: its diagonal)
  std::vector<int> parent_;       ///< elimination tree: first row below L's diagonal, −1: root
  // P·A·Pᵀ's upper triangle by columns (A without W), the input of a new factor.
  std::vector<int> upperStart_;      ///< column k: entries [upperStart_[k], upperStart_[k+1])
  std::vector<int> upperRows_;       ///< row of each entry
  std::vector<double> upperValues_;  ///< value of each entry [N/m]
  std::vector<double> diagonal_;     ///< column k's diagonal entry, one array read by row [N/m]
  std::vector<double> weights_;      ///< W per row [N/m]
  std::vector<double> lower_;        ///< L's entries as the pattern orders them [√(N/m)]
  /// lower_ in btScalar as the pattern orders it, each column's diagonal inverted [√(N/m), on the
  /// diagonal its inverse]: the stream the solve reads.
  std::vector<btScalar> solveValues_;
  /// The rows below the diagonal as byte offsets in the solved vector (row · sizeof(btVector3))
  /// [B], stored once per run of columns that share them: where column j's parent is j + 1 and
  /// column j has one entry more, its rows below j + 1 are column j + 1's, so the run's columns
  /// read one list, each from one further on (the fundamental supernodes: 30 179 offsets for
  /// cylinder-twist's 184 708 entries).
  std::vector<uint32_t> solveRows_;
  std::vector<int> solveRowStart_;  ///< column j: its first row below the diagonal in solveRows_
  /// The first column of each run of columns that read one list of rows, then size(): the runs'
  /// columns after the first are the rows just below the first's diagonal.
  std::vector<int> solveRuns_;
  std::vector<btVector3> solveGathered_;  ///< the solve's copy of x at one run's rows [per row]
  // Scratch of a new factor or an update (sized once).
  std::vector<double> scatter_;  ///< row k of L being formed, or an update's vector (zero between)
  std::vector<int> tags_;        ///< the row that last visited each column
  std::vector<int> pattern_;     ///< stack of the columns of row k, in topological order
  /// 1 for a row of L to recompute: a row whose W changed and every row above it in the
  /// elimination tree (L's other rows and columns do not depend on it), else 0.
  std::vector<uint8_t> stale_;
  std::vector<long> rowWork_;      ///< per row: the entries its new values visit [1]
  std::vector<int> changedRows_;   ///< rows whose W changed since the last update
  std::vector<double> changedBy_;  ///< and by how much [N/m]
};

}  // namespace fibremss
