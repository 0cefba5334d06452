// The run's files (hybgen/rt/io/run_outputs.hpp): what is written, in parallel.

#include "hybgen/rt/io/run_outputs.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <mutex>
#include <string>
#include <vector>

#include "hybgen/rt/io/figures.hpp"
#include "hybgen/rt/io/netcdf.hpp"
#include "hybgen/rt/io/npy.hpp"
#include "hybgen/rt/io/progress.hpp"
#include "hybgen/rt/io/report.hpp"
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

std::string resolution_warning(const RunRecord& run) {
  const MassBudget& b = run.budget;
  const std::size_t K = run.times.size();
  if (K == 0 || b.mass.size() != K || b.mass_error.size() != K || !(b.mass0 > 0)) return "";
  // Marginals are deposited from the particles by cloud-in-cell: their sum is the mass.
  if (run.marginals) return "";
  double worst = 0, worst_sum = 0;
  std::size_t worst_k = K;
  for (std::size_t k = 0; k < K; ++k) {
    const std::vector<double> u = run.total_density(k);
    const double sum = marginal(u, run.axes, {}).front();  // the trapezoid sum of the nodes
    const double gap = std::fabs(sum - b.mass[k]);
    if (gap > 0.05 * b.mass0 && gap > 10 * b.mass_error[k] && gap > worst)
      worst = gap, worst_sum = sum, worst_k = k;
  }
  if (worst_k == K) return "";
  char msg[640];
  std::snprintf(msg, sizeof msg,
                "the grid under-resolves the density: at t = %g the nodes' trapezoid sum is %.4g "
                "but the mass is %.4g +/- %.2g (adaptive cubature), so the density has features "
                "narrower than the grid's spacing and the pictures and run.nc show node samples "
                "of them (speckle), not their shape; refine the grid, or use cell averages: "
                "--set method=transfer --set scheme=cell, or method=particles",
                run.times[worst_k], worst_sum, b.mass[worst_k], b.mass_error[worst_k]);
  return msg;
}

nlohmann::json WrittenOutputs::to_json() const {
  nlohmann::json j = nlohmann::json::object();
  if (!netcdf.empty()) j["netcdf"] = netcdf;
  if (!npy.empty()) j["npy"] = npy;
  if (!mode_npy.empty()) j["mode_npy"] = mode_npy;
  if (!figures.empty()) j["figures"] = figures;
  if (!vti.empty()) j["vti"] = vti;
  if (!pvd.empty()) j["pvd"] = pvd;
  if (!report.empty()) j["report"] = report;
  return j;
}

std::string WrittenOutputs::describe(const std::vector<std::string>& frame_names) const {
  std::string kinds;
  if (!npy.empty()) kinds += "/.npy";
  for (const char* ext : {".png", ".svg"})
    if (std::any_of(figures.begin(), figures.end(),
                    [&](const std::string& f) { return f.ends_with(std::string(ext)); }))
      kinds += std::string("/") + ext;
  if (!vti.empty()) kinds += "/.vti";
  std::string out = netcdf;
  if (!kinds.empty() && !frame_names.empty()) {
    if (!out.empty()) out += ", ";
    out += frame_names.size() == 1 ? frame_names.front()
                                   : frame_names.front() + ".." + frame_names.back();
    out += " " + kinds.substr(1);
  }
  for (const std::string& f : figures)
    if (f.ends_with(".pdf") || f.ends_with(".gif") || f.rfind("budget", 0) == 0 ||
        f.rfind("spectrum", 0) == 0)
      out += ", " + f;
  if (!report.empty()) out += ", " + report;
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
  FigureRequest figures;
  figures.png = settings.includes<"outputs">("png");
  figures.pdf = settings.includes<"outputs">("pdf");
  figures.svg = settings.includes<"outputs">("svg");
  figures.gif = settings.includes<"outputs">("gif");
  const bool html = settings.includes<"outputs">("html");
  figures.scale = settings.word<"figure_scale">();
  const bool vti = settings.includes<"outputs">("vti");

  WrittenOutputs w;
  for (std::size_t k = 0; k < K; ++k) {
    const std::string& base = run.frame_names[k];
    if (npy) {
      w.npy.push_back(base + ".npy");
      if (n_mode > 1)
        for (const std::string& m : run.mode_names)
          w.mode_npy[m].push_back(base + "_" + m + ".npy");
    }
    if (vti) w.vti.push_back(base + ".vti");
  }
  if (netcdf) w.netcdf = "run.nc";
  if (std::string why = resolution_warning(run); !why.empty()) w.warnings.push_back(why);
  if (vti && !run.times.empty()) w.pvd = "u.pvd";
  if (vti && run.axes.size() > 3)
    w.notes.push_back("the .vti images hold the marginal density on the first three axes (" +
                      run.axis_names[0] + ", " + run.axis_names[1] + ", " + run.axis_names[2] +
                      "): VTK images have three axes; run.nc has the whole grid");

  // Frames over threads; run.nc (NetCDF is not thread-safe: one writer) beside them.
  FirstError error;
  Progress progress("writing outputs", K + (netcdf ? 1 : 0) + 1, quiet);
#pragma omp parallel
  {
#pragma omp single nowait
    if (netcdf) {
      error.run([&] { write_netcdf((out / w.netcdf).string(), run); });
      progress.advance();
    }
#pragma omp for schedule(dynamic)
    for (std::size_t k = 0; k < K; ++k) {
      // Arrays of the whole grid, which marginals do not have (the runner refuses npy and
      // vti with them).
      if (npy || vti)
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
          if (vti) write_image(run, k, total, (out / (base + ".vti")).string());
        });
      progress.advance();
    }
  }
  error.rethrow();
  // The pictures: frames in parallel inside (one colour scale for the run needs every frame).
  if (figures.png || figures.pdf || figures.svg || figures.gif) {
    write_figures(run, figures, dir);
    w.figures = figures.out;
  }
  // The report, last: it links what was written.
  if (html) {
    std::vector<std::string> files = w.figures;
    if (!w.netcdf.empty()) files.push_back(w.netcdf);
    if (!w.pvd.empty()) files.push_back(w.pvd);
    if (const std::string why = write_report(run, files, dir); !why.empty())
      w.warnings.push_back(why);
    w.report = "report.html";
  }
  progress.advance();
  progress.finish();
  if (!w.pvd.empty()) write_pvd((out / w.pvd).string(), w.vti, run.times);
  return w;
}

}  // namespace hybgen::rt
