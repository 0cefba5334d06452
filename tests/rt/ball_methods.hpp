#pragma once
/// \file ball_methods.hpp
/// Every method of the runtime on the hand-written bouncing ball (bouncing_ball_model.hpp),
/// instantiated once, in ball_methods.cpp, for the tests that solve it through
/// `solve_method`: an explicit instantiation declaration keeps each of those tests from
/// instantiating all the methods again (about 20 s of compile apiece at -O1, 45 s under the
/// sanitizers; docs/hardening.md).

#include <span>

#include "bouncing_ball_model.hpp"
#include "hybgen/rt/methods/methods.hpp"

namespace hybgen::rt {

/// `solve_method` for the bouncing ball, compiled in ball_methods.cpp.
extern template MethodResult<2> solve_method<testing::BouncingBall>(const TensorGrid<2>& grid,
                                                                    std::span<const double> times,
                                                                    double dt, const double* par,
                                                                    const MethodSettings& s);

}  // namespace hybgen::rt
