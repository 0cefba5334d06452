#pragma once
/// \file fold_map.hpp
/// The fold map g of tests/validation/models/fold_halves.model (its comment), written here from
/// its definition for the tests that push samples through it (test_almost_invariant.cpp,
/// test_coherent.cpp): continuous, piecewise linear, with g(1 − x) = 1 − g(x); on [0, 1/2] up
/// from 0 to P at 1/6, down to 0 at 1/3, up to 1/2.

namespace hybgen::testing {

/// g(x) for the model's parameter P.
inline double fold(double x, double P) {
  if (x > 0.5) return 1.0 - fold(1.0 - x, P);
  if (x < 1.0 / 6.0) return 6.0 * P * x;
  if (x < 1.0 / 3.0) return P - 6.0 * P * (x - 1.0 / 6.0);
  return 3.0 * (x - 1.0 / 3.0);
}

}  // namespace hybgen::testing
