// Selected entries of the inverse of a sparse symmetric positive definite matrix: one sparse
// LDL^T factorization and Takahashi's recursion on the factor's pattern, so the marginal
// covariances of a graph's nodes (the diagonal blocks of the inverse Hessian) and the
// cross-covariances of nodes a factor connects cost about as much as the factorization, not a
// dense inverse or one solve per column. Used by the loop closure's smoothed-posterior graph.
// ROS-free, Eigen only.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <string>
#include <vector>

namespace inekf_semantic_mapping {
namespace estimation {

class SelectedInverse {
 public:
  // Factors `matrix` (symmetric; both triangles stored). Throws std::runtime_error starting with
  // `owner` when it is not clearly positive definite: a pivot that is zero, not finite or not
  // above 1e-12 of the diagonal it came from is a direction nothing observes.
  SelectedInverse(const Eigen::SparseMatrix<double>& matrix, const std::string& owner);

  int size() const { return size_; }
  // (matrix^-1)(row, col) for a structural nonzero (row, col) of the matrix, or any entry of the
  // filled pattern of its factor (a diagonal entry always is). Throws std::logic_error for an
  // entry off that pattern.
  double operator()(int row, int col) const;
  // A block of the inverse (each entry as above), symmetric blocks made exactly symmetric.
  Eigen::MatrixXd block(int row, int col, int rows, int cols) const;

 private:
  double entry(int permuted_row, int permuted_col) const;

  int size_ = 0;
  Eigen::VectorXi permutation_;  // matrix index -> factor index
  std::vector<int> outer_, rows_;
  std::vector<double> lower_;  // Z on the strictly lower pattern of L, L's storage order
  std::vector<double> diagonal_;
};

}  // namespace estimation
}  // namespace inekf_semantic_mapping
