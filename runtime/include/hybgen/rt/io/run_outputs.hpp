#pragma once
/// \file run_outputs.hpp
/// A run's files, chosen by the setting `outputs` (settings.hpp): `run.nc` (netcdf.hpp),
/// pictures per frame (png.hpp), `.npy` arrays per frame and mode (npy.hpp), and `.vti`
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
  std::vector<std::string> png;                              ///< Pictures, per frame.
  std::vector<std::string> vti;                              ///< VTK images, per frame.
  std::string pvd;                                           ///< The .vti time series.
  std::vector<std::string> notes;  ///< What was not written and why (printed, not fatal).

  /// As the summary's `outputs` block.
  nlohmann::json to_json() const;
  /// One line for the terminal: "run.nc, u_0000..u_0050 .png/.vti, u.pvd".
  std::string describe(const std::vector<std::string>& frame_names) const;
};

/// Writes the outputs `settings` chooses for `run` into `dir` (an existing directory);
/// throws std::runtime_error naming the file on an I/O failure. Frames are written in
/// parallel; `quiet` hides the progress bar.
WrittenOutputs write_run_outputs(const RunRecord& run, const Settings& settings,
                                 const std::string& dir, bool quiet);

}  // namespace hybgen::rt
