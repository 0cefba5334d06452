#pragma once
/// \file run_files.hpp
/// The kinds of file a run writes into its directory, defined once: the runner writes only
/// these (run_outputs.hpp, runner.hpp), and hybgen replaces a directory only when it holds
/// nothing else (generator/src/outputs.cpp), so that `--out` never deletes a user's file.

#include <array>
#include <string_view>

namespace hybgen::rt {

/// Extensions of the files in a run's directory (run.nc, frames, summary and config).
inline constexpr std::array<std::string_view, 6> kRunFileExtensions = {".nc",  ".npy", ".png",
                                                                       ".vti", ".pvd", ".json"};

/// Whether `ext` (with its dot) is the extension of a file a run writes.
constexpr bool is_run_file_extension(std::string_view ext) {
  for (const std::string_view e : kRunFileExtensions)
    if (e == ext) return true;
  return false;
}

}  // namespace hybgen::rt
