#pragma once
/// \file netcdf_series.hpp
/// Reading a run.nc's one-dimensional series (the budget's terms, a guard's absorbed mass or
/// impacts) as a test checks them against summary.json.

#include <netcdf.h>

#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

namespace hybgen::testing {

/// A one-dimensional variable of a NetCDF file, as doubles (empty when it is not there).
inline std::vector<double> nc_values(const std::filesystem::path& file, const std::string& name) {
  int id = -1, var = -1;
  if (nc_open(file.c_str(), NC_NOWRITE, &id) != NC_NOERR) return {};
  std::vector<double> out;
  std::size_t len = 0;
  int dim = -1, ndims = 0;
  if (nc_inq_varid(id, name.c_str(), &var) == NC_NOERR && nc_inq_varndims(id, var, &ndims) == 0 &&
      ndims == 1 && nc_inq_vardimid(id, var, &dim) == 0 && nc_inq_dimlen(id, dim, &len) == 0) {
    out.resize(len);
    nc_get_var_double(id, var, out.data());
  }
  nc_close(id);
  return out;
}

}  // namespace hybgen::testing

namespace hybgen::testing {

/// An integer variable of a NetCDF file of any rank, flattened in C order (empty when it is
/// not there).
inline std::vector<int> nc_ints(const std::filesystem::path& file, const std::string& name) {
  int id = -1, var = -1;
  if (nc_open(file.c_str(), NC_NOWRITE, &id) != NC_NOERR) return {};
  std::vector<int> out;
  int ndims = 0;
  if (nc_inq_varid(id, name.c_str(), &var) == NC_NOERR && nc_inq_varndims(id, var, &ndims) == 0) {
    std::vector<int> dims(static_cast<std::size_t>(ndims));
    std::size_t total = 1;
    if (nc_inq_vardimid(id, var, dims.data()) == NC_NOERR)
      for (const int d : dims) {
        std::size_t len = 0;
        nc_inq_dimlen(id, d, &len);
        total *= len;
      }
    out.resize(total);
    if (nc_get_var_int(id, var, out.data()) != NC_NOERR) out.clear();
  }
  nc_close(id);
  return out;
}

}  // namespace hybgen::testing
