#pragma once
/// \file run_files.hpp
/// The kinds of file a run writes into its directory, defined once: the runner writes only
/// these (run_outputs.hpp, runner.hpp), and hybgen replaces a directory only when it holds
/// nothing else (generator/src/outputs.cpp), so that `--out` never deletes a user's file.

#include <array>
#include <string_view>

namespace hybgen::rt {

/// Extensions of the files in a run's directory (run.nc, frames, summary and config).
inline constexpr std::array<std::string_view, 10> kRunFileExtensions = {
    ".nc", ".npy", ".png", ".pdf", ".svg", ".gif", ".vti", ".pvd", ".json", ".html"};

/// The report's copy of KaTeX (report.hpp): the one directory a run writes, holding only
/// files with these extensions (its fonts in a subdirectory).
inline constexpr std::string_view kReportAssetsDirectory = "katex";
/// Extensions of the files in kReportAssetsDirectory.
inline constexpr std::array<std::string_view, 3> kReportAssetExtensions = {".css", ".js", ".woff2"};

/// Whether `ext` (with its dot) is the extension of a file a run writes.
constexpr bool is_run_file_extension(std::string_view ext) {
  for (const std::string_view e : kRunFileExtensions)
    if (e == ext) return true;
  return false;
}

/// Whether `ext` (with its dot) is the extension of a report asset.
constexpr bool is_report_asset_extension(std::string_view ext) {
  for (const std::string_view e : kReportAssetExtensions)
    if (e == ext) return true;
  return false;
}

}  // namespace hybgen::rt
