// The run's writers (runtime/src/io/run_outputs.cpp, netcdf.cpp) on a record made here: a
// 4-D grid with two modes, every kind of output, read back with NetCDF's C library, numpy's
// format reader (npy.hpp) and the .pvd/.vti text. The independent reader of run.nc is
// xarray (tests/e2e/test_run_nc.cpp); this file checks the layout under the sanitizers.

#include <gtest/gtest.h>
#include <netcdf.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "hybgen/rt/io/atomic_file.hpp"
#include "hybgen/rt/io/npy.hpp"
#include "hybgen/rt/io/run_outputs.hpp"
#include "support/files.hpp"

namespace {

namespace fs = std::filesystem;
using namespace hybgen::rt;

class RunOutputs : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("hybgen_run_outputs_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    // Axes a (3 nodes), b (4), c (2), d (5); modes "left", "right"; 3 frames.
    rec_.model = "made_up";
    rec_.method = "characteristics";
    rec_.axis_names = {"a", "b", "c", "d"};
    rec_.axes = {{0, 1, 3}, {-1, 1, 4}, {0, 2, 2}, {-2, 2, 5}};
    rec_.mode_names = {"left", "right"};
    rec_.param_names = {"k"};
    rec_.params = {0.25};
    rec_.times = {0, 0.5, 1};
    rec_.frame_names = {"u_0000", "u_0001", "u_0002"};
    const std::size_t n = rec_.n_node();
    values_.resize(3 * 2 * n);
    // A value that names its place: frame k, mode m, node i.
    for (std::size_t k = 0; k < 3; ++k)
      for (std::size_t m = 0; m < 2; ++m)
        for (std::size_t i = 0; i < n; ++i)
          values_[(k * 2 + m) * n + i] =
              static_cast<double>(k) + 0.1 * static_cast<double>(m) + 1e-4 * static_cast<double>(i);
    rec_.density = values_;
    rec_.budget.mass0 = 1;
    rec_.budget.mass = {1, 0.9, 0.7};
    rec_.budget.outflow = {0, 0.05, 0.2};
    rec_.budget.atom = {0, 0.04, 0.09};
    rec_.budget.mass_error = {1e-6, 2e-6, 3e-6};
    rec_.provenance = {{"model_text", "model made_up\n"}, {"model_sha256", "abc"}};
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string slurp(const std::string& name) const {
    return hybgen::testing::read_text(dir_ / name);
  }

  fs::path dir_;
  RunRecord rec_;
  std::vector<double> values_;
};

Settings with_outputs(const std::string& list) {
  Settings s;
  s.assign("outputs", {list, 0, false});
  return s;
}

TEST_F(RunOutputs, EveryKindInFourDimensionsWithTwoModes) {
  const WrittenOutputs w =
      write_run_outputs(rec_, with_outputs("netcdf+npy+vti+png"), dir_.string(), true);
  EXPECT_TRUE(fs::exists(dir_ / "budget.png"));
  EXPECT_EQ(w.netcdf, "run.nc");
  ASSERT_EQ(w.npy.size(), 3u);
  ASSERT_EQ(w.mode_npy.at("right").size(), 3u);
  EXPECT_EQ(w.figures.size(), 4u);  // 3 frames and the budget
  EXPECT_EQ(w.vti.size(), 3u);
  EXPECT_EQ(w.pvd, "u.pvd");
  ASSERT_EQ(w.notes.size(), 1u);  // 4-D: the images hold a 3-D marginal, and say so
  EXPECT_NE(w.notes[0].find("first three axes"), std::string::npos) << w.notes[0];
  for (const auto& f : {"run.nc", "u_0002.npy", "u_0002_left.npy", "u_0001.png", "u_0000.vti"})
    EXPECT_TRUE(fs::exists(dir_ / f)) << f;

  // The summed and per-mode arrays.
  const std::size_t n = rec_.n_node();
  const NpyArray total = read_npy((dir_ / "u_0001.npy").string());
  EXPECT_EQ(total.shape, (std::vector<std::size_t>{3, 4, 2, 5}));
  const NpyArray right = read_npy((dir_ / "u_0001_right.npy").string());
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_DOUBLE_EQ(right.data[i], values_[(1 * 2 + 1) * n + i]);
    EXPECT_DOUBLE_EQ(total.data[i], values_[(1 * 2 + 0) * n + i] + values_[(1 * 2 + 1) * n + i]);
  }

  // The .pvd lists the frames at their times; each image has the sum and each mode.
  const std::string pvd = slurp("u.pvd");
  EXPECT_NE(pvd.find("timestep=\"0.5\" group=\"\" part=\"0\" file=\"u_0001.vti\""),
            std::string::npos)
      << pvd;
  const std::string vti = slurp("u_0001.vti");
  for (const char* name :
       {"Name=\"u_marginal\"", "Name=\"u_marginal_left\"", "Name=\"u_marginal_right\""})
    EXPECT_NE(vti.find(name), std::string::npos) << name;
  EXPECT_NE(vti.find("WholeExtent=\"0 2 0 3 0 1\""), std::string::npos);  // axes a, b, c
}

TEST_F(RunOutputs, TheNetcdfLayout) {
  (void)write_run_outputs(rec_, with_outputs("netcdf"), dir_.string(), true);
  EXPECT_FALSE(fs::exists(dir_ / "u_0000.png"));  // only what was asked for
  int nc = -1;
  ASSERT_EQ(nc_open((dir_ / "run.nc").c_str(), NC_NOWRITE, &nc), NC_NOERR);
  int var = -1, ndims = 0;
  ASSERT_EQ(nc_inq_varid(nc, "density_by_mode", &var), NC_NOERR);
  ASSERT_EQ(nc_inq_varndims(nc, var, &ndims), NC_NOERR);
  EXPECT_EQ(ndims, 6);  // time, mode, a, b, c, d
  std::vector<double> by_mode(values_.size());
  ASSERT_EQ(nc_get_var_double(nc, var, by_mode.data()), NC_NOERR);
  EXPECT_EQ(by_mode, values_);  // the same layout as the solution: [time][mode][node]
  ASSERT_EQ(nc_inq_varid(nc, "unaccounted", &var), NC_NOERR);
  std::vector<double> defect(3);
  ASSERT_EQ(nc_get_var_double(nc, var, defect.data()), NC_NOERR);
  EXPECT_NEAR(defect[2], 1 - 0.7 - 0.2 - 0.09, 1e-15);
  ASSERT_EQ(nc_inq_varid(nc, "d", &var), NC_NOERR);
  std::vector<double> d(5);
  ASSERT_EQ(nc_get_var_double(nc, var, d.data()), NC_NOERR);
  EXPECT_EQ(d, (std::vector<double>{-2, -1, 0, 1, 2}));
  double k = 0;
  ASSERT_EQ(nc_get_att_double(nc, NC_GLOBAL, "parameter_k", &k), NC_NOERR);
  EXPECT_EQ(k, 0.25);
  std::size_t len = 0;
  ASSERT_EQ(nc_inq_attlen(nc, NC_GLOBAL, "model_text", &len), NC_NOERR);
  std::string text(len, '\0');
  ASSERT_EQ(nc_get_att_text(nc, NC_GLOBAL, "model_text", text.data()), NC_NOERR);
  EXPECT_EQ(text, "model made_up\n");
  nc_close(nc);
}

TEST_F(RunOutputs, AFailedWriteNamesTheFileAndLeavesNoTornNetcdf) {
  // The directory is gone: run.nc cannot be created, the error says which file.
  fs::remove_all(dir_);
  try {
    (void)write_run_outputs(rec_, with_outputs("netcdf"), dir_.string(), true);
    FAIL() << "expected an exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find((dir_ / "run.nc").string()), std::string::npos)
        << e.what();
  }
  fs::create_directories(dir_);
}

TEST(Marginal, KeepsTheAxesInTheOrderGivenAndIntegratesTheRest) {
  // u(a, b, c) = a + 10 b + 100 c on a 2 x 3 x 2 grid of unit spacing: the trapezoid weights
  // are 1/2 at both ends of each axis (and 1 inside).
  const std::vector<GridAxis> axes = {{0, 1, 2}, {0, 2, 3}, {0, 1, 2}};
  std::vector<double> u(12);
  for (std::size_t i = 0; i < 2; ++i)
    for (std::size_t j = 0; j < 3; ++j)
      for (std::size_t k = 0; k < 2; ++k)
        u[(i * 3 + j) * 2 + k] =
            static_cast<double>(i) + 10.0 * static_cast<double>(j) + 100.0 * static_cast<double>(k);
  // On (c, a): ∫ over b with weights 1/2, 1, 1/2 (sum 2): 2 (a + 100 c) + 10 (0 + 1 + 1).
  const std::vector<double> ca = marginal(u, axes, {2, 0});
  ASSERT_EQ(ca.size(), 4u);
  for (std::size_t k = 0; k < 2; ++k)
    for (std::size_t i = 0; i < 2; ++i)
      EXPECT_DOUBLE_EQ(ca[k * 2 + i],
                       2 * (static_cast<double>(i) + 100.0 * static_cast<double>(k)) + 20)
          << k << "," << i;
  // Nothing kept: the whole integral, equal to the marginal on (a) integrated over a.
  const std::vector<double> a = marginal(u, axes, {0});
  const std::vector<double> all = marginal(u, axes, {});
  ASSERT_EQ(all.size(), 1u);
  EXPECT_DOUBLE_EQ(all[0], 0.5 * a[0] + 0.5 * a[1]);
}

TEST_F(RunOutputs, DeferredDurabilitySyncsOnce) {
  // Inside the scope the files land (renamed into place) before the one sync; commit
  // reports the sync's failure by naming the directory.
  {
    const DeferredDurability durable(dir_.string());
    write_file_atomic((dir_ / "a.json").string(), "{}");
    EXPECT_TRUE(fs::exists(dir_ / "a.json"));
    EXPECT_NO_THROW(durable.commit());
  }
  const DeferredDurability missing((dir_ / "nope").string());
  try {
    missing.commit();
    FAIL() << "expected an exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("nope"), std::string::npos) << e.what();
  }
}

}  // namespace
