// A C++ program that uses hybgen as a library (docs/install.md): the kernels `hybgen
// generate` wrote for decay.model, and the runtime's characteristics solver, found with
// find_package(hybgen). It checks the solver against the closed form and exits 1 if they
// differ, so that tests/install/test_install.sh can run it as a test.

#include <cmath>
#include <cstdio>
#include <vector>

#include <hybgen/rt/methods/methods.hpp>

#include "decay.hpp"  // hybgen generate decay.model -o <dir>

int main() {
  using M = hybgen_model::decay;
  namespace rt = hybgen::rt;

  // The generated kernels are plain static functions: the field at x = 1.
  std::vector<double> par(M::param_defaults.begin(), M::param_defaults.end());
  const double x1 = 1.0;
  double v = 0;
  M::flow(0, &x1, par.data(), &v);
  std::printf("%s: x' = %g at x = 1 (a = %g)\n", M::name, v, par[0]);

  // The density at t = 0, 0.5, 1 on 61 nodes, by the characteristics method.
  rt::TensorGrid<1> grid;
  grid.axes[0] = {-1.5, 1.5, 61};
  const std::vector<double> times{0.0, 0.5, 1.0};
  rt::MethodSettings s;
  s.settings.assign("method", {"characteristics", 0, false});
  s.settings.assign("budget", {"off", 0, false});
  s.quiet = true;
  const rt::MethodResult<1> r = rt::solve_method<M>(grid, times, 0.5, par.data(), s);
  if (!r.ok()) {
    std::printf("failed: %s\n", r.failure.c_str());
    return 1;
  }

  // Against u(t, x) = u0(x e^{a t}) e^{a t}, u0 = exp(-x^2).
  double worst = 0;
  for (std::size_t k = 0; k < times.size(); ++k)
    for (std::size_t i = 0; i < grid.size(); ++i) {
      const double x = grid.node(i)[0], g = std::exp(par[0] * times[k]);
      worst = std::max(worst, std::fabs(r.solution.at(k, 0, i) - std::exp(-x * x * g * g) * g));
    }
  std::printf("largest difference from the closed form: %.3e\n", worst);
  return worst < 1e-7 ? 0 : 1;
}
