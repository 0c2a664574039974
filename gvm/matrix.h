// A dense row-major table of doubles: one row per sample, one column per feature.
#pragma once

#include <cstddef>
#include <vector>

namespace collido::gvm {

class Matrix {
 public:
  Matrix() = default;
  Matrix(size_t rows, size_t cols, double fill = 0.0)
      : rows_(rows), cols_(cols), v_(rows * cols, fill) {}
  size_t rows() const { return rows_; }
  size_t cols() const { return cols_; }
  double& operator()(size_t r, size_t c) { return v_[r * cols_ + c]; }
  double operator()(size_t r, size_t c) const { return v_[r * cols_ + c]; }
  double* row(size_t r) { return v_.data() + r * cols_; }
  const double* row(size_t r) const { return v_.data() + r * cols_; }
  // Appends one row; false (and nothing appended) when its length differs from cols().
  // The first row of a 0x0 matrix sets cols().
  bool push_row(const std::vector<double>& r) {
    if (rows_ == 0 && cols_ == 0) cols_ = r.size();
    if (r.size() != cols_) return false;
    v_.insert(v_.end(), r.begin(), r.end());
    ++rows_;
    return true;
  }

 private:
  size_t rows_ = 0, cols_ = 0;
  std::vector<double> v_;
};

}  // namespace collido::gvm
