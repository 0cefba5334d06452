#pragma once
/// \file hash.hpp
/// Content hashes for provenance headers and the build cache (SHA-256).

#include <string>
#include <string_view>

namespace hybgen::gen {

/// Lower-case hex SHA-256 of `data`.
std::string sha256_hex(std::string_view data);

}  // namespace hybgen::gen
