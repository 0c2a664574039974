// Small dense linear algebra for the predictors' least-squares fits (a few dozen
// unknowns at most, where Eigen would add nothing) and their networks' hidden layers.
// Header-only.
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

// z[j] = b[j] + w[j][0] x[0] + w[j][1] x[1] + .. for H neurons of I inputs (w row-major,
// H x I), each neuron adding its inputs in order; four neurons at a time, so that their
// sums are four independent chains of adds where one neuron's was a single chain. The
// same bits as the plain loop. A network's hidden layer: the GVM's predict() and the
// MLP baseline's training.
inline void hidden_sums(const double* w, const double* b, size_t H, size_t I, const double* x,
                        double* z) {
  size_t j = 0;
  for (; j + 4 <= H; j += 4) {
    const double *w0 = w + j * I, *w1 = w0 + I, *w2 = w1 + I, *w3 = w2 + I;
    double z0 = b[j], z1 = b[j + 1], z2 = b[j + 2], z3 = b[j + 3];
    for (size_t i = 0; i < I; ++i) {
      z0 += w0[i] * x[i];
      z1 += w1[i] * x[i];
      z2 += w2[i] * x[i];
      z3 += w3[i] * x[i];
    }
    z[j] = z0, z[j + 1] = z1, z[j + 2] = z2, z[j + 3] = z3;
  }
  for (; j < H; ++j) {
    double s = b[j];
    for (size_t i = 0; i < I; ++i) s += w[j * I + i] * x[i];
    z[j] = s;
  }
}

}  // namespace collido::gvm
