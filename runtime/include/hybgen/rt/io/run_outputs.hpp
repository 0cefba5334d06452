#pragma once
/// \file run_outputs.hpp
/// A run's files, chosen by the setting `outputs` (settings.hpp): `run.nc` (netcdf.hpp),
/// pictures (figures.hpp), `.npy` arrays per frame and mode (npy.hpp), and `.vti`
/// images with per-mode arrays and a `.pvd` time series for ParaView (vti.hpp). Written in
/// parallel (frames over threads, run.nc beside them) into a staging directory whose files
/// are made durable together, once, by the caller (atomic_file.hpp, DeferredDurability).

#include <map>
#include <string>
#include <vector>

#include "hybgen/rt/io/run_record.hpp"
#include "hybgen/rt/settings.hpp"

namespace hybgen::rt {

/// The files a run wrote, by kind, as names relative to its directory.
struct WrittenOutputs {
  std::string netcdf;                                        ///< run.nc, or empty.
  std::vector<std::string> npy;                              ///< Summed density per frame.
  std::map<std::string, std::vector<std::string>> mode_npy;  ///< Per mode (several modes).
  std::vector<std::string> figures;  ///< Pictures (figures.hpp): frames, density.pdf, budget.
  std::vector<std::string> vti;      ///< VTK images, per frame.
  std::string pvd;                   ///< The .vti time series.
  std::string report;                ///< report.html, or empty.
  std::vector<std::string> notes;    ///< What was not written and why (printed, not fatal).
  /// What the files may mislead about (printed as warnings): a density narrower than the
  /// grid (resolution_warning).
  std::vector<std::string> warnings;

  /// As the summary's `outputs` block.
  nlohmann::json to_json() const;
  /// One line for the terminal: "run.nc, u_0000..u_0050 .png/.vti, u.pvd".
  std::string describe(const std::vector<std::string>& frame_names) const;
};

/// Whether the grid under-resolves the density: when the budget measured the mass by
/// adaptive cubature (characteristics: `budget.mass_error` is set), the trapezoid sum of the
/// node values at some output time differs from it by more than 5 % of the initial mass and
/// 10 times its error bar. Node samples of a density narrower than the grid's spacing (a
/// concentrating flow) are then speckle, not a picture of the density. "" when not.
std::string resolution_warning(const RunRecord& run);

/// Writes the outputs `settings` chooses for `run` into `dir` (an existing directory);
/// throws std::runtime_error naming the file on an I/O failure. Frames are written in
/// parallel; `quiet` hides the progress bar.
WrittenOutputs write_run_outputs(const RunRecord& run, const Settings& settings,
                                 const std::string& dir, bool quiet);

}  // namespace hybgen::rt
