// The general vector machine on its own: fitting, determinism, saving, range checks.
#include "gvm/machine.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "gvm/rng.h"

namespace collido::gvm {
namespace {

constexpr double kPi = 3.14159265358979323846;

// 15 evenly spaced samples of sin on [-pi, pi] and 200 points between them.
void sin_data(Matrix* x, Matrix* y, Matrix* vx, Matrix* vy) {
  for (int i = 0; i < 15; ++i) {
    const double t = -kPi + 2 * kPi * i / 14;
    x->push_row({t});
    y->push_row({std::sin(t)});
  }
  for (int i = 0; i < 200; ++i) {
    const double t = -kPi + 2 * kPi * (i + 0.5) / 200;
    vx->push_row({t});
    vy->push_row({std::sin(t)});
  }
}

// f(a, b) = exp(-(a^2 + b^2)) + 0.5 a b on [-2, 2]^2: smooth, far from linear.
double bump(double a, double b) {
  return std::exp(-(a * a + b * b)) + 0.5 * a * b;
}

void bump_data(size_t n, uint64_t seed, Matrix* x, Matrix* y) {
  Rng rng(seed);
  for (size_t i = 0; i < n; ++i) {
    const double a = rng.uniform(-2, 2), b = rng.uniform(-2, 2);
    x->push_row({a, b});
    y->push_row({bump(a, b)});
  }
}

double mse(const Machine& m, const Matrix& x, const Matrix& y) {
  double s = 0.0;
  for (size_t r = 0; r < x.rows(); ++r) {
    const double e = m.predict(std::vector<double>{x.row(r), x.row(r) + x.cols()})[0] - y(r, 0);
    s += e * e;
  }
  return s / x.rows();
}

// Every activation learns it (softsign is the default, tanh and sigmoid are options).
class MachineActivation : public ::testing::TestWithParam<Activation> {};

TEST_P(MachineActivation, LearnsSinFromFifteenPoints) {
  Matrix x, y, vx, vy;
  sin_data(&x, &y, &vx, &vy);
  GvmOptions opt;
  opt.epochs = 300;
  opt.activation = GetParam();
  // One input carrying a whole period needs neurons sharper than beta = 1 allows
  // (with beta_max 1 the best fit misses by ~0.1); see docs/gvm.md.
  opt.beta_max = 5.0;
  TrainReport rep;
  auto m = Machine::train(x, y, vx, vy, opt, &rep);
  ASSERT_TRUE(m) << m.status().message();
  double max_err = 0.0;
  for (size_t r = 0; r < vx.rows(); ++r)
    max_err = std::max(max_err, std::abs(m->predict({vx(r, 0)})[0] - vy(r, 0)));
  EXPECT_LT(std::sqrt(mse(*m, vx, vy)), 0.03);
  EXPECT_LT(max_err, 0.08);
  ASSERT_EQ(rep.curve.size(), 300u);
  EXPECT_LT(rep.curve.back().validation_loss, 0.1 * rep.curve.front().validation_loss);
}

INSTANTIATE_TEST_SUITE_P(Activations, MachineActivation,
                         ::testing::Values(Activation::kSoftsign, Activation::kTanh,
                                           Activation::kSigmoid),
                         [](const ::testing::TestParamInfo<Activation>& i) {
                           return std::string(activation_name(i.param));
                         });

// Ordinary least squares y = c0 + c1 a + c2 b, solved by Cramer's rule.
struct Plane {
  double c[3];
  double operator()(double a, double b) const { return c[0] + c[1] * a + c[2] * b; }
};
Plane fit_plane(const Matrix& x, const Matrix& y) {
  double A[3][3] = {}, r[3] = {};
  for (size_t n = 0; n < x.rows(); ++n) {
    const double f[3] = {1.0, x(n, 0), x(n, 1)};
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) A[i][j] += f[i] * f[j];
      r[i] += f[i] * y(n, 0);
    }
  }
  auto det = [](double m[3][3]) {
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
           m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
           m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  };
  Plane p;
  const double d = det(A);
  for (int k = 0; k < 3; ++k) {
    double M[3][3];
    std::memcpy(M, A, sizeof M);
    for (int i = 0; i < 3; ++i) M[i][k] = r[i];
    p.c[k] = det(M) / d;
  }
  return p;
}

TEST(Machine, SmoothFunctionOfTwoInputsBeatsLinearFit) {
  Matrix x, y, vx, vy;
  bump_data(70, 11, &x, &y);
  bump_data(30, 12, &vx, &vy);
  GvmOptions opt;
  opt.epochs = 300;
  auto m = Machine::train(x, y, vx, vy, opt, nullptr);
  ASSERT_TRUE(m) << m.status().message();
  const Plane plane = fit_plane(x, y);
  double lin = 0.0;
  for (size_t r = 0; r < vx.rows(); ++r) lin += std::pow(plane(vx(r, 0), vx(r, 1)) - vy(r, 0), 2);
  lin /= vx.rows();
  const double gvm = mse(*m, vx, vy);
  EXPECT_LT(gvm, 0.25 * lin) << "gvm " << gvm << " linear " << lin;
}

TEST(Machine, SameSeedGivesSameModelAndOtherSeedDoesNot) {
  Matrix x, y, vx, vy;
  bump_data(40, 3, &x, &y);
  GvmOptions opt;
  opt.epochs = 40;
  opt.seed = 77;
  TrainReport r1, r2;
  auto a = Machine::train(x, y, vx, vy, opt, &r1);
  auto b = Machine::train(x, y, vx, vy, opt, &r2);
  ASSERT_TRUE(a && b);
  EXPECT_EQ(a->params().w, b->params().w);
  EXPECT_EQ(a->params().b, b->params().b);
  EXPECT_EQ(a->params().beta, b->params().beta);
  EXPECT_EQ(a->params().v, b->params().v);
  EXPECT_EQ(a->params().out_c, b->params().out_c);
  ASSERT_EQ(r1.curve.size(), r2.curve.size());
  for (size_t e = 0; e < r1.curve.size(); ++e)
    EXPECT_EQ(r1.curve[e].train_loss, r2.curve[e].train_loss);
  opt.seed = 78;
  auto c = Machine::train(x, y, vx, vy, opt, nullptr);
  ASSERT_TRUE(c);
  EXPECT_NE(a->params().w, c->params().w);
}

TEST(Machine, OutputSignsAreBalancedPlusMinusOne) {
  Matrix x, y, vx, vy;
  Rng rng(5);
  for (int i = 0; i < 20; ++i) {
    const double a = rng.uniform01();
    x.push_row({a});
    y.push_row({a, a * a, 1 - a});
  }
  GvmOptions opt;
  opt.hidden = 10;
  opt.epochs = 2;
  auto m = Machine::train(x, y, vx, vy, opt, nullptr);
  ASSERT_TRUE(m);
  for (size_t k = 0; k < 3; ++k) {
    int sum = 0;
    for (size_t j = 0; j < 10; ++j) {
      const int v = m->params().v[k * 10 + j];
      EXPECT_TRUE(v == 1 || v == -1);
      sum += v;
    }
    EXPECT_EQ(sum, 0) << "output " << k;
  }
  // Different outputs get different sign patterns, or they could only differ by scale.
  EXPECT_FALSE(
      std::equal(m->params().v.begin(), m->params().v.begin() + 10, m->params().v.begin() + 10));
}

TEST(Machine, IncrementalCachesMatchAFullForwardPass) {
  // The trainer sums its rows four at a time: row counts that leave every remainder,
  // and a second output missing on every third row (its rows masked out of the sums).
  for (size_t rows : {5, 6, 7, 8, 49, 50, 51, 52}) {
    for (bool two_outputs : {false, true}) {
      Matrix x, y1, y, vx, vy;
      bump_data(rows, 21 + rows, &x, &y1);
      for (size_t r = 0; r < rows; ++r)
        y.push_row(two_outputs ? std::vector<double>{y1(r, 0), r % 3 == 0 ? NAN : x(r, 0) * x(r, 1)}
                               : std::vector<double>{y1(r, 0)});
      GvmOptions opt;
      opt.epochs = 60;
      TrainReport rep;
      auto m = Machine::train(x, y, vx, vy, opt, &rep);
      ASSERT_TRUE(m);
      // The trainer's loss comes from cached, incrementally updated neuron outputs;
      // Machine::loss recomputes everything from the parameters.
      EXPECT_NEAR(rep.curve.back().train_loss, m->loss(x, y), 1e-12)
          << rows << " rows, " << (two_outputs ? 2 : 1) << " outputs";
      EXPECT_LT(rep.curve.back().train_loss, rep.curve.front().train_loss) << rows << " rows";
    }
  }
}

TEST(Machine, TrainingLossNeverRises) {
  Matrix x, y, vx, vy;
  bump_data(50, 22, &x, &y);
  GvmOptions opt;
  opt.epochs = 80;
  TrainReport rep;
  ASSERT_TRUE(Machine::train(x, y, vx, vy, opt, &rep));
  for (size_t e = 1; e < rep.curve.size(); ++e)
    EXPECT_LE(rep.curve[e].train_loss, rep.curve[e - 1].train_loss * (1 + 1e-12)) << e;
  EXPECT_GT(rep.accepted, 0);
  EXPECT_LT(rep.accepted, rep.proposals);
}

TEST(Machine, JsonRoundTripGivesBitIdenticalPredictions) {
  Matrix x, y, vx, vy;
  bump_data(40, 31, &x, &y);
  GvmOptions opt;
  opt.epochs = 30;
  opt.activation = Activation::kSigmoid;
  auto m = Machine::train(x, y, vx, vy, opt, nullptr, {"a", "b"}, {"f"});
  ASSERT_TRUE(m);
  auto back = Machine::from_json(m->to_json());
  ASSERT_TRUE(back) << back.status().message();
  EXPECT_EQ(back->params().input_names, (std::vector<std::string>{"a", "b"}));
  EXPECT_EQ(back->params().activation, Activation::kSigmoid);
  Rng rng(9);
  for (int i = 0; i < 200; ++i) {
    const std::vector<double> in = {rng.uniform(-3, 3), rng.uniform(-3, 3)};
    const double p1 = m->predict(in)[0], p2 = back->predict(in)[0];
    EXPECT_EQ(std::memcmp(&p1, &p2, sizeof p1), 0) << p1 << " vs " << p2;
  }
  EXPECT_EQ(m->to_json(), back->to_json());
}

TEST(Machine, ReportsInputsOutsideTheTrainedRange) {
  Matrix x, y, vx, vy;
  for (int i = 0; i <= 10; ++i) {
    x.push_row({static_cast<double>(i), 5.0 + i});
    y.push_row({static_cast<double>(i)});
  }
  GvmOptions opt;
  opt.epochs = 2;
  auto m = Machine::train(x, y, vx, vy, opt, nullptr, {"alpha", "gamma"}, {"out"});
  ASSERT_TRUE(m);
  const double inside[] = {3.0, 7.0};
  EXPECT_TRUE(m->check_range(inside).empty());
  const double edge[] = {0.0, 15.0};
  EXPECT_TRUE(m->check_range(edge).empty());
  const double outside[] = {3.0, 15.5};
  auto issues = m->check_range(outside);
  ASSERT_EQ(issues.size(), 1u);
  EXPECT_EQ(issues[0].name, "gamma");
  EXPECT_EQ(issues[0].input, 1u);
  EXPECT_EQ(issues[0].min, 5.0);
  EXPECT_EQ(issues[0].max, 15.0);
  const double nan_in[] = {std::nan(""), 7.0};
  EXPECT_EQ(m->check_range(nan_in).size(), 1u);
}

TEST(Machine, MissingTargetsAreLeftOut) {
  Matrix x, y, vx, vy;
  const double nan = std::nan("");
  for (int i = 0; i < 30; ++i) {
    const double a = i / 29.0;
    x.push_row({a});
    y.push_row({a, i % 2 ? nan : 2 * a});  // second output known on even rows only
  }
  GvmOptions opt;
  opt.epochs = 100;
  TrainReport rep;
  auto m = Machine::train(x, y, vx, vy, opt, &rep);
  ASSERT_TRUE(m) << m.status().message();
  EXPECT_TRUE(std::isfinite(rep.curve.back().train_loss));
  const auto out = m->predict({0.5});
  EXPECT_NEAR(out[0], 0.5, 0.05);
  EXPECT_NEAR(out[1], 1.0, 0.1);
}

TEST(Machine, RejectsBadInputWithoutThrowing) {
  Matrix x, y, vx, vy;
  GvmOptions opt;
  EXPECT_FALSE(Machine::train(x, y, vx, vy, opt, nullptr));  // empty
  x.push_row({1.0});
  x.push_row({std::nan("")});
  y.push_row({1.0});
  y.push_row({2.0});
  auto r = Machine::train(x, y, vx, vy, opt, nullptr);
  ASSERT_FALSE(r);
  EXPECT_NE(r.status().message().find("NaN"), std::string::npos);
  x(1, 0) = 2.0;
  opt.hidden = 0;
  EXPECT_FALSE(Machine::train(x, y, vx, vy, opt, nullptr));
  opt.hidden = 4;
  opt.delta = 0.0;
  EXPECT_FALSE(Machine::train(x, y, vx, vy, opt, nullptr));
  opt.delta = 0.1;
  Matrix short_y;
  short_y.push_row({1.0});
  EXPECT_FALSE(Machine::train(x, short_y, vx, vy, opt, nullptr));
  EXPECT_TRUE(Machine::train(x, y, vx, vy, opt, nullptr));
}

TEST(Machine, MalformedJsonIsAnErrorNotACrash) {
  EXPECT_FALSE(Machine::from_json("not json"));
  EXPECT_FALSE(Machine::from_json("{}"));
  EXPECT_FALSE(Machine::from_json(R"({"kind": "general-vector-machine", "version": 1})"));
  Matrix x, y, vx, vy;
  bump_data(10, 1, &x, &y);
  GvmOptions opt;
  opt.epochs = 1;
  auto m = Machine::train(x, y, vx, vy, opt, nullptr);
  ASSERT_TRUE(m);
  MachineParams p = m->params();
  p.w.pop_back();
  EXPECT_FALSE(Machine::from_params(p));
  p = m->params();
  p.v[0] = 0;
  EXPECT_FALSE(Machine::from_params(p));
  p = m->params();
  p.w[0] = 2.0 * p.w_max;
  EXPECT_FALSE(Machine::from_params(p));
  std::string text = m->to_json();
  text.replace(text.find("\"softsign\""), 10, "\"relu\"");
  EXPECT_FALSE(Machine::from_json(text));
}

}  // namespace
}  // namespace collido::gvm
