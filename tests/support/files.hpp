#pragma once
/// \file files.hpp
/// Reading a file a test wrote or had written, whole, with no library of hybgen's (the runtime
/// tests do not link the generator's hybgen/gen/fs.hpp).

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace hybgen::testing {

/// The bytes of the file `p` ("" when it cannot be opened).
inline std::string read_text(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace hybgen::testing
