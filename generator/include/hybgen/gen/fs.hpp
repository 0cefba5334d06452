#pragma once
/// \file fs.hpp
/// File-system helpers of the generator: atomic writes, whole-file reads.

#include <string>

namespace hybgen::gen {

/// Write `content` to `path` atomically (temporary file in the same directory,
/// fsync, rename). On failure the previous file is intact, the temporary file
/// is removed, and std::runtime_error names the path and the reason.
void write_file_atomic(const std::string& path, const std::string& content);

/// Read a whole file; throws std::runtime_error naming the path on failure.
std::string read_file(const std::string& path);

}  // namespace hybgen::gen
