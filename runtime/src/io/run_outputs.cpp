// The run's files (hybgen/rt/io/run_outputs.hpp): what is written, in parallel.

#include "hybgen/rt/io/run_outputs.hpp"

#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
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

/// Whether resolution_warning compares anything: a time series whose budget measured the
/// mass by adaptive cubature, with the density on every node.
bool resolution_checked(const RunRecord& run) {
  const MassBudget& b = run.budget;
  const std::size_t K = run.times.size();
  // Marginals are deposited from the particles by cloud-in-cell: their sum is the mass.
  return K > 0 && b.mass.size() == K && b.mass_error.size() == K && b.mass0 > 0 &&
         run.marginals == nullptr;
}

/// resolution_warning from the trapezoid sums of the nodes per frame.
std::string resolution_warning(const RunRecord& run, const std::vector<double>& sums) {
  const MassBudget& b = run.budget;
  const std::size_t K = run.times.size();
  if (!resolution_checked(run) || sums.size() != K) return "";
  const std::size_t k = under_resolved_frame(b, sums);
  if (k == K) return "";
  char msg[760];
  std::snprintf(msg, sizeof msg,
                "the grid under-resolves the density: at t = %g the %s trapezoid sum is %.4g "
                "but the mass is %.4g +/- %.2g (adaptive cubature), so the density has features "
                "narrower than the grid's spacing and the pictures and run.nc show samples of "
                "them (speckle), not their shape; refine the grid, or use cell averages: --set "
                "values=cells (the exact density's mean over each node's dual cell; "
                "budget=full refines them further), method=transfer (cell masses), or "
                "method=particles",
                run.times[k], run.cell_averages ? "cell averages'" : "nodes'", sums[k], b.mass[k],
                b.mass_error[k]);
  return msg;
}

/// The files `settings` asks for, by name (the same list on every rank).
WrittenOutputs planned_outputs(const RunRecord& run, const Settings& settings) {
  WrittenOutputs w;
  const bool npy = settings.includes<"outputs">("npy"), vti = settings.includes<"outputs">("vti");
  for (std::size_t k = 0; k < run.n_frame(); ++k) {
    const std::string& base = run.frame_names[k];
    if (npy) {
      w.npy.push_back(base + ".npy");
      if (run.n_mode() > 1)
        for (const std::string& m : run.mode_names)
          w.mode_npy[m].push_back(base + "_" + m + ".npy");
    }
    if (vti) w.vti.push_back(base + ".vti");
  }
  if (settings.includes<"outputs">("netcdf")) w.netcdf = "run.nc";
  if (vti && !run.times.empty()) w.pvd = "u.pvd";
  if (vti && run.axes.size() > 3)
    w.notes.push_back("the .vti images hold the marginal density on the first three axes (" +
                      run.axis_names[0] + ", " + run.axis_names[1] + ", " + run.axis_names[2] +
                      "): VTK images have three axes; run.nc has the whole grid");
  return w;
}

/// The pictures and the report of `run` (figures.hpp, report.hpp) into `w`.
void write_pictures_and_report(const RunRecord& run, const Settings& settings,
                               const std::string& dir, WrittenOutputs& w) {
  FigureRequest figures;
  figures.png = settings.includes<"outputs">("png");
  figures.pdf = settings.includes<"outputs">("pdf");
  figures.svg = settings.includes<"outputs">("svg");
  figures.gif = settings.includes<"outputs">("gif");
  figures.scale = settings.word<"figure_scale">();
  // The pictures: frames in parallel inside (one colour scale for the run needs every frame).
  if (figures.png || figures.pdf || figures.svg || figures.gif) {
    write_figures(run, figures, dir);
    w.figures = figures.out;
  }
  // The report, last: it links what was written.
  if (settings.includes<"outputs">("html")) {
    std::vector<std::string> files = w.figures;
    if (!w.netcdf.empty()) files.push_back(w.netcdf);
    if (!w.pvd.empty()) files.push_back(w.pvd);
    if (const std::string why = write_report(run, files, dir); !why.empty())
      w.warnings.push_back(why);
    w.report = "report.html";
  }
}

/// Every rank runs `f`; if it threw on some rank, every rank throws the message of the
/// lowest such rank (so that no rank waits in a collective that the others left).
template <class F>
void on_every_rank(const Backend& b, F&& f) {
  std::string error;
  try {
    f();
  } catch (const std::exception& e) {
    error = e.what();
    if (error.empty()) error = "an output failed";
  }
  const std::int64_t none = b.ranks();
  const std::int64_t first = b.min(error.empty() ? none : std::int64_t{b.rank()});
  if (first == none) return;
  throw std::runtime_error(b.broadcast(error, static_cast<int>(first)));
}

/// The outputs of a run distributed over ranks (RunRecord::distributed), on every rank. No
/// rank gathers a frame of the grid:
///  - the density summed over the modes is formed on node blocks (Backend::sum_to_blocks);
///  - run.nc: rank 0 writes the file but for the density (write_netcdf), then every rank
///    writes its part of every frame collectively (write_netcdf_frames);
///  - .npy: rank 0 creates each file, every rank writes its block (write_npy_part);
///  - the pictures and the report, on rank 0, from the 2-D marginals of the figure pairs,
///    each the sum of every rank's part (marginal_part); 1-D: the frames themselves;
///  - .vti is refused by the runner before the run (runner.hpp): run.nc holds the same.
WrittenOutputs write_distributed_outputs(const RunRecord& run, const Settings& settings,
                                         const std::string& dir) {
  const Backend& b = *run.backend;
  const std::filesystem::path out(dir);
  const std::size_t K = run.n_frame(), n_mode = run.n_mode(), n_node = run.n_node();
  const std::size_t N = run.axes.size();
  if (settings.includes<"outputs">("vti"))
    throw std::logic_error("outputs vti of a distributed run (the runner refuses it)");
  WrittenOutputs w = planned_outputs(run, settings);
  std::vector<std::size_t> shape;
  for (const GridAxis& a : run.axes) shape.push_back(static_cast<std::size_t>(a.n));

  // This rank's node block of each frame summed over the modes: the one piece of every
  // mode's nodes it holds goes to the nodes' owners, in mode order (as total_density).
  const Block nodes = b.block(n_node);
  std::vector<std::vector<double>> total(K);
  for (std::size_t k = 0; k < K; ++k) {
    const std::span<const double> part = run.frame_part(k);
    total[k].assign(nodes.size(), 0.0);
    for (std::size_t m = 0; m < n_mode; ++m) {
      const std::size_t lo = std::max(run.owned.begin, m * n_node);
      const std::size_t hi = std::min(run.owned.end, (m + 1) * n_node);
      const std::span<const double> piece =
          hi > lo ? part.subspan(lo - run.owned.begin, hi - lo) : std::span<const double>();
      const std::vector<double> got = b.sum_to_blocks(piece, hi > lo ? lo - m * n_node : 0, n_node);
      for (std::size_t i = 0; i < got.size(); ++i) total[k][i] += got[i];
    }
  }
  if (resolution_checked(run)) {
    std::vector<double> sums(K, 0.0);
    for (std::size_t k = 0; k < K; ++k)
      sums[k] = marginal_part(total[k], nodes.begin, run.axes, {}).front();
    b.sum(std::span<double>(sums));
    if (std::string why = resolution_warning(run, sums); !why.empty()) w.warnings.push_back(why);
  }

  // What the pictures show, on rank 0: a record without the grid's density.
  RunRecord view = run;
  view.distributed = false;
  view.density = {};
  view.backend = nullptr;
  std::vector<double> whole;
  Marginals mg;
  const bool pictures = settings.includes<"outputs">("png") ||
                        settings.includes<"outputs">("pdf") ||
                        settings.includes<"outputs">("svg") ||
                        settings.includes<"outputs">("gif") || settings.includes<"outputs">("html");
  if (pictures && N == 1) {
    // A 1-D run's picture is its curve: the frames themselves (n values each).
    for (std::size_t k = 0; k < K; ++k) {
      const std::vector<double> f = b.gather(run.frame_part(k));
      whole.insert(whole.end(), f.begin(), f.end());
    }
    view.density = whole;
  } else if (pictures) {
    for (const auto& [a, c] : figure_pairs(N, run.figure_axes)) {
      const std::array<std::size_t, 2> pair{std::min(a, c), std::max(a, c)};
      if (mg.index(pair[0], pair[1]) < mg.pairs.size()) continue;
      mg.pairs.push_back(pair);
      mg.offset.push_back(mg.block);
      mg.block += shape[pair[0]] * shape[pair[1]];
    }
    // Frame by frame: a rank holds one frame's parts, rank 0 every frame's sums.
    if (b.root()) mg.values.assign(K * n_mode * mg.block, 0.0);
    std::vector<double> frame(n_mode * mg.block);
    for (std::size_t k = 0; k < K; ++k) {
      std::fill(frame.begin(), frame.end(), 0.0);
      const std::span<const double> part = run.frame_part(k);
      for (std::size_t m = 0; m < n_mode; ++m) {
        const std::size_t lo = std::max(run.owned.begin, m * n_node);
        const std::size_t hi = std::min(run.owned.end, (m + 1) * n_node);
        if (hi <= lo) continue;
        for (std::size_t p = 0; p < mg.pairs.size(); ++p) {
          const std::vector<double> piece =
              marginal_part(part.subspan(lo - run.owned.begin, hi - lo), lo - m * n_node, run.axes,
                            {mg.pairs[p][0], mg.pairs[p][1]});
          std::copy(piece.begin(), piece.end(),
                    frame.begin() + static_cast<long>(m * mg.block + mg.offset[p]));
        }
      }
      b.sum_to_root(std::span<double>(frame));
      if (b.root())
        std::copy(frame.begin(), frame.end(),
                  mg.values.begin() + static_cast<long>(k * n_mode * mg.block));
    }
    view.marginals = &mg;
  }

  // run.nc's file, the pictures and the report on rank 0; then every rank's parts.
  const std::string nc_path = (out / "run.nc").string();
  on_every_rank(b, [&] {
    if (!b.root()) return;
    if (!w.netcdf.empty()) write_netcdf(nc_path, run);
    write_pictures_and_report(view, settings, dir, w);
    for (std::size_t k = 0; k < K && !w.npy.empty(); ++k) {
      create_npy((out / w.npy[k]).string(), shape);
      for (const auto& [m, files] : w.mode_npy) create_npy((out / files[k]).string(), shape);
    }
  });
  on_every_rank(b, [&] {
    if (!w.netcdf.empty()) write_netcdf_frames(nc_path, run, total);
    for (std::size_t k = 0; k < K && !w.npy.empty(); ++k) {
      write_npy_part((out / w.npy[k]).string(), shape, nodes.begin, total[k].data(), nodes.size());
      const std::span<const double> part = run.frame_part(k);
      for (std::size_t m = 0; m < n_mode && n_mode > 1; ++m) {
        const std::size_t lo = std::max(run.owned.begin, m * n_node);
        const std::size_t hi = std::min(run.owned.end, (m + 1) * n_node);
        if (hi > lo)
          write_npy_part((out / w.mode_npy[run.mode_names[m]][k]).string(), shape, lo - m * n_node,
                         part.data() + (lo - run.owned.begin), hi - lo);
      }
    }
  });
  // Every rank's report of what it found (rank 0's figures and warnings are the ones shown).
  return w;
}

}  // namespace

std::string resolution_warning(const RunRecord& run) {
  if (!resolution_checked(run)) return "";
  std::vector<double> sums;
  for (std::size_t k = 0; k < run.times.size(); ++k)  // the trapezoid sum of the nodes
    sums.push_back(marginal(run.total_density(k), run.axes, {}).front());
  return resolution_warning(run, sums);
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
        f.rfind("spectrum", 0) == 0 || (f.rfind("sets.", 0) == 0 && !f.ends_with(".pdf")))
      out += ", " + f;
  if (!report.empty()) out += ", " + report;
  if (!pvd.empty()) out += ", " + pvd;
  return out;
}

WrittenOutputs write_run_outputs(const RunRecord& run, const Settings& settings,
                                 const std::string& dir, bool quiet) {
  if (run.distributed) {
    if (run.backend == nullptr) throw std::logic_error("a distributed run without its backend");
    return write_distributed_outputs(run, settings, dir);
  }
  const std::filesystem::path out(dir);
  const std::size_t K = run.n_frame(), n_mode = run.n_mode();
  std::vector<std::size_t> shape;
  for (const GridAxis& a : run.axes) shape.push_back(static_cast<std::size_t>(a.n));
  const bool npy = settings.includes<"outputs">("npy");
  const bool vti = settings.includes<"outputs">("vti");

  WrittenOutputs w = planned_outputs(run, settings);
  const bool netcdf = !w.netcdf.empty();
  if (std::string why = resolution_warning(run); !why.empty()) w.warnings.push_back(why);

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
  write_pictures_and_report(run, settings, dir, w);
  progress.advance();
  progress.finish();
  if (!w.pvd.empty()) write_pvd((out / w.pvd).string(), w.vti, run.times);
  return w;
}

}  // namespace hybgen::rt
