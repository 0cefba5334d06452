// Validation: method=escape (runtime/include/hybgen/rt/methods/escape.hpp) through the whole
// pipeline — `hybgen run FILE --set method=escape` on the open systems of
// tests/validation/escape_*.model, which hybgen does not ship — against closed forms derived
// in those files (none comes from hybgen):
//   escape_linear.model      x' = a x on [0, 1]: κ = a, the uniform density;
//   escape_logistic.model    x' = a x (1 + x) on [0, 1]: κ = a, v(x) = 2/(1 + x)²;
//   escape_thermostat.model  two modes, the thermostat cycle in T times y' = c y (1 + y²) on
//                            [−1, 1]: κ = c, u_m(T, y) = w(y)/(ln 3 |T'_m|) with
//                            w(y) = 1/(√2 (1 + y²)^{3/2}).
// The argument for κ = f'(0) in 1-D: a density that decays in shape, u = e^{−κt} v, solves
// −κ v + (f v)' = 0, so f v = C exp(∫ κ/f) ~ x^{κ/a} near the repelling fixed point x = 0
// (f ≈ a x); v is bounded there only for κ = a. The grid's smoothing (transfer.hpp) selects
// that bounded density.
//
// Measured (h = 0.05, hat): x' = a x is exact on the grid (|κ − a| ≤ 1e-10 at 51 … 801
// nodes, the density uniform to 4e-5 (a = 1) and 4e-4 (a = 2) in relative L1), so there the
// estimate is the eigen-solver's tol/h = 2e-9; x' = x (1 + x) converges at first order
// (escape.hpp's table), the estimate 2|κ_h − κ_2h| is 1.97× the error at 201 nodes.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "hybgen/rt/io/npy.hpp"
#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::testing::read_json_file;
using hybgen::testing::run_hybgen;
using hybgen::testing::ShellResult;
using json = nlohmann::json;

const fs::path kWork = hybgen::testing::e2e_dir("validation_escape");

/// The path of tests/validation/`name`.
std::string model(const std::string& name) {
  return std::string(HYBGEN_SOURCE_DIR) + "/tests/validation/" + name;
}

/// `hybgen run MODEL --set method=escape SETS` into kWork/`dir`.
ShellResult run_escape(const std::string& dir, const std::string& file, const std::string& sets) {
  const fs::path out = hybgen::testing::own_dir(kWork) / dir;
  fs::remove_all(out);
  return run_hybgen("run '" + model(file) + "' --quiet --set method=escape " + sets + " --out '" +
                        out.string() + "'",
                    kWork / "cache");
}

/// The escape block of kWork/`dir`/summary.json.
json escape_block(const std::string& dir) {
  const json s = read_json_file(hybgen::testing::own_dir(kWork) / dir / "summary.json");
  EXPECT_EQ(s["method"], "escape");
  EXPECT_TRUE(s["times"].empty());  // one frame, no time series
  return s["escape"];
}

/// Relative L1 distance Σ w|u − v| / Σ w|v| with the trapezoid weights of a 1-D grid of
/// `u.size()` nodes (per axis `nx` × `ny` in 2-D: the caller flattens).
double rel_l1_1d(const std::vector<double>& u, double (*exact)(double), double lo, double hi) {
  const std::size_t n = u.size();
  double num = 0.0, den = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double x = lo + (hi - lo) * static_cast<double>(i) / static_cast<double>(n - 1);
    const double w = (i == 0 || i + 1 == n) ? 0.5 : 1.0;
    num += w * std::fabs(u[i] - exact(x));
    den += w * std::fabs(exact(x));
  }
  return num / den;
}

double uniform(double) {
  return 1.0;
}
double logistic_density(double x) {
  return 2.0 / ((1.0 + x) * (1.0 + x));
}

TEST(Escape, LinearLeakHasRateAAndAUniformDensity) {
  // x' = a x on [0, 1] (escape_linear.model), 201 nodes, h = dt = 0.05. κ = a within the
  // reported error; the hat scheme is exact here (the true error is rounding and the forward
  // flow's tolerance, ≤ 1e-10 measured), so the estimate is its floor, the eigen-solver's
  // tol/h = 2e-9, plus 2|κ_h − κ_2h| (≤ 1e-10): asserted at most 10× the true error beyond
  // that floor. The density: uniform within 1e-3 in relative L1 (measured 4e-5 for a = 1,
  // 4e-4 for a = 2: the hat deposit's smoothing at the outflow face x = 1).
  for (const double a : {1.0, 2.0}) {
    SCOPED_TRACE("a = " + std::to_string(a));
    const std::string dir = a == 1.0 ? "linear_a1" : "linear_a2";
    const ShellResult r = run_escape(dir, "escape_linear.model",
                                     "--set a=" + std::to_string(a) + " --set outputs=npy");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(r.out.find("closed"), std::string::npos) << r.out;  // an open system
    const json e = escape_block(dir);
    const double rate = e["rate"], err = e["rate_error"], solver_floor = e["solver_error"];
    const double truth = std::fabs(rate - a);
    std::printf("escape_linear a = %g: kappa = %.12f, rate_error %.3e, true error %.3e\n", a, rate,
                err, truth);
    EXPECT_EQ(e["step"], 0.05);
    EXPECT_NEAR(e["lambda1"].get<double>(), std::exp(-a * 0.05), 1e-9);
    EXPECT_LE(truth, err);
    EXPECT_LE(err, 10.0 * truth + solver_floor * 1.0000001);
    EXPECT_EQ(e["closed"], false);
    EXPECT_EQ(e["file"], "escape.npy");
    const auto u =
        hybgen::rt::read_npy((hybgen::testing::own_dir(kWork) / dir / "escape.npy").string());
    ASSERT_EQ(u.data.size(), 201u);
    const double l1 = rel_l1_1d(u.data, uniform, 0.0, 1.0);
    std::printf("escape_linear a = %g: density rel L1 from uniform %.3e\n", a, l1);
    EXPECT_LT(l1, 1e-3);
  }
}

TEST(Escape, LogisticLeakCalibratesTheErrorEstimate) {
  // x' = x (1 + x) on [0, 1] (escape_logistic.model), 201 nodes, h = 0.05: κ = 1 with an
  // O(Δx) error (1.23e-2 measured) that the estimate must cover, by at most 10×
  // (escape.hpp: 1.97× measured). The density 2/(1 + x)² within 2e-2 in relative L1
  // (9.1e-3 measured; first order too: 1.8e-2 at 101 nodes, 4.6e-3 at 401).
  const ShellResult r = run_escape("logistic", "escape_logistic.model", "--set outputs=npy");
  ASSERT_EQ(r.code, 0) << r.out;
  const json e = escape_block("logistic");
  const double rate = e["rate"], err = e["rate_error"], truth = std::fabs(rate - 1.0);
  std::printf("escape_logistic: kappa = %.8f, rate_error %.3e, true error %.3e (%.2fx)\n", rate,
              err, truth, err / truth);
  EXPECT_LE(truth, err);
  EXPECT_LE(err, 10.0 * truth);
  const auto u =
      hybgen::rt::read_npy((hybgen::testing::own_dir(kWork) / "logistic" / "escape.npy").string());
  ASSERT_EQ(u.data.size(), 201u);
  const double l1 = rel_l1_1d(u.data, logistic_density, 0.0, 1.0);
  std::printf("escape_logistic: density rel L1 %.3e\n", l1);
  EXPECT_LT(l1, 2e-2);
}

/// w(y) = 1/(√2 (1 + y²)^{3/2}): the y-part of escape_thermostat.model, unit mass on [−1, 1].
double thermostat_w(double y) {
  return 1.0 / (std::sqrt(2.0) * std::pow(1.0 + y * y, 1.5));
}

TEST(Escape, HybridThermostatTimesAnOpenAxis) {
  // escape_thermostat.model (its comment derives the closed form): two modes switching on
  // T = 2 and T = 1 with identity resets, the y-axis open. κ = c = 1 within the reported
  // error, the error at most 10× the true error; the density per mode within 3e-2 of
  // u_m(T, y) = w(y)/(ln 3 |T'_m|) in relative L1 over both modes (101 × 101 nodes).
  // Measured: κ − 1 = 2.88e-3, rate_error 1.69e-2 (5.9×: κ_2h − 1 = 1.13e-2, nearly second
  // order here, with the fixed point y = 0 on a node in the middle of the box), density
  // 1.6e-2.
  const ShellResult r = run_escape("thermostat", "escape_thermostat.model", "--set outputs=npy");
  ASSERT_EQ(r.code, 0) << r.out;
  const json e = escape_block("thermostat");
  const double rate = e["rate"], err = e["rate_error"], truth = std::fabs(rate - 1.0);
  std::printf("escape_thermostat: kappa = %.8f, rate_error %.3e, true error %.3e (%.2fx)\n", rate,
              err, truth, err / truth);
  EXPECT_LE(truth, err);
  EXPECT_LE(err, 10.0 * truth);
  const std::size_t n = 101;
  double num = 0.0, den = 0.0;
  for (const char* mode : {"heat", "cool"}) {
    const auto u = hybgen::rt::read_npy(
        (hybgen::testing::own_dir(kWork) / "thermostat" / (std::string("escape_") + mode + ".npy"))
            .string());
    ASSERT_EQ(u.data.size(), n * n) << mode;
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = 0; j < n; ++j) {
        const double T = 1.0 + static_cast<double>(i) / static_cast<double>(n - 1);
        const double y = -1.0 + 2.0 * static_cast<double>(j) / static_cast<double>(n - 1);
        const double w =
            ((i == 0 || i + 1 == n) ? 0.5 : 1.0) * ((j == 0 || j + 1 == n) ? 0.5 : 1.0);
        const double speed = mode[0] == 'h' ? 4.0 - T : T;
        const double exact = thermostat_w(y) / (std::log(3.0) * speed);
        num += w * std::fabs(u.data[i * n + j] - exact);
        den += w * exact;
      }
  }
  std::printf("escape_thermostat: density rel L1 %.3e\n", num / den);
  EXPECT_LT(num / den, 3e-2);
}

TEST(Escape, AClosedSystemIsToldToUseInvariant) {
  // escape_thermostat.model with c = 0: y' = 0, nothing leaves the box (the thermostat's
  // guards sit on the T faces), λ₁ = 1 within its error: a warning that names
  // method=invariant, and `closed` in summary.json.
  const ShellResult r = run_escape("closed", "escape_thermostat.model",
                                   "--set c=0 --set grid=41x41 --set outputs=npy");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("the system is closed"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("use method=invariant"), std::string::npos) << r.out;
  const json e = escape_block("closed");
  EXPECT_EQ(e["closed"], true);
  EXPECT_LE(std::fabs(e["rate"].get<double>()), e["rate_error"].get<double>());
}

TEST(Escape, RunNcAndTheReportCarryTheRate) {
  // run.nc's global attributes escape_rate, escape_rate_error (with their units) read by an
  // independent reader (Debian's python3-netcdf4), and the line in report.html.
  const ShellResult r = run_escape("outputs", "escape_linear.model",
                                   "--set a=2 --set grid=51 --set outputs=netcdf+html");
  ASSERT_EQ(r.code, 0) << r.out;
  const json e = escape_block("outputs");
  std::ifstream in(hybgen::testing::own_dir(kWork) / "outputs" / "report.html");
  std::stringstream html;
  html << in.rdbuf();
  EXPECT_NE(html.str().find("escape rate 2 ± "), std::string::npos);
  const std::string python = hybgen::testing::python_with("netCDF4");
  HYBGEN_REQUIRE_PYTHON(python, "netCDF4");
  const ShellResult nc = hybgen::testing::run_shell(
      python + " -c \"import netCDF4; d = netCDF4.Dataset('" +
      (hybgen::testing::own_dir(kWork) / "outputs" / "run.nc").string() +
      "'); print(float(d.escape_rate), float(d.escape_rate_error), d.escape_rate_units, "
      "d.variables['density'].long_name)\" 2>&1");
  ASSERT_EQ(nc.code, 0) << nc.out;
  std::istringstream words(nc.out);
  double rate = 0.0, err = 0.0;
  std::string units1, units2, units3;
  words >> rate >> err >> units1 >> units2 >> units3;
  EXPECT_EQ(rate, e["rate"].get<double>()) << nc.out;
  EXPECT_EQ(err, e["rate_error"].get<double>()) << nc.out;
  EXPECT_EQ(units1 + " " + units2 + " " + units3, "per unit time") << nc.out;
  EXPECT_NE(nc.out.find("conditionally invariant density"), std::string::npos) << nc.out;
}

TEST(Escape, SweepHasTheEscapeRateColumn) {
  // `hybgen sweep` over a: the escape_rate and escape_rate_error columns, κ = a per row.
  const fs::path out = hybgen::testing::own_dir(kWork) / "sweep";
  fs::remove_all(out);
  const ShellResult r =
      run_hybgen("sweep '" + model("escape_linear.model") +
                     "' --set a=1:3:3 --set grid=51 --set outputs=npy --jobs 1 --quiet --out '" +
                     out.string() + "'",
                 kWork / "cache");
  ASSERT_EQ(r.code, 0) << r.out;
  const json table = read_json_file(out / "sweep.json");
  ASSERT_EQ(table["rows"].size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    const json& row = table["rows"][i];
    const double a = 1.0 + static_cast<double>(i);
    EXPECT_EQ(row["method"], "escape");
    EXPECT_NEAR(row["escape_rate"].get<double>(), a, row["escape_rate_error"].get<double>()) << i;
  }
  std::ifstream in(out / "sweep.csv");
  std::string header;
  std::getline(in, header);
  EXPECT_NE(header.find("escape_rate"), std::string::npos) << header;
  EXPECT_NE(header.find("escape_rate_error"), std::string::npos) << header;
}

TEST(Escape, RunHelpListsTheMethod) {
  const ShellResult r = run_hybgen("run --help", kWork / "cache");
  EXPECT_NE(r.out.find("escape"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("conditionally invariant density"), std::string::npos) << r.out;
}

}  // namespace
