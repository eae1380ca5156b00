#include "inekf_semantic_mapping/estimation/selected_inverse.h"

#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace inekf_semantic_mapping {
namespace estimation {

SelectedInverse::SelectedInverse(const Eigen::SparseMatrix<double>& matrix,
                                 const std::string& owner)
    : size_(static_cast<int>(matrix.rows())) {
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(matrix);
  // P A P^T = L D L^T. Eigen only reports an exactly zero pivot; a pivot that is not clearly
  // positive against the diagonal it came from is a direction the factors do not observe (the
  // inverse would be rounding noise, or negative).
  const auto fail = [&owner](const std::string& why) {
    return std::runtime_error(
        owner + ": the Hessian cannot be factored for the marginal covariances (" + why +
        "; is the graph anchored, is every direction of every node observed?)");
  };
  if (solver.info() != Eigen::Success) throw fail("zero pivot");
  const Eigen::VectorXd d = solver.vectorD();
  permutation_ = solver.permutationP().indices();
  Eigen::VectorXd permuted_diagonal(size_);
  for (int i = 0; i < size_; ++i) permuted_diagonal(permutation_(i)) = matrix.coeff(i, i);
  constexpr double kRelativePivot = 1e-12;
  for (int i = 0; i < size_; ++i) {
    if (!std::isfinite(d(i)) || !(d(i) > kRelativePivot * permuted_diagonal(i))) {
      throw fail("pivot " + std::to_string(d(i)) + " for a diagonal of " +
                 std::to_string(permuted_diagonal(i)));
    }
  }

  // Takahashi's recursion for Z = (L D L^T)^-1 on the pattern of L (the strictly lower part as
  // stored by Eigen, each column's rows ascending), columns from the last to the first:
  //   Z(j, i) = -sum_{k in S_i} L(k, i) Z(k, j)  for j in S_i,
  //   Z(i, i) = 1 / d_i - sum_{k in S_i} L(k, i) Z(k, i),
  // with S_i the rows of column i below the diagonal. S_i is a clique of the filled graph, so
  // every Z(k, j) needed is on the pattern and already computed. Cost: sum |S_i|^2 log |S_i|.
  const auto& l = solver.matrixL().nestedExpression();
  outer_.assign(l.outerIndexPtr(), l.outerIndexPtr() + size_ + 1);
  rows_.assign(l.innerIndexPtr(), l.innerIndexPtr() + outer_[size_]);
  const double* values = l.valuePtr();
  lower_.assign(rows_.size(), 0.0);
  diagonal_.assign(size_, 0.0);
  for (int i = size_ - 1; i >= 0; --i) {
    const int begin = outer_[i], end = outer_[i + 1];
    double diagonal = 1.0 / d(i);
    for (int p = begin; p < end; ++p) {
      const int j = rows_[p];
      double sum = 0.0;
      for (int q = begin; q < end; ++q) sum += values[q] * entry(rows_[q], j);
      lower_[p] = -sum;
      diagonal -= values[p] * lower_[p];
    }
    diagonal_[i] = diagonal;
  }
}

double SelectedInverse::entry(int r, int c) const {
  if (r == c) return diagonal_[r];
  if (r < c) std::swap(r, c);
  const auto begin = rows_.begin() + outer_[c];
  const auto end = rows_.begin() + outer_[c + 1];
  const auto found = std::lower_bound(begin, end, r);
  if (found == end || *found != r) {
    throw std::logic_error("SelectedInverse: an entry off the factor's pattern was asked for");
  }
  return lower_[found - rows_.begin()];
}

double SelectedInverse::operator()(int row, int col) const {
  if (row < 0 || col < 0 || row >= size_ || col >= size_) {
    throw std::logic_error("SelectedInverse: entry (" + std::to_string(row) + ", " +
                           std::to_string(col) + ") outside a " + std::to_string(size_) +
                           "-square matrix");
  }
  return entry(permutation_(row), permutation_(col));
}

Eigen::MatrixXd SelectedInverse::block(int row, int col, int rows, int cols) const {
  Eigen::MatrixXd out(rows, cols);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) out(r, c) = (*this)(row + r, col + c);
  }
  return out;
}

}  // namespace estimation
}  // namespace inekf_semantic_mapping
