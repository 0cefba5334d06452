// models/gl3.model: the reduced GL3 system, 10 states, whose grid (33⁹·41 nodes) cannot be
// held. The particles keep the marginal of every pair of axes and the moments instead
// (density=marginals), and the run is checked against facts of the system that do not
// come from hybgen.
//
// The system (paper §4.3 with n = 3, H = ½ tr(ζζᵀ); checked here, not copied):
//   ζ' = ζᵀζ − ζζᵀ,  q' = (q + 1) tr ζ,  at q = 0 decreasing: ζ⁺ = ζ − (2/3) tr(ζ) I₃.
//  - tr ζ' = tr(ζᵀζ) − tr(ζζᵀ) = 0: tr ζ is constant between impacts.
//  - d/dt tr(ζζᵀ) = 2 tr(ζᵀζζᵀ − ζζᵀζᵀ) = 0 (the two traces are equal by cyclicity), and
//    |ζ⁺|² = |ζ|² − (4/3)(tr ζ)² + (4/9)(tr ζ)²·3 = |ζ|²: |ζ|² is conserved, impacts
//    included, so E|ζ|² over the mass in the box changes only by the mass that leaves it.
//  - tr ζ⁺ = tr ζ − 2 tr ζ = −tr ζ, and q + 1 = (q0 + 1)·e^{s t} with s = tr ζ between
//    impacts, q = 0 at one: with L = ln(1 + q0) + s0·t, q(t) = e^{|L|} − 1 and
//    tr ζ(t) = s0·sign L. With u0 ∝ exp(−4|ζ|² − 8(q − 1/2)²) on q ≥ 0, s0 = ζ1 + ζ5 + ζ9 is
//    N(0, 3/8) and independent of q0, so E q(t) and E tr ζ(t) are 2-D integrals, computed
//    below by quadrature.

#include <gtest/gtest.h>
#include <netcdf.h>

#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::rt::exit_status;
using hybgen::rt::ExitCode;
using hybgen::testing::e2e_dir;
using hybgen::testing::read_json_file;
using hybgen::testing::run_hybgen;

/// A variable of a NetCDF file, as doubles (empty when it is not there).
std::vector<double> nc_values(const fs::path& file, const std::string& name) {
  int id = -1, var = -1;
  if (nc_open(file.c_str(), NC_NOWRITE, &id) != NC_NOERR) return {};
  std::vector<double> out;
  if (nc_inq_varid(id, name.c_str(), &var) == NC_NOERR) {
    int ndims = 0;
    nc_inq_varndims(id, var, &ndims);
    std::vector<int> dims(static_cast<std::size_t>(ndims));
    nc_inq_vardimid(id, var, dims.data());
    std::size_t size = 1;
    for (const int d : dims) {
      std::size_t len = 0;
      nc_inq_dimlen(id, d, &len);
      size *= len;
    }
    out.resize(size);
    nc_get_var_double(id, var, out.data());
  }
  nc_close(id);
  return out;
}

/// E q(t) and E tr ζ(t) under u0, from the closed form above (midpoint rule: q0 on [0, 3]
/// in 3000 cells, s0 on ±8σ in 4000).
std::pair<double, double> closed_form(double t) {
  const double sd = std::sqrt(3.0 / 8.0);
  const int nq = 3000, ns = 4000;
  const double hq = 3.0 / nq, hs = 16.0 * sd / ns;
  double mass = 0.0, eq = 0.0, es = 0.0;
  for (int i = 0; i < nq; ++i) {
    const double q0 = (i + 0.5) * hq;
    const double pq = std::exp(-8.0 * (q0 - 0.5) * (q0 - 0.5));
    for (int j = 0; j < ns; ++j) {
      const double s0 = -8.0 * sd + (j + 0.5) * hs;
      const double w = pq * std::exp(-0.5 * s0 * s0 / (sd * sd));
      const double L = std::log1p(q0) + s0 * t;
      mass += w;
      eq += w * std::expm1(std::fabs(L));
      es += w * (L >= 0.0 ? s0 : -s0);
    }
  }
  return {eq / mass, es / mass};
}

/// Run gl3 with `extra` into `name`; its summary (the run must succeed).
nlohmann::json run_gl3(const std::string& name, const std::string& extra) {
  const fs::path dir = e2e_dir("gl3") / name;
  fs::remove_all(dir);
  const auto r = run_hybgen("run models/gl3.model -q " + extra + " --out '" + dir.string() + "'",
                            e2e_dir("gl3") / "cache", hybgen::testing::kMpiEnv);
  EXPECT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  return fs::exists(dir / "summary.json") ? read_json_file(dir / "summary.json")
                                          : nlohmann::json::object();
}

TEST(Gl3, ParticlesKeepMarginalsAndMomentsThatMatchTheClosedForm) {
  const nlohmann::json s = run_gl3("omp", "--set outputs=netcdf+png");
  const fs::path nc = e2e_dir("gl3") / "omp" / "run.nc";
  ASSERT_TRUE(fs::exists(nc));
  // No density on the grid; a marginal per pair (45), the moments.
  EXPECT_TRUE(nc_values(nc, "density").empty());
  EXPECT_EQ(nc_values(nc, "marginal_zeta1_zeta5").size(), 5u * 33 * 33);
  EXPECT_EQ(nc_values(nc, "marginal_zeta9_q").size(), 5u * 33 * 41);
  const std::vector<double> mean = nc_values(nc, "mean"), cov = nc_values(nc, "covariance");
  ASSERT_EQ(mean.size(), 5u * 10);
  ASSERT_EQ(cov.size(), 5u * 100);
  // Each particle keeps its |ζ|² and its weight, so E|ζ|² over the mass in the box changes
  // only by what leaves the box (q > 20, a rare particle with a large tr ζ): the outflow's
  // share of the mass times twice the largest |ζ|² of the support (6.25), and the ODE's
  // tolerance. (200000 particles: 1.1e-5 of the mass leaves by t = 1; E|ζ|² moves by 2.5e-5.)
  const auto outflow = s.at("outflow").get<std::vector<double>>();
  const auto in_box = s.at("mass").get<std::vector<double>>();
  const double mass0 = s.at("initial_mass").get<double>();
  for (const double o : outflow) EXPECT_LE(std::fabs(o), 1e-4 * mass0);
  auto energy = [&](std::size_t k) {
    double e = 0.0;
    for (std::size_t a = 0; a < 9; ++a)
      e += cov[(k * 10 + a) * 10 + a] + mean[k * 10 + a] * mean[k * 10 + a];
    return e;
  };
  for (std::size_t k = 1; k < 5; ++k)
    EXPECT_NEAR(energy(k), energy(0), 1e-8 * energy(0) + 2.0 * 6.25 * outflow[k] / in_box[k]);
  EXPECT_NEAR(energy(0), 9.0 / 8.0, 0.02);  // E|ζ|² = 9 × 1/8 under u0
  // E q and E tr ζ against the closed form. Their Monte-Carlo error is the standard
  // deviation over √n_eff. The product proposal (particles.hpp) fits this u0 up to its
  // support, so n_eff ≈ n; 10·sd/√n allows n_eff down to n/4 at 5σ. (Measured: within
  // 1.5·sd/√n at every frame.)
  const double n = s.at("particles").at("particles").get<double>();
  for (std::size_t k = 0; k < 5; ++k) {
    const double t = 0.25 * static_cast<double>(k);
    const auto [eq, es] = closed_form(t);
    const double mq = mean[k * 10 + 9];
    const double ms = mean[k * 10 + 0] + mean[k * 10 + 4] + mean[k * 10 + 8];
    double var_s = 0.0;
    for (const std::size_t a : {0, 4, 8})
      for (const std::size_t b : {0, 4, 8}) var_s += cov[(k * 10 + a) * 10 + b];
    const double var_q = cov[(k * 10 + 9) * 10 + 9];
    EXPECT_NEAR(mq, eq, 10.0 * std::sqrt(var_q / n)) << "E q at t = " << t;
    EXPECT_NEAR(ms, es, 10.0 * std::sqrt(var_s / n)) << "E tr zeta at t = " << t;
    std::printf("t = %.2f: E q %.5f (closed form %.5f), E tr zeta %.5f (%.5f)\n", t, mq, eq, ms,
                es);
  }
  // Impacts happened: by t = 1 the mean of tr ζ has left 0 (every impact flips it to > 0).
  EXPECT_GT(closed_form(1.0).second, 0.1);
  // A pair's marginal integrates to the mass in the box (trapezoid on its nodes).
  const std::vector<double> m15 = nc_values(nc, "marginal_zeta1_zeta5");
  const double h = 5.0 / 32.0;
  double integral = 0.0;
  for (std::size_t i = 0; i < 33; ++i)
    for (std::size_t j = 0; j < 33; ++j)
      integral += m15[4 * 33 * 33 + i * 33 + j] * (i == 0 || i == 32 ? 0.5 : 1.0) *
                  (j == 0 || j == 32 ? 0.5 : 1.0) * h * h;
  const double mass = s.at("mass").get<std::vector<double>>().back();
  EXPECT_NEAR(integral, mass, 1e-9 * mass);
  // The pictures show the pairs of figure_axes.
  EXPECT_TRUE(fs::exists(e2e_dir("gl3") / "omp" / "u_0004.png"));
}

TEST(Gl3, FullDensitiesOfTenDimensionsAreRefusedWithTheWayOut) {
  const fs::path dir = e2e_dir("gl3") / "refused";
  const auto r =
      run_hybgen("run models/gl3.model -q --set density=grid --out '" + dir.string() + "'",
                 e2e_dir("gl3") / "cache");
  // Refused by the checker, before anything is built: the way out is named.
  EXPECT_EQ(r.code, exit_status(ExitCode::UsageError)) << r.out;
  EXPECT_NE(r.out.find("density marginals"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(dir));
}

}  // namespace
