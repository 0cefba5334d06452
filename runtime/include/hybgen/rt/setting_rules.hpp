#pragma once
/// \file setting_rules.hpp
/// The rules that relate a setting to another setting, to the method (method_table.hpp), to
/// the model (its states, its resets) or to the run (its ranks, the machine's memory),
/// defined once, beside the settings table (settings.hpp) that checks each setting on its
/// own. The generator applies them before it builds a runner (generator/src/run.cpp,
/// `check_runnable`; generator/src/check.cpp for figure_axes, located at the setting;
/// generator/src/derive.cpp as `check`'s warning), the runner again on its configuration
/// (runner.hpp, `validate_run`), so that a configuration written by hand is held to the same
/// rules. A rule knows only what `RunFacts` tells it: a fact left at its "unknown" value
/// skips the rules that need it.
///
/// Adding a rule: a function here returning its message ("" when the rule holds), called from
/// `setting_conflicts`; docs/design.md, "Adding a setting".

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "hybgen/rt/method_table.hpp"
#include "hybgen/rt/settings.hpp"

namespace hybgen::rt {

/// What the rules know besides the settings. Defaults are "unknown": the rule is skipped.
struct RunFacts {
  std::vector<std::string> states;  ///< The model's state names (empty: unknown).
  /// The guards whose reset has an inverse on its guard only (derive.cpp,
  /// `inverse_on_guard_only`), by name and index; null: unknown.
  const std::vector<std::pair<std::size_t, std::string>>* guards_without_inverse = nullptr;
  int ranks = 0;  ///< The processes of the run (0: from the settings `backend` and `ranks`).
  std::vector<long> grid;     ///< Nodes per axis (empty: unknown).
  int modes = 0;              ///< Modes (0: unknown).
  std::size_t frames = 0;     ///< Output times of a time series (0: unknown).
  double memory_bytes = 0.0;  ///< This machine's memory (0: unknown).
};

/// A broken rule.
struct SettingConflict {
  std::string setting;  ///< The setting at fault (a key of settings.hpp, or "grid").
  /// The guard whose reset the rule is about (an index of the model's guards), or -1.
  long guard = -1;
  std::string message;  ///< What is wrong and the way out.
};

/// The processes a run of `s` has: `facts.ranks` when known, else the setting `ranks` with
/// backend=mpi, else 1.
inline int run_ranks(const Settings& s, const RunFacts& facts) {
  if (facts.ranks > 0) return facts.ranks;
  return s.word<"backend">() == "mpi" ? static_cast<int>(s.integer<"ranks">()) : 1;
}

/// Most output times a run may have: a loud cap, before anything is allocated (t_end = 1e15
/// with dt = 1e-9 asked for 1e24 frames).
inline constexpr double kMaxFrames = 1e6;

/// The number of output times of `t_end` and `dt` (runner.hpp's output_times: 0, dt, …, and
/// t_end), in floating point so that it cannot overflow.
inline double frame_count(double t_end, double dt) {
  const double n = std::floor(t_end / dt + 1e-9);
  return n + 1.0 + (t_end - n * dt > 1e-9 * std::max(1.0, t_end) ? 1.0 : 0.0);
}

/// This machine's memory in bytes (0 if unknown).
inline double physical_memory_bytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), size = ::sysconf(_SC_PAGE_SIZE);
  return pages > 0 && size > 0 ? static_cast<double>(pages) * static_cast<double>(size) : 0.0;
}

/// t_end / dt gives at most kMaxFrames output times.
inline std::string frames_rule(const Settings& s) {
  const double t_end = s.real<"t_end">(), dt = s.real<"dt">();
  const double frames = frame_count(t_end, dt);
  if (frames <= kMaxFrames) return "";
  char b[240];
  std::snprintf(b, sizeof b,
                "t_end = %g with dt = %g asks for %.3g output times, more than the %.0e a run may "
                "have: raise dt (the output interval; the solvers' own steps do not depend on it)",
                t_end, dt, frames, kMaxFrames);
  return b;
}

/// Most time steps `method=transfer` may march (its operator's step, or with scheme=fv the
/// cap of its step): a loud cap, before anything is allocated (t_end = 2 with step = 1e-300
/// asked for 2e300 steps and ended in std::length_error, exit 70).
inline constexpr double kMaxTransferSteps = 1e7;

/// method=transfer with step > 0 marches at most kMaxTransferSteps steps to t_end.
inline std::string steps_rule(const Settings& s) {
  if (s.word<"method">() != method_spec(Method::transfer).name) return "";
  const double step = s.real<"step">(), t_end = s.real<"t_end">();
  if (!(step > 0.0) || t_end / step <= kMaxTransferSteps) return "";
  char b[300];
  std::snprintf(b, sizeof b,
                "t_end = %g with step = %g asks the transfer operator for %.3g steps, more than "
                "the %.0e a run may take: raise step (0 takes dt, or with scheme=fv the "
                "stability bound)",
                t_end, step, t_end / step, kMaxTransferSteps);
  return b;
}

/// ranks > 1 runs MPI ranks: it needs backend=mpi.
inline std::string ranks_rule(const Settings& s) {
  if (s.integer<"ranks">() > 1 && s.word<"backend">() != "mpi")
    return "ranks=" + std::to_string(s.integer<"ranks">()) +
           " runs that many MPI ranks, which needs backend=mpi (--ranks N sets both)";
  return "";
}

/// The sets' methods take the whole operator in one process (MethodSpec::whole_operator: the
/// eigenvectors of methods/almost_invariant.hpp and methods/coherent.hpp).
inline std::string one_process_rule(const Settings& s, int ranks) {
  const MethodSpec& m = method_named(s.word<"method">());
  if (ranks <= 1 || !m.whole_operator) return "";
  return "method " + std::string(m.name) +
         " runs in one process (the sets need the whole operator); run it without --ranks, or "
         "on a coarser grid";
}

/// A method that inverts the resets needs every reset's inverse off its guard too.
inline std::string inverse_rule(const Settings& s, const std::string& guard) {
  if (!method_named(s.word<"method">()).inverts_resets) return "";
  return "the reset of guard '" + guard +
         "' has no inverse in the whole state space (it is locally injective on its guard "
         "only), which the " +
         s.word<"method">() + " method needs; use --set method=" + forward_methods();
}

/// density=marginals is what a method that deposits marginals keeps.
inline std::string marginals_rule(const Settings& s) {
  if (s.word<"density">() != "marginals") return "";
  const std::string& method = s.word<"method">();
  if (!method_named(method).deposits_marginals) {
    std::vector<std::string_view> keepers;
    for (const MethodSpec& m : kMethods)
      if (m.deposits_marginals) keepers.push_back(m.name);
    const std::string which = or_list(keepers);
    return "density=marginals is what the " + which + " deposit; method " + method +
           " keeps the density on every node (use method=" + which + ")";
  }
  for (const char* o : {"npy", "vti"})
    if (s.includes<"outputs">(o))
      return std::string("outputs ") + o +
             " holds the density on every node, which density=marginals does not keep (netcdf, "
             "png, pdf, svg, gif and html show the marginals)";
  return "";
}

/// scheme=fv discretises the generator: its null vector is the invariant density, which
/// method invariant takes (methods/generator_solve.hpp), and method transfer steps it in time
/// (methods/generator_march.hpp); the escape rate is not built on it yet.
inline std::string fv_scheme_rule(const Settings& s) {
  constexpr std::size_t kScheme = setting_index("scheme");
  static_assert(kScheme < kSettings.size(), "the setting scheme");
  if (s.word<"scheme">() != "fv") return "";
  const MethodSpec& m = method_named(s.word<"method">());
  if (m.id == Method::invariant || m.id == Method::transfer || !method_reads(m, kSettings[kScheme]))
    return "";
  return "scheme=fv is the finite-volume generator, whose null vector is the invariant density "
         "and which method transfer steps in time; method " +
         s.word<"method">() +
         " is not built on it yet: use method=invariant or transfer with scheme=fv, or "
         "scheme=hat";
}

/// scheme=galerkin steps the density's hat expansion by a projection with a mass matrix
/// (methods/transfer.hpp): method transfer's, in one process. Its operator is not a matrix of
/// probabilities, so the methods that read an operator's spectrum or columns do not take it.
inline std::string galerkin_scheme_rule(const Settings& s, int ranks) {
  constexpr std::size_t kScheme = setting_index("scheme");
  if (s.word<"scheme">() != "galerkin") return "";
  const MethodSpec& m = method_named(s.word<"method">());
  if (m.id != Method::transfer && method_reads(m, kSettings[kScheme]))
    return "scheme=galerkin is a transient scheme of method transfer: its step solves with a "
           "mass matrix, so its operator is no matrix of probabilities whose spectrum or "
           "columns method " +
           s.word<"method">() + " reads; use scheme=hat (or fv for invariant)";
  if (ranks > 1)
    return "scheme=galerkin runs in one process: run without MPI, or use scheme=hat over "
           "several ranks";
  return "";
}

/// fv_order=4: the even-order upwind reconstruction is anti-dissipative on cycles (a
/// periodic flow's eigenvalues measured at |λ| = 1 + 1.7e-7, growing modes), so it is
/// refused; 1, 2 and 3 stay for tests of the order, 5 is the default.
inline std::string fv_order_rule(const Settings& s) {
  if (s.integer<"fv_order">() != 4) return "";
  return "fv_order=4 is not offered: an even-order upwind reconstruction does not damp, and "
         "a cycle's eigenvalues come out above 1 (growing modes); use fv_order=5 (the "
         "default) or 3";
}

/// A VTK image is one process's whole grid.
inline std::string vti_rule(const Settings& s, int ranks) {
  if (ranks > 1 && s.includes<"outputs">("vti"))
    return "outputs vti holds a whole grid in one process's file, which a run over several ranks "
           "does not gather: run.nc has the same arrays (ParaView opens it with its NetCDF CF "
           "reader), or run with one rank";
  return "";
}

/// figure_axes names two or more of the model's states (the pictures show their pairs).
inline std::string figure_axes_rule(const Settings& s, const std::vector<std::string>& states) {
  const std::vector<std::string> names = s.names<"figure_axes">();
  for (const std::string& n : names)
    if (std::find(states.begin(), states.end(), n) == states.end()) {
      std::string list;
      for (const auto& st : states) list += (list.empty() ? "" : ", ") + st;
      return "'" + n + "' is not a state variable (the states: " + list + ")";
    }
  if (!names.empty() && names.size() < 2 && states.size() > 2)
    return "needs two or more state variables: the pictures show their pairs";
  return "";
}

/// The densities a run keeps on every node must fit in memory (frames × modes × nodes
/// doubles; one frame for a method with one frame), unless it keeps marginals.
inline std::string memory_rule(const Settings& s, const RunFacts& f) {
  if (f.grid.empty() || f.modes <= 0 || !(f.memory_bytes > 0.0)) return "";
  if (s.word<"density">() == "marginals") return "";
  const double series =
      f.frames > 0 ? static_cast<double>(f.frames) : frame_count(s.real<"t_end">(), s.real<"dt">());
  const MethodSpec& m = method_named(s.word<"method">());
  const double frames = m.one_frame ? 1.0 : m.ends_only ? 2.0 : series;
  double nodes = 1.0;
  for (const long n : f.grid) nodes *= static_cast<double>(n);
  const double need = nodes * static_cast<double>(frames) * f.modes * 8.0;
  if (need <= f.memory_bytes) return "";
  char b[400];
  std::snprintf(b, sizeof b,
                "the densities on the grid need %.3g GB (%.3g nodes x %d mode(s) x %.0f "
                "frame(s)) and this machine has %.3g GB: use a coarser grid, or method=particles "
                "with density=marginals (the marginal of every pair of axes)",
                need / 1e9, nodes, f.modes, frames, f.memory_bytes / 1e9);
  return b;
}

/// Every rule that `s` and `facts` break, in a fixed order (the first is the one to report).
inline std::vector<SettingConflict> setting_conflicts(const Settings& s, const RunFacts& facts) {
  std::vector<SettingConflict> out;
  const auto add = [&](const char* setting, std::string why, long guard = -1) {
    if (!why.empty()) out.push_back({setting, guard, std::move(why)});
  };
  add("dt", frames_rule(s));
  add("step", steps_rule(s));
  add("ranks", ranks_rule(s));
  add("ranks", one_process_rule(s, run_ranks(s, facts)));
  if (facts.guards_without_inverse)
    for (const auto& [g, name] : *facts.guards_without_inverse)
      add("method", inverse_rule(s, name), static_cast<long>(g));
  add("density", marginals_rule(s));
  add("scheme", fv_scheme_rule(s));
  add("scheme", galerkin_scheme_rule(s, run_ranks(s, facts)));
  add("fv_order", fv_order_rule(s));
  add("grid", memory_rule(s, facts));
  add("outputs", vti_rule(s, run_ranks(s, facts)));
  if (!facts.states.empty()) add("figure_axes", figure_axes_rule(s, facts.states));
  return out;
}

}  // namespace hybgen::rt
