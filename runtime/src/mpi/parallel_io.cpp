// ParallelIo over MPI_COMM_WORLD with Debian's parallel NetCDF (libnetcdf-mpi-dev): the file
// is opened by every rank through parallel HDF5 (MPI-IO). An MPI runner links
// libnetcdf_mpi instead of the serial libnetcdf (generator/src/build.cpp), so the writers of
// hybgen::io (runtime/src/io/netcdf.cpp) call the same library as this file.

#include <mpi.h>
#include <netcdf.h>
#include <netcdf_par.h>

#include "mpi_backend.hpp"

namespace hybgen::rt::mpi {

namespace {

class ParallelNetcdf final : public ParallelIo {
 public:
  int open_netcdf(const char* path, int* ncid) const override {
    return nc_open_par(path, NC_WRITE, MPI_COMM_WORLD, MPI_INFO_NULL, ncid);
  }
  int collective(int ncid, int var) const override {
    return nc_var_par_access(ncid, var, NC_COLLECTIVE);
  }
};

}  // namespace

const ParallelIo& parallel_netcdf() {
  static const ParallelNetcdf io;
  return io;
}

}  // namespace hybgen::rt::mpi
