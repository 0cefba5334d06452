#pragma once
/// \file netcdf.hpp
/// One NetCDF-4 file per run (`run.nc`, CF-1.8), the run's self-describing result:
/// `xarray.open_dataset("run.nc")` gives a labelled dataset.
///
/// Dimensions: one per state variable, named after it, and `time` (a time series) or
/// `eigenvalue` (an invariant density), `mode` when the model has several. Variables:
///  - a coordinate per state (its grid nodes, both ends included), `time`, `mode` (names);
///  - `density` (time, states…): the density summed over the modes; `density_by_mode`
///    (time, mode, states…) when there are several modes. Without `time` for a method with one
///    frame (`invariant`, `escape`);
///  - the mass budget as time series: `mass`, `outflow`, `atom`, `unaccounted`
///    (mass0 − mass − outflow − atom) and their `_error` bars (solution.hpp, budget.hpp),
///    `initial_mass`;
///  - `invariant`: `eigenvalue_real`, `eigenvalue_imag`, `eigenvalue_abs` and the
///    spectral gap and decay rate as attributes;
///  - `escape`: the global attributes `escape_rate`, `escape_rate_error` (per unit time, with
///    `escape_rate_units` and `escape_rate_description`), `escape_lambda1`, `transfer_step`.
/// Global attributes: Conventions, title, source, history, model, method, the model's text
/// and SHA-256, the derived equations, the settings (JSON) and every parameter value.
/// A name of ours that a state variable already uses gets a trailing `_` (a state called
/// `time` keeps its name; the time axis is then `time_`).
/// Docs: docs/outputs.md, "run.nc".

#include <cstddef>
#include <string>
#include <vector>

#include "hybgen/rt/io/run_record.hpp"

namespace hybgen::rt {

/// Frames of more than this many nodes are chunked in slabs of their slowest axes (16 MiB
/// chunks; HDF5 refuses chunks of 4 GiB and more, and a rank writing its part of a chunk
/// sends it to the chunk's writer).
inline constexpr std::size_t kChunkValues = std::size_t{1} << 21;

/// Writes `run` to `path` as NetCDF-4 (replacing it); throws std::runtime_error naming the
/// file and what NetCDF said. `deflate` is the zlib level of the density (0: none). A
/// distributed run (RunRecord::distributed): everything but the density's values, which
/// every rank then writes with write_netcdf_frames.
void write_netcdf(const std::string& path, const RunRecord& run, int deflate = 1);

/// The density of a distributed run into the run.nc that write_netcdf made: every rank of
/// run.backend, collectively (its ParallelIo: parallel NetCDF-4 through MPI-IO), writes
/// `density` from `total` (per frame, this rank's block Backend::block(n_node) of the density
/// summed over the modes) and `density_by_mode` from its pairs run.owned. No rank holds more
/// than its own part. Throws std::runtime_error naming the file.
void write_netcdf_frames(const std::string& path, const RunRecord& run,
                         const std::vector<std::vector<double>>& total);

}  // namespace hybgen::rt
