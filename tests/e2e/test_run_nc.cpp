// End to end: run.nc (runtime/src/io/netcdf.cpp) read by an independent reader, xarray
// (tests/e2e/check_run_nc.py), and compared with the arrays the run wrote beside it, which
// are in turn compared with closed forms of models hybgen does not ship: two modes with a
// switch and a contracting field (|J| != 1 along the flow), a 3-D model whose state names
// are the file's own (time, density), and an invariant density of a constant reset.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <numbers>
#include <string>

#include "hybgen/rt/io/npy.hpp"
#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::rt::exit_status;
using hybgen::rt::ExitCode;
using hybgen::testing::python_with;
using hybgen::testing::read_json_file;
using hybgen::testing::run_hybgen;
using hybgen::testing::write_model_file;

const fs::path kWork = hybgen::testing::e2e_dir("e2e_run_nc");

/// Run `check_run_nc.py` on `out` (the run of `model`); "ok" or what failed.
std::string xarray_reads(const std::string& python, const fs::path& out, const std::string& model) {
  const auto r = hybgen::testing::run_shell(python + " '" + HYBGEN_SOURCE_DIR +
                                            "/tests/e2e/check_run_nc.py' '" + out.string() + "' '" +
                                            model + "' 2>&1");
  return r.code == 0 ? r.out : "exit " + std::to_string(r.code) + ": " + r.out;
}

/// Run the model `text` (written as NAME.model) into kWork/NAME, with the options `sets`;
/// returns the directory, or an empty path with a test failure when the run fails.
fs::path run_made_up(const std::string& name, const std::string& text, std::string& model,
                     const std::string& sets = "") {
  model = write_model_file(kWork, name + ".model", text);
  const fs::path out = hybgen::testing::own_dir(kWork) / name;
  fs::remove_all(out);
  const auto r =
      run_hybgen("run '" + model + "' --out '" + out.string() + "' " + sets, kWork / "cache");
  EXPECT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  return r.code == exit_status(ExitCode::Success) ? out : fs::path();
}

// Mode L (x < 0) drifts right, x' = 1; mode R (x > 0) also contracts y, y' = -c y, so that
// the density grows by e^{c s} after s in R. By characteristics, with u0 the initial
// density of L and τ = x the time spent in R (x' = 1 from x = 0):
//   u_L(t, x, y) = u0(x − t, y)                     (x < 0),
//   u_R(t, x, y) = u0(x − t, y e^{c x}) e^{c x}      (0 < x < t), 0 for x > t.
constexpr const char* kSwitching = R"(model switching_drift
parameter c = 1.5
state x, y
mode L {
  where x < 0
  x' = 1
  y' = 0
}
mode R {
  where x > 0
  x' = 1
  y' = -c*y
}
guard L_to_R {
  from L to R
  when x = 0 increasing
  reset identity
}
simulation {
  domain x in [-1.5, 1]
  domain y in [-1, 1]
  grid 51x41
  initial L: exp(-8*((x + 0.5)^2 + y^2))
  t_end 1
  dt 0.25
  outputs netcdf + npy
}
)";

TEST(RunNc, TwoModesMatchTheClosedFormAndTheXarrayReader) {
  std::string model;
  // --set c=1.5 (the model's own value): run.nc's history must name it (check_run_nc.py; on
  // a81ba15 it named the command without its --set options).
  // values=nodes: the node values against the closed form (not cell averages).
  const fs::path out =
      run_made_up("switching_drift", kSwitching, model, "--set c=1.5 --set values=nodes");
  ASSERT_FALSE(out.empty());
  const auto s = read_json_file(out / "summary.json");
  EXPECT_EQ(s["outputs"]["netcdf"], "run.nc");
  EXPECT_FALSE(s["outputs"].contains("png")) << "outputs netcdf + npy wrote pictures";

  // The per-mode arrays against the closed form at t = 0.5 (frame 2).
  const double c = 1.5, t = 0.5;
  const auto u0 = [](double x, double y) { return std::exp(-8 * ((x + 0.5) * (x + 0.5) + y * y)); };
  const auto L = hybgen::rt::read_npy((out / "u_0002_L.npy").string());
  const auto R = hybgen::rt::read_npy((out / "u_0002_R.npy").string());
  ASSERT_EQ(L.shape, (std::vector<std::size_t>{51, 41}));
  double worst = 0;
  std::size_t checked = 0;
  for (std::size_t i = 0; i < 51; ++i)
    for (std::size_t j = 0; j < 41; ++j) {
      const double x = -1.5 + 0.05 * static_cast<double>(i), y = -1 + 0.05 * static_cast<double>(j);
      if (std::fabs(x) < 1e-9 || std::fabs(x - t) < 1e-9) continue;  // on the switch or the front
      const double want_L = x < 0 ? u0(x - t, y) : 0.0;
      const double want_R = x > 0 && x < t ? u0(x - t, y * std::exp(c * x)) * std::exp(c * x) : 0.0;
      worst = std::max(
          {worst, std::fabs(L.data[i * 41 + j] - want_L), std::fabs(R.data[i * 41 + j] - want_R)});
      ++checked;
    }
  EXPECT_GT(checked, 2000u);
  EXPECT_LT(worst, 1e-6) << "the per-mode densities differ from the closed form";

  const std::string python = python_with("xarray, netCDF4, numpy");
  HYBGEN_REQUIRE_PYTHON(python, "xarray, netCDF4, numpy");
  EXPECT_EQ(xarray_reads(python, out, model), "ok\n");
}

// A 3-D model whose states are called like the file's own variables: they keep their
// names and ours get a '_' (time_, density_). The drift leaves through density = 1, so the
// budget's outflow is not zero.
constexpr const char* kNames = R"(model clashing_names
state time, density, z
mode only {
  time' = 0
  density' = 1
  z' = -z
}
simulation {
  domain time in [-1, 1]
  domain density in [-1, 1]
  domain z in [-1, 1]
  grid 9x11x13
  initial exp(-4*(time^2 + density^2 + z^2))
  t_end 1
  dt 0.5
  outputs netcdf + npy
}
)";

TEST(RunNc, StateNamesKeepTheirsAndABudgetTravels) {
  std::string model;
  const fs::path out = run_made_up("clashing_names", kNames, model);
  ASSERT_FALSE(out.empty());
  const auto s = read_json_file(out / "summary.json");
  EXPECT_GT(s["outflow"].back().get<double>(), 0.05);  // the density leaves through the face
  const std::string python = python_with("xarray, netCDF4, numpy");
  HYBGEN_REQUIRE_PYTHON(python, "xarray, netCDF4, numpy");
  EXPECT_EQ(xarray_reads(python, out, model), "ok\n");
  // The renames themselves, read by xarray.
  const auto dims = hybgen::testing::run_shell(
      python + " -c \"import xarray as xr; ds = xr.open_dataset('" + (out / "run.nc").string() +
      "'); print(list(ds['density_'].dims))\"");
  EXPECT_EQ(dims.out, "['time_', 'time', 'density', 'z']\n");
}

// The stationary density of x' = 1 + x² on [0, 1] with the reset x = 1 ↦ 0: the flux
// u (1 + x) is constant, so u = 4 / (π (1 + x²)) (normalised: ∫₀¹ dx/(1+x²) = π/4).
constexpr const char* kFire = R"(model quadratic_fire
state x
mode grow {
  x' = 1 + x^2
}
guard fire {
  when x = 1 increasing
  reset (0)
}
simulation {
  domain x in [0, 1]
  grid 201
  initial 1
  t_end 1
  method invariant
  outputs netcdf + npy
}
)";

TEST(RunNc, TheInvariantDensityAndItsSpectrum) {
  std::string model;
  const fs::path out = run_made_up("quadratic_fire", kFire, model);
  ASSERT_FALSE(out.empty());
  const auto u = hybgen::rt::read_npy((out / "invariant.npy").string());
  ASSERT_EQ(u.data.size(), 201u);
  // The default scheme (auto) takes the finite-volume generator here (the guard x = 1 and its
  // image x = 0 are coordinate planes): its node values are point values of a density of
  // unit integral, whose trapezoid sum differs from 1 by the rule's error, h²/12 ∫u'' ≈ 2e-6
  // (measured 1.3e-6); the density itself to 1e-7 at every node (measured 3.5e-8 inside,
  // 4.6e-8 at the end nodes). (With
  // scheme=hat, the sampled operator: interior 5.9e-3, end nodes 3.7e-2, mass 1 to rounding.)
  double interior = 0, ends = 0, mass = 0;
  for (std::size_t i = 0; i < 201; ++i) {
    const double x = static_cast<double>(i) / 200;
    const double err = std::fabs(u.data[i] - 4 / (std::numbers::pi * (1 + x * x)));
    (i < 5 || i > 195 ? ends : interior) = std::max(i < 5 || i > 195 ? ends : interior, err);
    mass += (i == 0 || i == 200 ? 0.5 : 1.0) * u.data[i] / 200;
  }
  EXPECT_LT(interior, 1e-7) << "the invariant density differs from 4/(pi (1 + x^2))";
  EXPECT_LT(ends, 1e-7);
  EXPECT_NEAR(mass, 1.0, 5e-6);
  const std::string python = python_with("xarray, netCDF4, numpy");
  HYBGEN_REQUIRE_PYTHON(python, "xarray, netCDF4, numpy");
  EXPECT_EQ(xarray_reads(python, out, model), "ok\n");
}

}  // namespace

namespace {

// x' = -5x, y' = -5y: a Gaussian of width 1 shrinks to width e^{-5} by t = 1, far below
// the spacing 0.1 of a 21 x 21 grid. The characteristics' node samples (the peak e^{10} at
// the origin) then sum to 220 while the mass is π. By default (values=auto) the run then
// reports the dual cells' averages instead, whose masses sum to the mass; with values=nodes
// it says the grid under-resolves the density and names the cell averages and the cell-mass
// methods; transfer with cells says nothing.
constexpr const char* kSink = R"(model sink
state x, y
mode only {
  x' = -5*x
  y' = -5*y
}
simulation {
  domain x in [-1, 1]
  domain y in [-1, 1]
  grid 21x21
  initial exp(-(x^2 + y^2))
  t_end 1
  dt 0.5
}
)";

TEST(RunOutputs, AConcentratingFlowIsFlaggedAsUnderResolved) {
  const std::string model = write_model_file(kWork, "sink.model", kSink);
  const fs::path out = hybgen::testing::own_dir(kWork) / "sink";
  fs::remove_all(out);
  auto r = run_hybgen("run '" + model + "' --out '" + out.string() + "' --set outputs=npy",
                      kWork / "cache");
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  EXPECT_EQ(r.out.find("under-resolves"), std::string::npos) << r.out;
  auto s = read_json_file(out / "summary.json");
  EXPECT_EQ(s["values"]["kind"], "cells") << s["values"].dump();
  EXPECT_FALSE(s.contains("output_warnings")) << s.dump();
  // The cells' masses (trapezoid weights are the dual cells' volumes) sum to π erf(e^5)² = π.
  const std::vector<double> u = hybgen::rt::read_npy((out / "u_0002.npy").string()).data;
  double sum = 0.0;
  for (std::size_t i = 0; i < u.size(); ++i) {
    const std::size_t ix = i / 21, iy = i % 21;
    sum += u[i] * 0.1 * 0.1 * (ix == 0 || ix == 20 ? 0.5 : 1.0) * (iy == 0 || iy == 20 ? 0.5 : 1.0);
  }
  EXPECT_NEAR(sum, std::numbers::pi, 0.01 * std::numbers::pi);
  EXPECT_LE(s["values"]["error"].back().get<double>(), 0.02) << s["values"].dump();

  r = run_hybgen("run '" + model + "' --out '" + out.string() + "' --set values=nodes",
                 kWork / "cache");
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  EXPECT_NE(r.out.find("warning: the grid under-resolves the density: at t = 1 "),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("--set values=cells (the exact density's mean"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("method=transfer (cell masses)"), std::string::npos) << r.out;
  s = read_json_file(out / "summary.json");
  ASSERT_TRUE(s.contains("output_warnings"));
  EXPECT_EQ(s["values"]["kind"], "nodes");
  EXPECT_NEAR(s["mass"].back().get<double>(), std::numbers::pi, 0.05);
  r = run_hybgen("run '" + model + "' --set method=transfer --out '" + out.string() + "'",
                 kWork / "cache");
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  EXPECT_EQ(r.out.find("under-resolves"), std::string::npos) << r.out;
}

}  // namespace
