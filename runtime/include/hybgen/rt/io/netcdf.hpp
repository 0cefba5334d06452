#pragma once
/// \file netcdf.hpp
/// One NetCDF-4 file per run (`run.nc`, CF-1.8), the run's self-describing result:
/// `xarray.open_dataset("run.nc")` gives a labelled dataset.
///
/// Dimensions: one per state variable, named after it, and `time` (a time series) or
/// `eigenvalue` (an invariant density), `mode` when the model has several. Variables:
///  - a coordinate per state (its grid nodes, both ends included), `time`, `mode` (names);
///  - `density` (time, states…): the density summed over the modes; `density_by_mode`
///    (time, mode, states…) when there are several modes. Without `time` for `invariant`;
///  - the mass budget as time series: `mass`, `outflow`, `atom`, `unaccounted`
///    (mass0 − mass − outflow − atom) and their `_error` bars (solution.hpp, budget.hpp),
///    `initial_mass`;
///  - `invariant`: `eigenvalue_real`, `eigenvalue_imag`, `eigenvalue_abs` and the
///    spectral gap and decay rate as attributes.
/// Global attributes: Conventions, title, source, history, model, method, the model's text
/// and SHA-256, the derived equations, the settings (JSON) and every parameter value.
/// A name of ours that a state variable already uses gets a trailing `_` (a state called
/// `time` keeps its name; the time axis is then `time_`).
/// Docs: docs/outputs.md, "run.nc".

#include <string>

#include "hybgen/rt/io/run_record.hpp"

namespace hybgen::rt {

/// Writes `run` to `path` as NetCDF-4 (replacing it); throws std::runtime_error naming the
/// file and what NetCDF said. `deflate` is the zlib level of the density (0: none).
void write_netcdf(const std::string& path, const RunRecord& run, int deflate = 1);

}  // namespace hybgen::rt
