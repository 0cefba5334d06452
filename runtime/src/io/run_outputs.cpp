// The run's files (hybgen/rt/io/run_outputs.hpp): what is written, in parallel.

#include "hybgen/rt/io/run_outputs.hpp"

#include <omp.h>

#include <exception>
#include <filesystem>
#include <mutex>
#include <string>
#include <vector>

#include "hybgen/rt/io/netcdf.hpp"
#include "hybgen/rt/io/npy.hpp"
#include "hybgen/rt/io/png.hpp"
#include "hybgen/rt/io/progress.hpp"
#include "hybgen/rt/io/vti.hpp"

namespace hybgen::rt {

namespace {

/// The first exception thrown by any thread, rethrown once they have all finished.
class FirstError {
 public:
  template <class F>
  void run(F&& f) noexcept {
    try {
      f();
    } catch (...) {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (!error_) error_ = std::current_exception();
    }
  }
  void rethrow() const {
    if (error_) std::rethrow_exception(error_);
  }

 private:
  std::mutex mutex_;
  std::exception_ptr error_;
};

/// t with three decimals (a frame's title).
std::string fixed3(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.3f", v);
  return b;
}

/// The marginal of `u` (C order, `shape`) on the axes `keep`, integrating the others with
/// the trapezoid rule of their grid axes.
std::vector<double> marginal(const std::vector<double>& u, const std::vector<GridAxis>& axes,
                             const std::vector<std::size_t>& keep) {
  const std::size_t N = axes.size();
  std::vector<std::vector<double>> w(N);
  std::vector<bool> kept(N, false);
  for (std::size_t a : keep) kept[a] = true;
  for (std::size_t a = 0; a < N; ++a)
    if (!kept[a]) w[a] = trapezoid_rule(axes[a]).weights;
  std::size_t n_out = 1;
  for (std::size_t a : keep) n_out *= static_cast<std::size_t>(axes[a].n);
  std::vector<double> out(n_out, 0.0);
  std::vector<std::size_t> idx(N, 0);
  for (std::size_t i = 0; i < u.size(); ++i) {
    // idx = the multi-index of node i (C order).
    std::size_t rem = i;
    for (std::size_t a = N; a-- > 0;) {
      idx[a] = rem % static_cast<std::size_t>(axes[a].n);
      rem /= static_cast<std::size_t>(axes[a].n);
    }
    double weight = 1.0;
    std::size_t o = 0;
    for (std::size_t a = 0; a < N; ++a) {
      if (kept[a])
        o = o * static_cast<std::size_t>(axes[a].n) + idx[a];
      else
        weight *= w[a][idx[a]];
    }
    out[o] += weight * u[i];
  }
  return out;
}

/// The frame's picture: a line plot (1-D), a heat map (2-D), the marginal on the first two
/// axes (3-D and more).
void write_picture(const RunRecord& run, std::size_t k, const std::vector<double>& total,
                   const std::string& path) {
  const std::size_t N = run.axes.size();
  std::string title = run.model + "   ";
  title += run.times.empty() ? std::string("invariant density (transfer operator)")
                             : run.method + "   t = " + fixed3(run.times[k]);
  if (run.n_mode() > 1) title += "   (sum over modes)";
  const auto n = [&](std::size_t a) { return static_cast<std::size_t>(run.axes[a].n); };
  if (N == 1) {
    std::vector<double> xs(n(0));
    for (std::size_t i = 0; i < xs.size(); ++i)
      xs[i] = axis_node(run.axes[0], static_cast<int>(i));
    write_lineplot_png(path, xs, total, run.axis_names[0], "u", title);
  } else if (N == 2) {
    write_heatmap_png(path, total.data(), n(0), n(1), run.axis_names[0], run.axes[0].min,
                      run.axes[0].max, run.axis_names[1], run.axes[1].min, run.axes[1].max, title,
                      run.outside.empty() ? nullptr : run.outside.data());
  } else {
    const std::vector<double> m = marginal(total, run.axes, {0, 1});
    std::string others;
    for (std::size_t a = 2; a < N; ++a) others += (a > 2 ? ", " : "") + run.axis_names[a];
    write_heatmap_png(path, m.data(), n(0), n(1), run.axis_names[0], run.axes[0].min,
                      run.axes[0].max, run.axis_names[1], run.axes[1].min, run.axes[1].max,
                      title + "   marginal over " + others);
  }
}

/// The frame's VTK image: the summed density and each mode's (several modes) on the grid,
/// or for 4 and more axes their marginals on the first three (VTK images have three axes).
void write_image(const RunRecord& run, std::size_t k, const std::vector<double>& total,
                 const std::string& path) {
  const std::size_t N = run.axes.size(), kept = std::min<std::size_t>(N, 3);
  std::vector<std::size_t> dims, keep;
  std::vector<double> origins, spacings;
  std::vector<std::string> names;
  for (std::size_t a = 0; a < kept; ++a) {
    keep.push_back(a);
    dims.push_back(static_cast<std::size_t>(run.axes[a].n));
    origins.push_back(run.axes[a].min);
    spacings.push_back((run.axes[a].max - run.axes[a].min) / (run.axes[a].n - 1));
    names.push_back(run.axis_names[a]);
  }
  std::vector<std::vector<double>> arrays;
  std::vector<std::string> labels;
  const auto reduce = [&](const std::vector<double>& u) {
    return N <= 3 ? u : marginal(u, run.axes, keep);
  };
  arrays.push_back(reduce(total));
  labels.push_back(N <= 3 ? "u" : "u_marginal");
  if (run.n_mode() > 1)
    for (std::size_t m = 0; m < run.n_mode(); ++m) {
      const std::span<const double> u = run.mode_density(k, m);
      arrays.push_back(reduce(std::vector<double>(u.begin(), u.end())));
      labels.push_back(labels.front() + "_" + run.mode_names[m]);
    }
  std::vector<VtiField> fields;
  for (std::size_t i = 0; i < arrays.size(); ++i) fields.push_back({labels[i], arrays[i].data()});
  write_vti(path, fields, dims, origins, spacings, names);
}

}  // namespace

nlohmann::json WrittenOutputs::to_json() const {
  nlohmann::json j = nlohmann::json::object();
  if (!netcdf.empty()) j["netcdf"] = netcdf;
  if (!npy.empty()) j["npy"] = npy;
  if (!mode_npy.empty()) j["mode_npy"] = mode_npy;
  if (!png.empty()) j["png"] = png;
  if (!vti.empty()) j["vti"] = vti;
  if (!pvd.empty()) j["pvd"] = pvd;
  return j;
}

std::string WrittenOutputs::describe(const std::vector<std::string>& frame_names) const {
  std::string kinds;
  if (!npy.empty()) kinds += "/.npy";
  if (!png.empty()) kinds += "/.png";
  if (!vti.empty()) kinds += "/.vti";
  std::string out = netcdf;
  if (!kinds.empty() && !frame_names.empty()) {
    if (!out.empty()) out += ", ";
    out += frame_names.size() == 1 ? frame_names.front()
                                   : frame_names.front() + ".." + frame_names.back();
    out += " " + kinds.substr(1);
  }
  if (!pvd.empty()) out += ", " + pvd;
  return out;
}

WrittenOutputs write_run_outputs(const RunRecord& run, const Settings& settings,
                                 const std::string& dir, bool quiet) {
  const std::filesystem::path out(dir);
  const std::size_t K = run.n_frame(), n_mode = run.n_mode();
  std::vector<std::size_t> shape;
  for (const GridAxis& a : run.axes) shape.push_back(static_cast<std::size_t>(a.n));
  const bool netcdf = settings.includes<"outputs">("netcdf");
  const bool npy = settings.includes<"outputs">("npy");
  const bool png = settings.includes<"outputs">("png");
  const bool vti = settings.includes<"outputs">("vti");

  WrittenOutputs w;
  for (std::size_t k = 0; k < K; ++k) {
    const std::string& base = run.frame_names[k];
    if (npy) {
      w.npy.push_back(base + ".npy");
      if (n_mode > 1)
        for (const std::string& m : run.mode_names) w.mode_npy[m].push_back(base + "_" + m + ".npy");
    }
    if (png) w.png.push_back(base + ".png");
    if (vti) w.vti.push_back(base + ".vti");
  }
  if (netcdf) w.netcdf = "run.nc";
  if (vti && !run.times.empty()) w.pvd = "u.pvd";
  if (vti && run.axes.size() > 3)
    w.notes.push_back("the .vti images hold the marginal density on the first three axes (" +
                      run.axis_names[0] + ", " + run.axis_names[1] + ", " + run.axis_names[2] +
                      "): VTK images have three axes; run.nc has the whole grid");

  // Frames over threads; run.nc (NetCDF is not thread-safe: one writer) beside them.
  FirstError error;
  Progress progress("writing outputs", K + (netcdf ? 1 : 0), quiet);
#pragma omp parallel
  {
#pragma omp single nowait
    if (netcdf) {
      error.run([&] { write_netcdf((out / w.netcdf).string(), run); });
      progress.advance();
    }
#pragma omp for schedule(dynamic)
    for (std::size_t k = 0; k < K; ++k) {
      error.run([&] {
        const std::vector<double> total = run.total_density(k);
        const std::string& base = run.frame_names[k];
        if (npy) {
          write_npy((out / (base + ".npy")).string(), total, shape);
          if (n_mode > 1)
            for (std::size_t m = 0; m < n_mode; ++m)
              write_npy((out / (base + "_" + run.mode_names[m] + ".npy")).string(),
                        run.mode_density(k, m).data(), shape);
        }
        if (png) write_picture(run, k, total, (out / (base + ".png")).string());
        if (vti) write_image(run, k, total, (out / (base + ".vti")).string());
      });
      progress.advance();
    }
  }
  progress.finish();
  error.rethrow();
  if (!w.pvd.empty()) write_pvd((out / w.pvd).string(), w.vti, run.times);
  return w;
}

}  // namespace hybgen::rt
