// The methods on the hand-written bouncing ball, instantiated once (ball_methods.hpp).

#include "ball_methods.hpp"

namespace hybgen::rt {

template MethodResult<2> solve_method<testing::BouncingBall>(const TensorGrid<2>& grid,
                                                             std::span<const double> times,
                                                             double dt, const double* par,
                                                             const MethodSettings& s);

}  // namespace hybgen::rt
