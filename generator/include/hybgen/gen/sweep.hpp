#pragma once
/// \file sweep.hpp
/// `hybgen sweep`: one runner over a grid of parameter or setting values.
///
///   hybgen sweep MODEL --set e=0.5:1.0:6 --set method=characteristics,transfer [--set K=V]...
///
/// A `--set` value `A:B:N` is N equally spaced numbers from A to B (both included); a value
/// `v1,v2,...` is a list (commas inside brackets belong to the element: domain.x=[0,1],[0,2];
/// braces around the list are allowed, quoted, since a shell expands {v1,v2}).
/// Every other `--set` applies to every point. The points are the Cartesian product of the
/// axes, the first axis varying slowest. Each point is derived as `hybgen run` would derive
/// it (so every value is checked before anything runs), all points share one runner (the
/// values are read at run time, run.hpp), and the runners run `jobs` at a time. OUT holds
/// one directory of run outputs per point, sweep.csv and sweep.json: one row per point of the
/// swept values, the exit status and the run's summary quantities (sweep_row).

#include <cstddef>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "hybgen/gen/reduce.hpp"
#include "hybgen/gen/run.hpp"

namespace hybgen::gen {

/// One axis of a sweep: a setting or parameter and the values it takes, as `--set` writes them.
struct SweepAxis {
  std::string key;                  ///< The parameter or setting.
  std::vector<std::string> values;  ///< Its values, in order.
};

/// The `--set` arguments of a sweep, split.
struct SweepSpec {
  std::vector<std::string> fixed;  ///< KEY=VALUE overrides for every point.
  std::vector<SweepAxis> axes;     ///< The swept keys (at least one).
};

/// Most points a sweep may have: a typo such as e=0:1:100000 is refused, not run.
inline constexpr std::size_t kMaxSweepPoints = 10000;

/// Split `sets` into fixed overrides and axes. Throws UsageError for a malformed range or
/// list, a key given twice, no axis at all, or more than kMaxSweepPoints points.
SweepSpec parse_sweep(const std::vector<std::string>& sets);

/// The points of `spec`: for each, the KEY=VALUE of every axis (first axis slowest).
std::vector<std::vector<std::string>> sweep_points(const SweepSpec& spec);

/// A point's directory name: its index, zero-padded to the width of `count - 1`, then
/// `_KEY=VALUE` per axis, with characters other than [A-Za-z0-9._=+-] as '_'.
std::string sweep_label(std::size_t index, std::size_t count,
                        const std::vector<std::string>& point);

/// The summary quantities of one run (its summary.json) as a flat row: method, final time,
/// initial mass and, at the final time, mass, outflow, atom and the unaccounted mass with
/// their error bars; for `invariant` the spectral gap, decay rate and |λ| of the leading
/// eigenvalues; for `escape` the escape rate and its error; the timings in seconds.
nlohmann::ordered_json sweep_row(const nlohmann::json& summary);

/// The table as CSV: one header line (the union of the rows' keys, in first-seen order),
/// then one line per row; a missing value is an empty cell; numbers exactly (the shortest
/// decimal that reads back as the same double).
std::string sweep_csv(const nlohmann::ordered_json& rows);

/// How `hybgen sweep` runs.
struct SweepOptions {
  RunOptions run;                               ///< Output directory, build, quiet.
  std::size_t jobs = 0;                         ///< Runners at once (0: one per core).
  ReduceTarget target = ReduceTarget::Reduced;  ///< Lie-group models: --unreduced.
};

/// `hybgen sweep` on the model file `path`. Returns 0 if every point ran; else the exit
/// code of the first point that failed (its row says so; OUT is replaced if any point ran,
/// else left unchanged). On an interrupt, stops every runner, removes the staging directory
/// and ends hybgen by the signal.
int run_sweep(const std::string& path, const SweepSpec& spec, const SweepOptions& options);

}  // namespace hybgen::gen
