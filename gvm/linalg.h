// Small dense linear algebra for the predictors' least-squares fits (a few dozen
// unknowns at most, where Eigen would add nothing). Header-only.
#pragma once

#include <cmath>
#include <cstddef>
#include <vector>

namespace collido::gvm {

// Solves the symmetric positive definite system A x = b (n x n, row-major; only the
// lower triangle is read) by Cholesky. *bx holds b on entry and x on return.
// Returns false when A is not positive definite.
inline bool cholesky_solve(std::vector<double> a, size_t n, std::vector<double>* bx) {
  for (size_t j = 0; j < n; ++j) {
    double d = a[j * n + j];
    for (size_t k = 0; k < j; ++k) d -= a[j * n + k] * a[j * n + k];
    if (!(d > 0.0)) return false;
    const double l = std::sqrt(d);
    a[j * n + j] = l;
    for (size_t i = j + 1; i < n; ++i) {
      double s = a[i * n + j];
      for (size_t k = 0; k < j; ++k) s -= a[i * n + k] * a[j * n + k];
      a[i * n + j] = s / l;
    }
  }
  std::vector<double>& x = *bx;
  for (size_t i = 0; i < n; ++i) {  // L y = b
    double s = x[i];
    for (size_t k = 0; k < i; ++k) s -= a[i * n + k] * x[k];
    x[i] = s / a[i * n + i];
  }
  for (size_t i = n; i-- > 0;) {  // L^T x = y
    double s = x[i];
    for (size_t k = i + 1; k < n; ++k) s -= a[k * n + i] * x[k];
    x[i] = s / a[i * n + i];
  }
  return true;
}

}  // namespace collido::gvm
