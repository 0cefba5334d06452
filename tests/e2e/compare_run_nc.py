"""Two run.nc files hold the same run: the same dimensions, coordinates, variables and
attributes (but `history`, the time of writing, and in `settings` the backend, ranks and
threads; and `density_error`, which a run over several processes does not estimate), the
density's chunks and compression, and
data equal to the bit (numpy.array_equal) or, with --rtol R, to R of each variable's largest
magnitude (for the budget's series, at least of the initial mass). Used by tests/e2e/test_mpi.cpp: a run over two MPI ranks, whose run.nc every rank
writes in parts through parallel NetCDF, against the one-process run's file.

usage: compare_run_nc.py A B [--rtol R]; prints "ok" or what differs, exits 0 either way."""
import json
import sys

import netCDF4
import numpy as np


def main():
    a_path, b_path = sys.argv[1], sys.argv[2]
    rtol = float(sys.argv[sys.argv.index("--rtol") + 1]) if "--rtol" in sys.argv else 0.0
    a, b = netCDF4.Dataset(a_path), netCDF4.Dataset(b_path)
    problems = []
    dims = lambda d: {k: len(v) for k, v in d.dimensions.items()}
    if dims(a) != dims(b):
        problems.append(f"dimensions {dims(a)} != {dims(b)}")
    def attrs(d):
        out = {k: d.getncattr(k) for k in d.ncattrs() if k != "history"}
        if "settings" in out:  # the run's settings but how it was spread over processes
            settings = json.loads(out["settings"])
            for key in ("backend", "ranks", "threads"):
                settings.pop(key, None)
            out["settings"] = settings
        return out
    if attrs(a) != attrs(b):
        differ = sorted(k for k in set(attrs(a)) | set(attrs(b)) if attrs(a).get(k) != attrs(b).get(k))
        problems.append(f"global attributes differ: {differ}")
    # The transfer operator's error estimate needs whole frames: a run over MPI ranks makes
    # none (runtime/include/hybgen/rt/methods/methods.hpp, add_transfer_errors).
    one_process_only = {"density_error"}
    if set(a.variables) - one_process_only != set(b.variables) - one_process_only:
        problems.append(f"variables {sorted(a.variables)} != {sorted(b.variables)}")
    for name in sorted(set(a.variables) & set(b.variables)):
        va, vb = a.variables[name], b.variables[name]
        if va.dimensions != vb.dimensions:
            problems.append(f"{name}: dimensions {va.dimensions} != {vb.dimensions}")
            continue
        if {k: va.getncattr(k) for k in va.ncattrs()} != {k: vb.getncattr(k) for k in vb.ncattrs()}:
            problems.append(f"{name}: attributes differ")
        if va.chunking() != vb.chunking() or va.filters() != vb.filters():
            problems.append(f"{name}: storage {va.chunking()} {va.filters()} != "
                            f"{vb.chunking()} {vb.filters()}")
        x, y = va[...], vb[...]
        if va.dtype == str or x.dtype.kind in "OUS":
            if list(np.ravel(x)) != list(np.ravel(y)):
                problems.append(f"{name}: strings differ")
            continue
        x, y = np.ma.filled(x, np.nan), np.ma.filled(y, np.nan)
        # The observables' errors of transfer and invariant come from coarse answers that a
        # run over ranks does not keep (runtime/include/hybgen/rt/methods/observables.hpp):
        # NaN there, compared where both runs estimated them.
        if name.startswith("observable_") and name.endswith("_error") and (
                np.all(np.isnan(x)) or np.all(np.isnan(y))):
            continue
        if rtol == 0.0:
            if not np.array_equal(x, y, equal_nan=True):
                diff = np.nanmax(np.abs(x - y)) if x.size else 0.0
                problems.append(f"{name}: not the same bits (max |difference| {diff:.3g})")
        else:
            # NaN (none estimated, infinite impacts) must be where the other run has it; a
            # series that is NaN throughout in both (transfer's impacts' errors) agrees.
            if not np.array_equal(np.isnan(x), np.isnan(y)):
                problems.append(f"{name}: NaN at different places")
                continue
            if x.size and np.all(np.isnan(x)):
                continue
            scale = max(np.nanmax(np.abs(x)) if x.size else 0.0, 1e-300)
            if va.ndim <= 1 and "initial_mass" in a.variables:  # the budget: of the mass
                scale = max(scale, abs(float(a.variables["initial_mass"][...])))
            diff = np.nanmax(np.abs(x - y)) if x.size else 0.0
            if not diff <= rtol * scale:
                problems.append(f"{name}: max |difference| {diff:.3g} > {rtol:g} x {scale:.3g}")
    print("ok" if not problems else "; ".join(problems))


main()
