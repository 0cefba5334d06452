#pragma once
/// \file table_model.hpp
/// A generated model seen through a table of function pointers, so that the runtime can be
/// compiled once (runtime/src/, the library `hybgen::runner`) and a runner is only the
/// model's kernels plus this table: `hybgen build` compiles one small translation unit and
/// links it against the library (generator/src/build.cpp).
///
/// `ModelTable` is the contract: plain data and pointers to the generated struct's static
/// functions (model.hpp, `HybridModel`). `TableModel<N>` satisfies `HybridModel` with
/// n_state = N at compile time and everything else read from the installed table at run
/// time; the runtime's templates are instantiated for it, per dimension, in the library.
/// Every kernel call is then one indirect call (bench/bench_characteristics.cpp measures
/// what that costs against the inlined kernels).
///
/// Invariants: one table is installed per process, before any solver runs, and never
/// changes (`install_table`); its counts fit the compile-time capacities below
/// (`table_fits`, checked by the builder before it chooses this path and by the runner
/// again at start).

#include <array>
#include <concepts>
#include <cstddef>
#include <span>

#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

// Declared, not included (core/backend.hpp): every runner's one translation unit includes this
// header, and backend.hpp's standard headers were about 70 % of its compile (1.05 s of CPU with
// them, 0.30 s without, 2026-12-01).
class Backend;

/// State dimensions 1..kTableMaxState the library is instantiated for (runtime/CMakeLists.txt).
inline constexpr int kTableMaxState = 6;

/// A generated model as data and function pointers (the fields of `HybridModel`).
struct ModelTable {
  int n_state = 0;                                                       ///< State dimension.
  int n_param = 0;                                                       ///< Parameters.
  int n_mode = 0;                                                        ///< Modes.
  int n_guard = 0;                                                       ///< Guards.
  const char* name = "";                                                 ///< Model name.
  const char* const* state_names = nullptr;                              ///< n_state names.
  const char* const* param_names = nullptr;                              ///< n_param names.
  const double* param_defaults = nullptr;                                ///< n_param defaults.
  const char* const* mode_names = nullptr;                               ///< n_mode names.
  const char* const* guard_names = nullptr;                              ///< n_guard names.
  const GuardInfo* guards = nullptr;                                     ///< n_guard guards.
  void (*flow)(int, const double*, const double*, double*) = nullptr;    ///< X_k.
  double (*divergence)(int, const double*, const double*) = nullptr;     ///< div X_k.
  double (*guard_surface)(int, const double*, const double*) = nullptr;  ///< s_g.
  void (*guard_gradient)(int, const double*, const double*, double*) = nullptr;  ///< ∇s_g.
  void (*reset)(int, const double*, const double*, double*) = nullptr;           ///< Δ_g.
  void (*reset_inverse)(int, const double*, const double*, double*) = nullptr;   ///< Δ_g⁻¹.
  void (*reset_jacobian)(int, const double*, const double*, double*) = nullptr;  ///< DΔ_g.
  double (*hybrid_jacobian)(int, const double*, const double*) = nullptr;        ///< J_g.
  double (*initial_density)(int, const double*, const double*) = nullptr;        ///< u₀.
  bool (*in_support)(const double*, const double*) = nullptr;                    ///< support.
  /// Mode regions (`where`); null when the model has none (every mode everywhere).
  bool (*in_region)(int, const double*, const double*) = nullptr;
  int n_observable = 0;                           ///< Observables (`observe`; model.hpp).
  const char* const* observable_names = nullptr;  ///< n_observable names.
  /// f_i in mode k at index i·n_mode + k; null when the model has no observable.
  double (*observable)(int, const double*, const double*) = nullptr;
};

/// The table of the generated model struct M (its static members, by address).
template <HybridModel M>
ModelTable make_table() {
  ModelTable t;
  t.n_state = M::n_state;
  t.n_param = M::n_param;
  t.n_mode = M::n_mode;
  t.n_guard = M::n_guard;
  t.name = M::name;
  t.state_names = M::state_names.data();
  t.param_names = M::param_names.data();
  t.param_defaults = M::param_defaults.data();
  t.mode_names = M::mode_names.data();
  t.guard_names = M::guard_names.data();
  t.guards = M::guards.data();
  t.flow = &M::flow;
  t.divergence = &M::divergence;
  t.guard_surface = &M::guard_surface;
  t.guard_gradient = &M::guard_gradient;
  t.reset = &M::reset;
  t.reset_inverse = &M::reset_inverse;
  t.reset_jacobian = &M::reset_jacobian;
  t.hybrid_jacobian = &M::hybrid_jacobian;
  t.initial_density = &M::initial_density;
  t.in_support = &M::in_support;
  if constexpr (requires(int m, const double* x, const double* p) {
                  { M::in_region(m, x, p) } -> std::same_as<bool>;
                })
    t.in_region = &M::in_region;
  if constexpr (requires { M::observable_names; }) {
    t.n_observable = M::n_observable;
    t.observable_names = M::observable_names.data();
    t.observable = &M::observable;
  }
  return t;
}

/// Whether the library can run a model of this shape (dimension and guard count).
constexpr bool table_fits(int n_state, int n_guard) {
  return n_state >= 1 && n_state <= kTableMaxState && n_guard >= 0 && n_guard <= kTableMaxGuards;
}

/// The installed table's model, with state dimension N fixed at compile time. Satisfies
/// `HybridModel`; n_param, n_mode and n_guard are run-time values.
template <int N>
struct TableModel {
  static constexpr int n_state = N;                             ///< State dimension.
  static inline int n_param = 0;                                ///< Parameters.
  static inline int n_mode = 0;                                 ///< Modes.
  static inline int n_guard = 0;                                ///< Guards (≤ kTableMaxGuards).
  static inline const char* name = "";                          ///< Model name.
  static inline std::span<const char* const> state_names;       ///< State names.
  static inline std::span<const char* const> param_names;       ///< Parameter names.
  static inline std::span<const double> param_defaults;         ///< Parameter defaults.
  static inline std::span<const char* const> mode_names;        ///< Mode names.
  static inline std::span<const char* const> guard_names;       ///< Guard names.
  static inline std::span<const GuardInfo> guards;              ///< Guards.
  static inline int n_observable = 0;                           ///< Observables (model.hpp).
  static inline std::span<const char* const> observable_names;  ///< Observable names.
  static inline const ModelTable* table = nullptr;              ///< The installed table.

  /// X_k(x) into out.
  static void flow(int k, const double* x, const double* p, double* out) {
    table->flow(k, x, p, out);
  }
  /// div X_k(x).
  static double divergence(int k, const double* x, const double* p) {
    return table->divergence(k, x, p);
  }
  /// s_g(x).
  static double guard_surface(int g, const double* x, const double* p) {
    return table->guard_surface(g, x, p);
  }
  /// ∇s_g(x) into out.
  static void guard_gradient(int g, const double* x, const double* p, double* out) {
    table->guard_gradient(g, x, p, out);
  }
  /// Δ_g(x) into out.
  static void reset(int g, const double* x, const double* p, double* out) {
    table->reset(g, x, p, out);
  }
  /// Δ_g⁻¹(y) into out.
  static void reset_inverse(int g, const double* y, const double* p, double* out) {
    table->reset_inverse(g, y, p, out);
  }
  /// DΔ_g(x) into out, row-major.
  static void reset_jacobian(int g, const double* x, const double* p, double* out) {
    table->reset_jacobian(g, x, p, out);
  }
  /// J_g(x).
  static double hybrid_jacobian(int g, const double* x, const double* p) {
    return table->hybrid_jacobian(g, x, p);
  }
  /// u₀ of mode k at x.
  static double initial_density(int k, const double* x, const double* p) {
    return table->initial_density(k, x, p);
  }
  /// Whether x is in the state space.
  static bool in_support(const double* x, const double* p) { return table->in_support(x, p); }
  /// Whether x is in mode m's region (true where the model has no regions).
  static bool in_region(int m, const double* x, const double* p) {
    return table->in_region == nullptr || table->in_region(m, x, p);
  }

  /// Observable i in mode k at index i·n_mode + k (0 where the model has none).
  static double observable(int index, const double* x, const double* p) {
    return table->observable == nullptr ? 0.0 : table->observable(index, x, p);
  }

  /// Make `t` (kept by pointer; it must outlive every solver) the model of this process.
  static void install(const ModelTable& t) {
    table = &t;
    n_param = t.n_param;
    n_mode = t.n_mode;
    n_guard = t.n_guard;
    name = t.name;
    const auto np = static_cast<std::size_t>(t.n_param);
    state_names = {t.state_names, static_cast<std::size_t>(N)};
    param_names = {t.param_names, np};
    param_defaults = {t.param_defaults, np};
    mode_names = {t.mode_names, static_cast<std::size_t>(t.n_mode)};
    guard_names = {t.guard_names, static_cast<std::size_t>(t.n_guard)};
    guards = {t.guards, static_cast<std::size_t>(t.n_guard)};
    n_observable = t.observable == nullptr ? 0 : t.n_observable;
    observable_names = {t.observable_names, static_cast<std::size_t>(n_observable)};
  }
};

/// `runner_main` (runner.hpp) on TableModel<N> with `table` installed; instantiated in the
/// library for N = 1..kTableMaxState (runtime/src/runner_dim.cpp).
template <int N>
int table_runner_main_dim(const ModelTable& table, int argc, char** argv, const Backend& backend);

/// Run the runner's main program on the model of `table` (runtime/src/runner_table.cpp):
/// the entry point of a runner built against the library. Exit codes as `runner_main`;
/// a table the library cannot run (`table_fits`) is exit 70, since the builder checks it.
/// `backend`: the ranks of the run (core/backend.hpp; a runner built with backend=mpi
/// passes hybgen::mpi's, through mpi_main in hybgen/rt/mpi.hpp).
int table_runner_main(const ModelTable& table, int argc, char** argv, const Backend& backend);

/// `table_runner_main` on one process (core/backend.hpp, `serial_backend`): a serial runner's
/// entry point.
int table_runner_main(const ModelTable& table, int argc, char** argv);

}  // namespace hybgen::rt
