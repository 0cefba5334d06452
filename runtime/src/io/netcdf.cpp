// run.nc: the run as one NetCDF-4 file (hybgen/rt/io/netcdf.hpp states the layout).

#include "hybgen/rt/io/netcdf.hpp"

#include <netcdf.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <ctime>
#include <set>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/rt/io/hyperslab.hpp"
#include "hybgen/rt/method_table.hpp"

namespace hybgen::rt {

namespace {

/// A NetCDF file being written: every call checked, closed (and on failure removed) by the
/// destructor.
class NcFile {
 public:
  explicit NcFile(std::string path) : path_(std::move(path)) {
    check(nc_create(path_.c_str(), NC_NETCDF4 | NC_CLOBBER, &id_), "create");
  }
  NcFile(const NcFile&) = delete;
  NcFile& operator=(const NcFile&) = delete;
  ~NcFile() {
    if (id_ >= 0) {
      nc_close(id_);
      std::remove(path_.c_str());  // not closed by close(): a failure, leave no torn file
    }
  }

  /// Throws "cannot write 'PATH': WHAT: NetCDF's message" for a failed call.
  void check(int status, const char* what) const {
    if (status != NC_NOERR)
      throw std::runtime_error("cannot write '" + path_ + "': " + what + ": " +
                               nc_strerror(status));
  }
  int dim(const std::string& name, std::size_t n) {
    int d = -1;
    check(nc_def_dim(id_, name.c_str(), n, &d), "define a dimension");
    return d;
  }
  int var(const std::string& name, nc_type type, const std::vector<int>& dims) {
    int v = -1;
    check(nc_def_var(id_, name.c_str(), type, static_cast<int>(dims.size()), dims.data(), &v),
          "define a variable");
    return v;
  }
  void text(int var, const char* name, const std::string& value) {
    check(nc_put_att_text(id_, var, name, value.size(), value.c_str()), "write an attribute");
  }
  void number(int var, const char* name, double value) {
    check(nc_put_att_double(id_, var, name, NC_DOUBLE, 1, &value), "write an attribute");
  }
  void end_definitions() { check(nc_enddef(id_), "end the definitions"); }
  void put(int var, const std::vector<double>& values) {
    check(nc_put_var_double(id_, var, values.data()), "write a variable");
  }
  void put(int var, const std::vector<std::size_t>& start, const std::vector<std::size_t>& count,
           const double* values) {
    check(nc_put_vara_double(id_, var, start.data(), count.data(), values), "write a variable");
  }
  void put_strings(int var, const std::vector<std::string>& values) {
    std::vector<const char*> p;
    for (const auto& v : values) p.push_back(v.c_str());
    check(nc_put_var_string(id_, var, p.data()), "write a variable");
  }
  void close() {
    const int id = id_;
    id_ = -1;
    const int status = nc_close(id);
    if (status != NC_NOERR) {
      std::remove(path_.c_str());
      check(status, "close");
    }
  }
  int id() const { return id_; }

 private:
  std::string path_;
  int id_ = -1;
};

/// Names of ours that do not collide with the state variables: `base`, or `base_`, ….
class Names {
 public:
  explicit Names(const std::vector<std::string>& taken) : taken_(taken.begin(), taken.end()) {}
  std::string operator()(std::string base) {
    while (taken_.count(base)) base += '_';
    taken_.insert(base);
    return base;
  }

 private:
  std::set<std::string> taken_;
};

/// The names of run.nc's time, mode and density variables, taken first and in this order
/// (a state variable's name gets a trailing `_`), so that the writer of the file and the
/// writer of a distributed run's frames (write_netcdf_frames) name them alike.
struct DensityNames {
  std::string time, mode, density, by_mode;  ///< Empty: not in this run's file.
};

DensityNames density_names(Names& names, const RunRecord& run) {
  DensityNames d;
  if (!run.times.empty()) d.time = names("time");
  if (run.n_mode() > 1) d.mode = names("mode");
  if (run.marginals == nullptr) {
    d.density = names("density");
    if (run.n_mode() > 1) d.by_mode = names("density_by_mode");
  }
  return d;
}

/// The grid's shape, one extent per axis.
std::vector<std::size_t> grid_shape(const RunRecord& run) {
  std::vector<std::size_t> shape;
  for (const GridAxis& a : run.axes) shape.push_back(static_cast<std::size_t>(a.n));
  return shape;
}

/// The current UTC time, ISO 8601 (the history attribute).
std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char b[32];
  std::strftime(b, sizeof b, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return b;
}

std::string json_text(const nlohmann::json& j, const char* key) {
  return j.is_object() && j.contains(key) && j[key].is_string() ? j[key].get<std::string>() : "";
}

/// `hybgen run PATH --set KEY=VALUE …` of the provenance (the history attribute); a word
/// with a character a shell would read is single-quoted.
std::string run_command(const nlohmann::json& pv) {
  auto word = [](const std::string& w) {
    if (!w.empty() && w.find_first_of(" \t'\"\\$`*?[]{}()<>|&;#~!") == std::string::npos) return w;
    std::string q = "'";
    for (const char c : w) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
  };
  std::string cmd = "hybgen run " + word(json_text(pv, "model_path"));
  if (pv.is_object() && pv.contains("sets") && pv["sets"].is_array())
    for (const auto& s : pv["sets"])
      if (s.is_string()) cmd += " --set " + word(s.get<std::string>());
  return cmd;
}

}  // namespace

void write_netcdf(const std::string& path, const RunRecord& run, int deflate) {
  const std::size_t N = run.axes.size(), n_mode = run.n_mode(), n_node = run.n_node();
  const bool series = !run.times.empty();
  const Marginals* mg = run.marginals;
  if (mg == nullptr && !run.distributed && run.density.size() != run.n_frame() * n_mode * n_node)
    throw std::invalid_argument("write_netcdf: the density does not match the grid");
  NcFile nc(path);
  Names names(run.axis_names);
  const DensityNames dn = density_names(names, run);

  // Dimensions and coordinates.
  std::vector<int> axis_dims(N), axis_vars(N);
  for (std::size_t a = 0; a < N; ++a) {
    axis_dims[a] = nc.dim(run.axis_names[a], static_cast<std::size_t>(run.axes[a].n));
    axis_vars[a] = nc.var(run.axis_names[a], NC_DOUBLE, {axis_dims[a]});
    nc.text(axis_vars[a], "long_name", "state variable " + run.axis_names[a]);
  }
  int time_dim = -1, time_var = -1;
  if (series) {
    const std::string& t = dn.time;
    time_dim = nc.dim(t, run.times.size());
    time_var = nc.var(t, NC_DOUBLE, {time_dim});
    nc.text(time_var, "long_name", "time");
    nc.text(time_var, "units", "1");  // the model's own (dimensionless) time
    nc.text(time_var, "axis", "T");
  }
  int mode_dim = -1, mode_var = -1;
  if (n_mode > 1) {
    const std::string& m = dn.mode;
    mode_dim = nc.dim(m, n_mode);
    mode_var = nc.var(m, NC_STRING, {mode_dim});
    nc.text(mode_var, "long_name", "mode of the hybrid system");
  }

  // The density, one chunk per frame (and mode), or slabs of the slowest axes for a frame of
  // more than kChunkValues nodes.
  auto frame_dims = [&](bool by_mode) {
    std::vector<int> d;
    if (series) d.push_back(time_dim);
    if (by_mode) d.push_back(mode_dim);
    d.insert(d.end(), axis_dims.begin(), axis_dims.end());
    return d;
  };
  auto define_density = [&](const std::string& name, bool by_mode, const std::string& long_name) {
    const std::vector<int> dims = frame_dims(by_mode);
    const int v = nc.var(name, NC_DOUBLE, dims);
    std::vector<std::size_t> chunk;
    if (series) chunk.push_back(1);
    if (by_mode) chunk.push_back(1);
    for (const std::size_t c : c_order_chunk(grid_shape(run), kChunkValues)) chunk.push_back(c);
    nc.check(nc_def_var_chunking(nc.id(), v, NC_CHUNKED, chunk.data()), "chunk a variable");
    if (deflate > 0) nc.check(nc_def_var_deflate(nc.id(), v, 1, 1, deflate), "compress a variable");
    nc.text(v, "long_name", long_name);
    nc.text(v, "units", "1");
    if (run.cell_averages) {
      // CF: the value is a mean over the cell around the node along every state axis.
      std::string methods;
      for (const std::string& a : run.axis_names) methods += a + ": ";
      nc.text(v, "cell_methods", methods + "mean");
      nc.text(v, "description",
              "probability density with respect to the Lebesgue measure of the state "
              "variables, averaged over each node's dual cell (the box of half the grid "
              "spacing around it, clipped to the grid box), by adaptive cubature of the exact "
              "density (summary.json values.error: its estimated L1 error)");
    } else {
      nc.text(v, "description",
              "probability density with respect to the Lebesgue measure of the state "
              "variables, sampled at the grid nodes");
    }
    return v;
  };
  // A one-frame method's frame says what it is (method_table.hpp, frame_what).
  const MethodSpec* method = find_method(run.method);
  const std::string what =
      series || method == nullptr ? std::string("density") : std::string(method->frame_what);
  const int density =
      mg ? -1
         : define_density(dn.density, false, n_mode > 1 ? what + ", summed over the modes" : what);
  const int by_mode =
      !mg && n_mode > 1 ? define_density(dn.by_mode, true, what + " of each mode") : -1;

  // Or the marginals: marginal_<a>_<b> (time, [mode,] a, b) per pair, and the moments.
  std::vector<int> pair_vars, pair_mode_vars;
  int component_dim = -1, component_var = -1, mean_var = -1, cov_var = -1;
  if (mg) {
    for (const auto& [a, b] : mg->pairs) {
      const std::string pair = run.axis_names[a] + "_" + run.axis_names[b];
      auto define = [&](bool by) {
        std::vector<int> dims;
        if (series) dims.push_back(time_dim);
        if (by) dims.push_back(mode_dim);
        dims.push_back(axis_dims[a]);
        dims.push_back(axis_dims[b]);
        const int v = nc.var(names("marginal_" + pair + (by ? "_by_mode" : "")), NC_DOUBLE, dims);
        if (deflate > 0)
          nc.check(nc_def_var_deflate(nc.id(), v, 1, 1, deflate), "compress a variable");
        nc.text(v, "long_name",
                "marginal density on (" + run.axis_names[a] + ", " + run.axis_names[b] + ")" +
                    (by           ? " of each mode"
                     : n_mode > 1 ? ", summed over the modes"
                                  : ""));
        nc.text(v, "units", "1");
        nc.text(v, "description",
                "the density integrated over the other state variables, from the particles "
                "in the grid box (cloud-in-cell on the pair's grid nodes)");
        return v;
      };
      pair_vars.push_back(define(false));
      pair_mode_vars.push_back(n_mode > 1 ? define(true) : -1);
    }
    component_dim = nc.dim(names("component"), N);
    const int component2 = nc.dim(names("component2"), N);
    component_var = nc.var(names("component"), NC_STRING, {component_dim});
    nc.text(component_var, "long_name", "state variable of a moment");
    std::vector<int> mean_dims, cov_dims;
    if (series) mean_dims.push_back(time_dim), cov_dims.push_back(time_dim);
    mean_dims.push_back(component_dim);
    cov_dims.push_back(component_dim);
    cov_dims.push_back(component2);
    mean_var = nc.var(names("mean"), NC_DOUBLE, mean_dims);
    nc.text(mean_var, "long_name", "mean state of the mass in the grid box");
    cov_var = nc.var(names("covariance"), NC_DOUBLE, cov_dims);
    nc.text(cov_var, "long_name", "covariance of the state of the mass in the grid box");
  }

  // The mass budget.
  struct Series {
    std::string name, long_name;
    const std::vector<double>* values;
    std::vector<double> owned;
    int var = -1;
  };
  std::vector<Series> budget;
  const MassBudget& b = run.budget;
  const std::size_t K = run.times.size();
  if (series && b.mass.size() == K && b.outflow.size() == K && b.atom.size() == K) {
    auto add = [&](const char* name, const char* long_name, const std::vector<double>& v) {
      if (v.size() == K) budget.push_back({names(name), long_name, &v, {}, -1});
    };
    add("mass", "mass in the grid box", b.mass);
    add("mass_error", "estimated error of mass", b.mass_error);
    add("outflow", "net mass out through the faces of the grid box since time 0", b.outflow);
    add("outflow_error", "estimated error of outflow", b.outflow_error);
    add("atom", "mass come to rest at Zeno points", b.atom);
    add("atom_error", "estimated error of atom",
        run.atom_error.size() == K ? run.atom_error : b.atom_error);
    Series defect{names("unaccounted"),
                  "initial_mass - mass - outflow - atom: what no term accounts for", nullptr,
                  budget_defect(b), -1};
    budget.push_back(std::move(defect));
    Series defect_error{names("unaccounted_error"), "sum of the terms' estimated errors", nullptr,
                        budget_defect_error(b), -1};
    budget.push_back(std::move(defect_error));
    // The transfer operator's estimated error per output time (methods.hpp,
    // add_transfer_errors; NaN where none was estimated).
    const nlohmann::json* errors = nullptr;
    if (run.summary.is_object() && run.summary.contains(summary_key::transfer) &&
        run.summary[summary_key::transfer].contains("errors"))
      errors = &run.summary[summary_key::transfer]["errors"];
    if (errors != nullptr && errors->is_array() && errors->size() == K) {
      Series e{names("density_error"),
               "estimated relative L1 error of the density (max over modes)",
               nullptr,
               {},
               -1};
      for (const auto& v : *errors)
        e.owned.push_back(v.is_number() ? v.get<double>() : std::nan(""));
      budget.push_back(std::move(e));
    }
    // A per-guard series of summary.json (`member` of a guard's block) as `name`; NaN where
    // it holds none (null: not estimated, or infinite impacts).
    const auto guard_series = [&](const std::string& name, const std::string& long_name,
                                  const nlohmann::json& x) {
      Series v{names(name), long_name, nullptr, {}, -1};
      if (x.is_array())
        for (const auto& y : x) v.owned.push_back(y.is_number() ? y.get<double>() : std::nan(""));
      else
        v.owned.assign(K, std::nan(""));
      if (v.owned.size() == K) budget.push_back(std::move(v));
    };
    // A series NAME and its error NAME_error.
    const auto with_error = [&](const std::string& name, const std::string& long_name,
                                const nlohmann::json& values, const nlohmann::json& value_errors) {
      guard_series(name, long_name, values);
      guard_series(name + "_error", "estimated error of " + name, value_errors);
    };
    // What each trap (`reset absorb`) took since time 0, and its error (NaN: none).
    if (run.summary.is_object() && run.summary.contains(summary_key::absorbed))
      for (const auto& [guard, a] : run.summary[summary_key::absorbed].items())
        with_error("absorbed_" + guard,
                   "mass absorbed by the guard " + guard +
                       " (reset absorb) since time 0, a part of outflow",
                   a["values"], a["errors"]);
    // The impacts on each guard since time 0 and their mean rate over the interval ending at
    // each time (methods/impacts.hpp), with their errors; NaN where infinite (Zeno) or none.
    if (run.summary.is_object() && run.summary.contains(summary_key::impacts))
      for (const auto& [guard, a] : run.summary[summary_key::impacts].items()) {
        with_error("impacts_" + guard,
                   "mass crossing the guard " + guard +
                       " since time 0, counted once per crossing (NaN: infinite, Zeno)",
                   a["values"], a["errors"]);
        with_error("impact_rate_" + guard,
                   "mean rate of impacts_" + guard +
                       " per unit time over the interval from the previous time",
                   a["rate"], a["rate_errors"]);
      }
    for (Series& s : budget) {
      s.var = nc.var(s.name, NC_DOUBLE, {time_dim});
      nc.text(s.var, "long_name", s.long_name);
      nc.text(s.var, "units", "1");
    }
  }
  // The observables' expectations and their errors per frame (methods/observables.hpp;
  // scalars for a one-frame answer). NaN where there is none.
  std::vector<Series> observed;
  if (run.summary.is_object() && run.summary.contains(summary_key::observables))
    for (const auto& [name, o] : run.summary[summary_key::observables].items())
      for (const bool error : {false, true}) {
        const std::string base = "observable_" + name + (error ? "_error" : "");
        Series v{names(base),
                 error ? "estimated error of observable_" + name
                       : "mean of the observable " + name +
                             " under the density in the grid box (normalised to unit mass)",
                 nullptr,
                 {},
                 -1};
        for (const auto& x : o[error ? "errors" : "values"])
          v.owned.push_back(x.is_number() ? x.get<double>() : std::nan(""));
        if (v.owned.size() != std::max<std::size_t>(K, 1)) continue;
        v.var = nc.var(v.name, NC_DOUBLE, series ? std::vector<int>{time_dim} : std::vector<int>{});
        nc.text(v.var, "long_name", v.long_name);
        observed.push_back(std::move(v));
      }
  int mass0_var = -1;
  if (series && !b.mass.empty()) {
    mass0_var = nc.var(names("initial_mass"), NC_DOUBLE, {});
    nc.text(mass0_var, "long_name", "mass in the grid box at time 0");
    nc.number(mass0_var, "error", b.mass0_error);
  }

  // The invariant density's spectrum.
  const nlohmann::json inv = run.summary.is_object() && run.summary.contains(summary_key::invariant)
                                 ? run.summary[summary_key::invariant]
                                 : nlohmann::json();
  std::vector<double> re, im, ab, er;
  int re_var = -1, im_var = -1, abs_var = -1, err_var = -1;
  if (inv.is_object() && inv.contains("eigenvalues")) {
    for (const auto& l : inv["eigenvalues"]) {
      re.push_back(l.at("re").get<double>());
      im.push_back(l.at("im").get<double>());
      ab.push_back(l.at("abs").get<double>());
      er.push_back(l.contains("error") && l["error"].is_number() ? l["error"].get<double>()
                                                                 : std::nan(""));
    }
    const int ev = nc.dim(names("eigenvalue"), re.size());
    re_var = nc.var(names("eigenvalue_real"), NC_DOUBLE, {ev});
    im_var = nc.var(names("eigenvalue_imag"), NC_DOUBLE, {ev});
    abs_var = nc.var(names("eigenvalue_abs"), NC_DOUBLE, {ev});
    nc.text(re_var, "long_name", "real part of an eigenvalue of the transfer operator");
    nc.text(im_var, "long_name", "imaginary part of an eigenvalue of the transfer operator");
    nc.text(abs_var, "long_name", "modulus of an eigenvalue of the transfer operator");
    err_var = nc.var(names("eigenvalue_error"), NC_DOUBLE, {ev});
    nc.text(err_var, "long_name",
            "estimated error of the eigenvalue (from a grid of half the nodes per axis; NaN: "
            "no estimate)");
    // The estimated errors and the decisions they support (methods/two_grid.hpp).
    if (inv.contains("error") && inv["error"].is_number())
      nc.number(NC_GLOBAL, "density_error", inv["error"].get<double>());
    for (const char* key : {"spectral_gap", "spectral_gap_error", "decay_rate", "decay_rate_error",
                            "leak_rate", "leak_rate_error", "step"})
      if (inv.contains(key) && inv[key].is_number())
        nc.number(NC_GLOBAL,
                  (std::string(key == std::string("step") ? "transfer_" : "") + key).c_str(),
                  inv[key].get<double>());
    for (const char* key : {"decays", "leaks", "error_reliable"})
      if (inv.contains(key) && inv[key].is_boolean())
        nc.text(NC_GLOBAL,
                (std::string(key == std::string("error_reliable") ? "density_" : "") + key).c_str(),
                inv[key].get<bool>() ? "true" : "false");
  }

  // The escape rate (escape): per unit time of the model, −ln λ₁ / transfer_step.
  if (run.summary.is_object() && run.summary.contains(summary_key::escape)) {
    const nlohmann::json& e = run.summary[summary_key::escape];
    for (const auto& [attribute, key] :
         {std::pair{"escape_rate", "rate"}, std::pair{"escape_rate_error", "rate_error"},
          std::pair{"escape_lambda1", "lambda1"}, std::pair{"transfer_step", "step"}})
      if (e.contains(key) && e[key].is_number())
        nc.number(NC_GLOBAL, attribute, e[key].get<double>());
    nc.text(NC_GLOBAL, "escape_rate_units", "per unit time");
    nc.text(NC_GLOBAL, "escape_rate_description",
            "escape rate of the open system, -ln(escape_lambda1)/transfer_step per unit time: "
            "the conditionally invariant density loses the fraction exp(-escape_rate t) of its "
            "mass through the grid box's faces in the time t; escape_rate_error (per unit time) "
            "is |rate - rate on the grid with (n+1)/2 nodes per axis| + the eigen-solver's "
            "tolerance/transfer_step");
  }

  // The sets (almost_invariant, coherent): each node's set, at the one frame or at each of the
  // two (methods/almost_invariant.hpp, methods/coherent.hpp), and per set its numbers with
  // their errors, as the method's block of summary.json has them.
  int label_var = -1;
  std::vector<std::pair<int, std::vector<double>>> set_vars;
  const bool per_frame_labels = series && run.set_label.size() == run.n_frame() * n_mode * n_node;
  if (!run.set_label.empty() && !run.distributed &&
      (run.set_label.size() == n_mode * n_node || per_frame_labels)) {
    const bool coherent = run.summary.is_object() && run.summary.contains(summary_key::coherent);
    std::vector<int> dims;
    if (per_frame_labels) dims.push_back(time_dim);
    if (n_mode > 1) dims.push_back(mode_dim);
    dims.insert(dims.end(), axis_dims.begin(), axis_dims.end());
    label_var = nc.var(names("set_label"), NC_INT, dims);
    if (coherent) {
      nc.text(label_var, "long_name", "coherent pair of each node at each time (0: none)");
      nc.text(label_var, "description",
              "at the first time the pair whose initial set A holds the node, at the last the "
              "pair whose final set B holds it: the pair (1 ... K) whose SEBA vector of the "
              "normalised transport's K leading singular vectors is largest at the node; 0 "
              "where the density vanishes");
    } else {
      nc.text(label_var, "long_name", "almost-invariant set of each node (0: none)");
      nc.text(label_var, "description",
              "the set (1 ... K) whose SEBA vector of the reversibilised transfer operator's K "
              "leading eigenvectors is largest at the node; 0 where none exceeds the vectors' "
              "leakage, or the invariant density vanishes");
    }
    struct SetNumber {
      const char* key;
      const char* long_name;
      const char* units;
    };
    static constexpr SetNumber almost_invariant_numbers[] = {
        {"mass", "invariant mass of the set", "1"},
        {"mass_error", "estimated error of set_mass", "1"},
        {"ratio",
         "invariance ratio: the probability that invariant mass in the set is in it one transfer "
         "step later",
         "1"},
        {"ratio_error", "estimated error of set_ratio", "1"},
        {"exit_rate", "-ln(set_ratio)/step: rate at which mass leaves the set", "per unit time"}};
    static constexpr SetNumber coherent_numbers[] = {
        {"initial_mass", "mass of the pair's initial set at the first time", "1"},
        {"initial_mass_error", "estimated error of set_initial_mass", "1"},
        {"final_mass", "mass of the pair's final set at the last time", "1"},
        {"final_mass_error", "estimated error of set_final_mass", "1"},
        {"carried", "mass of the initial set that is in the final set at the last time", "1"},
        {"carried_error", "estimated error of set_carried", "1"},
        {"forward", "probability that mass in the initial set ends in the final set", "1"},
        {"forward_error", "estimated error of set_forward", "1"},
        {"backward", "probability that mass in the final set came from the initial set", "1"},
        {"backward_error", "estimated error of set_backward", "1"}};
    const std::span<const SetNumber> numbers =
        coherent ? std::span<const SetNumber>(coherent_numbers)
                 : std::span<const SetNumber>(almost_invariant_numbers);
    const char* block = coherent ? summary_key::coherent : summary_key::almost_invariant;
    const nlohmann::json* sets = nullptr;
    if (run.summary.is_object() && run.summary.contains(block)) sets = &run.summary[block]["sets"];
    if (sets != nullptr && sets->is_array() && !sets->empty()) {
      const int set_dim = nc.dim(names("set"), sets->size());
      for (const SetNumber& x : numbers) {
        const int v = nc.var(names(std::string("set_") + x.key), NC_DOUBLE, {set_dim});
        nc.text(v, "long_name", x.long_name);
        nc.text(v, "units", x.units);
        std::vector<double> values;
        for (const auto& a : *sets)
          values.push_back(a.contains(x.key) && a[x.key].is_number() ? a[x.key].get<double>()
                                                                     : std::nan(""));
        set_vars.emplace_back(v, std::move(values));
      }
    }
  }

  // Global attributes.
  const nlohmann::json& pv = run.provenance;
  const std::string version = json_text(pv, "hybgen_version");
  nc.text(NC_GLOBAL, "Conventions", "CF-1.8");
  nc.text(NC_GLOBAL, "title",
          run.model + ": " + (series ? std::string("density under the hybrid flow") : what) + " (" +
              run.method + ")");
  nc.text(NC_GLOBAL, "source", "hybgen" + (version.empty() ? "" : " " + version));
  nc.text(NC_GLOBAL, "history", utc_now() + " " + run_command(pv));
  nc.text(NC_GLOBAL, "model", run.model);
  nc.text(NC_GLOBAL, "method", run.method);
  for (const char* key : {"model_path", "model_sha256", "model_text", "equations"})
    if (const std::string v = json_text(pv, key); !v.empty()) nc.text(NC_GLOBAL, key, v);
  if (run.summary.is_object() && run.summary.contains(summary_key::settings))
    nc.text(NC_GLOBAL, "settings", run.summary[summary_key::settings].dump());
  for (std::size_t j = 0; j < run.params.size(); ++j)
    nc.number(NC_GLOBAL, ("parameter_" + run.param_names[j]).c_str(), run.params[j]);
  nc.end_definitions();

  // Data.
  for (std::size_t a = 0; a < N; ++a) {
    std::vector<double> x(static_cast<std::size_t>(run.axes[a].n));
    for (int i = 0; i < run.axes[a].n; ++i)
      x[static_cast<std::size_t>(i)] = axis_node(run.axes[a], i);
    nc.put(axis_vars[a], x);
  }
  if (series) nc.put(time_var, run.times);
  if (n_mode > 1) nc.put_strings(mode_var, run.mode_names);
  if (label_var >= 0)
    nc.check(nc_put_var_int(nc.id(), label_var, run.set_label.data()), "write a variable");
  for (const auto& [v, values] : set_vars) nc.put(v, values);
  for (std::size_t k = 0; k < run.n_frame() && mg; ++k)
    for (std::size_t p = 0; p < mg->pairs.size(); ++p) {
      const auto na = static_cast<std::size_t>(run.axes[mg->pairs[p][0]].n);
      const auto nb = static_cast<std::size_t>(run.axes[mg->pairs[p][1]].n);
      std::vector<double> total(na * nb, 0.0);
      for (std::size_t m = 0; m < n_mode; ++m) {
        const std::span<const double> u = mg->pair(k, m, n_mode, p);
        for (std::size_t i = 0; i < total.size(); ++i) total[i] += u[i];
        if (pair_mode_vars[p] >= 0) {
          std::vector<std::size_t> s, c;
          if (series) s.push_back(k), c.push_back(1);
          s.insert(s.end(), {m, 0, 0});
          c.insert(c.end(), {1, na, nb});
          nc.put(pair_mode_vars[p], s, c, u.data());
        }
      }
      std::vector<std::size_t> s, c;
      if (series) s.push_back(k), c.push_back(1);
      s.insert(s.end(), {0, 0});
      c.insert(c.end(), {na, nb});
      nc.put(pair_vars[p], s, c, total.data());
    }
  if (mg) {
    nc.put_strings(component_var, run.axis_names);
    nc.put(mean_var, mg->mean);
    nc.put(cov_var, mg->covariance);
  }
  // A distributed run's density: every rank writes its part afterwards (write_netcdf_frames).
  for (std::size_t k = 0; k < run.n_frame() && !mg && !run.distributed; ++k) {
    std::vector<std::size_t> start, count;
    if (series) start.push_back(k), count.push_back(1);
    const std::vector<double> total = run.total_density(k);
    std::vector<std::size_t> s = start, c = count;
    for (const GridAxis& a : run.axes) s.push_back(0), c.push_back(static_cast<std::size_t>(a.n));
    nc.put(density, s, c, total.data());
    if (by_mode >= 0)
      for (std::size_t m = 0; m < n_mode; ++m) {
        std::vector<std::size_t> sm = start, cm = count;
        sm.push_back(m), cm.push_back(1);
        for (const GridAxis& a : run.axes)
          sm.push_back(0), cm.push_back(static_cast<std::size_t>(a.n));
        nc.put(by_mode, sm, cm, run.mode_density(k, m).data());
      }
  }
  for (const Series& s : budget) nc.put(s.var, s.values ? *s.values : s.owned);
  for (const Series& s : observed) nc.put(s.var, s.owned);
  if (mass0_var >= 0) nc.put(mass0_var, std::vector<double>{b.mass0});
  if (re_var >= 0) {
    nc.put(re_var, re);
    nc.put(im_var, im);
    nc.put(abs_var, ab);
    nc.put(err_var, er);
  }
  nc.close();
}

void write_netcdf_frames(const std::string& path, const RunRecord& run,
                         const std::vector<std::vector<double>>& total) {
  const ParallelIo* io = run.backend ? run.backend->parallel_io() : nullptr;
  if (!run.distributed || io == nullptr || run.marginals != nullptr)
    throw std::logic_error("write_netcdf_frames: not a distributed run with parallel output");
  const Backend& b = *run.backend;
  if (run.owned.begin != b.block(run.n_mode() * run.n_node()).begin ||
      run.owned.end != b.block(run.n_mode() * run.n_node()).end)
    throw std::logic_error("write_netcdf_frames: a rank's pairs are not its block");
  // Every call is collective: a rank whose call fails keeps calling (writing nothing) so that
  // no rank waits for it, and the ranks agree on the first failure at the end.
  int failed = NC_NOERR;
  const char* failed_at = "";
  auto check = [&](int status, const char* what) {
    if (status != NC_NOERR && failed == NC_NOERR) failed = status, failed_at = what;
    return failed == NC_NOERR;
  };
  int id = -1;
  check(io->open_netcdf(path.c_str(), &id), "open it on every rank");
  // The open is collective; where it failed (on every rank, or on some) nothing is written.
  if (b.any(failed != NC_NOERR)) {
    if (failed == NC_NOERR) nc_close(id);
    throw std::runtime_error("cannot write '" + path + "': " +
                             (failed != NC_NOERR
                                  ? std::string(failed_at) + ": " + nc_strerror(failed)
                                  : std::string("another rank could not open it")));
  }
  Names names(run.axis_names);
  const DensityNames dn = density_names(names, run);
  const std::size_t n_mode = run.n_mode(), n_node = run.n_node();
  const bool series = !run.times.empty();
  const std::vector<std::size_t> nodes = grid_shape(run);
  std::vector<std::size_t> pairs = nodes;
  pairs.insert(pairs.begin(), n_mode);
  // Every rank calls each write, as often as the rank with the most boxes (the partition
  // is known everywhere); a rank with fewer writes nothing (count 0) in the rest.
  auto calls = [&](const std::vector<std::size_t>& shape, std::size_t n) {
    std::size_t most = 0;
    for (int r = 0; r < b.ranks(); ++r) {
      const Block blk = block_of(n, r, b.ranks());
      most = std::max(most, c_order_hyperslabs(shape, blk.begin, blk.end).size());
    }
    return most;
  };
  auto write = [&](int var, std::size_t k, const std::vector<std::size_t>& shape, Block part,
                   const double* values, std::size_t n_calls) {
    const std::vector<Hyperslab> boxes = c_order_hyperslabs(shape, part.begin, part.end);
    const std::size_t rank = shape.size() + (series ? 1 : 0);
    for (std::size_t j = 0; j < n_calls; ++j) {
      std::vector<std::size_t> start(rank, 0), count(rank, 0);
      if (j < boxes.size()) {
        const std::size_t at = series ? 1 : 0;
        if (series) start[0] = k, count[0] = 1;
        std::copy(boxes[j].start.begin(), boxes[j].start.end(),
                  start.begin() + static_cast<long>(at));
        std::copy(boxes[j].count.begin(), boxes[j].count.end(),
                  count.begin() + static_cast<long>(at));
      }
      if (failed != NC_NOERR) std::fill(count.begin(), count.end(), 0);  // keep in step
      check(nc_put_vara_double(id, var, start.data(), count.data(), values), "write a frame");
      if (j < boxes.size()) values += boxes[j].size();
    }
  };
  int density = -1, by_mode = -1;
  const Block node_block = b.block(n_node);
  bool shapes = total.size() == run.n_frame();
  for (const std::vector<double>& t : total) shapes = shapes && t.size() == node_block.size();
  if (!shapes) check(NC_EINVAL, "the summed density's blocks (one per frame, this rank's nodes)");
  check(nc_inq_varid(id, dn.density.c_str(), &density), "find the density");
  if (n_mode > 1) check(nc_inq_varid(id, dn.by_mode.c_str(), &by_mode), "find the density by mode");
  // The same metadata on every rank: these fail everywhere or nowhere.
  if (b.any(failed != NC_NOERR)) {
    nc_close(id);
    throw std::runtime_error("cannot write '" + path + "': " + failed_at + ": " +
                             nc_strerror(failed != NC_NOERR ? failed : NC_EINVAL));
  }
  check(io->collective(id, density), "write it collectively");
  if (by_mode >= 0) check(io->collective(id, by_mode), "write it collectively");
  const std::size_t node_calls = calls(nodes, n_node);
  const std::size_t pair_calls = n_mode > 1 ? calls(pairs, n_mode * n_node) : 0;
  for (std::size_t k = 0; k < run.n_frame(); ++k) {
    write(density, k, nodes, node_block, total[k].data(), node_calls);
    if (by_mode >= 0) write(by_mode, k, pairs, run.owned, run.frame_part(k).data(), pair_calls);
  }
  check(nc_close(id), "close");  // collective: flushes every rank's chunks
  // The first failure of any rank, said by every rank (the lowest failing rank's words).
  const std::int64_t none = b.ranks();
  const std::int64_t first = b.min(failed != NC_NOERR ? std::int64_t{b.rank()} : none);
  if (first == none) return;
  const std::string why = b.broadcast(
      failed != NC_NOERR ? std::string(failed_at) + ": " + nc_strerror(failed) : std::string(),
      static_cast<int>(first));
  throw std::runtime_error("cannot write '" + path + "': " + why);
}

}  // namespace hybgen::rt
