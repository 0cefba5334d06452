"""An independent reader of run.nc (runtime/src/io/netcdf.cpp): xarray opens the file and
every value is compared with what the run wrote beside it (the .npy frames, read by numpy,
and summary.json) and with the model file itself.

usage: check_run_nc.py RUN_DIR MODEL_FILE   (prints 'ok', or fails with an assertion)
"""
import hashlib
import json
import os
import sys

import numpy as np
import xarray as xr

run_dir, model_file = sys.argv[1], sys.argv[2]
s = json.load(open(os.path.join(run_dir, "summary.json")))
ds = xr.open_dataset(os.path.join(run_dir, "run.nc"))
axes = s["grid"]["axes"]
names = [a["name"] for a in axes]


def ours(base):
    """Our name for `base`: a trailing '_' while a state variable has it."""
    while base in names:
        base += "_"
    return base


# Coordinates: the grid nodes, both ends included.
for a in axes:
    x = ds[a["name"]].values
    assert x.shape == (a["n"],), (a, x.shape)
    assert np.allclose(x, np.linspace(a["min"], a["max"], a["n"]), rtol=0, atol=1e-14), a
    assert x[0] == a["min"] and x[-1] == a["max"], a

density = ds[ours("density")]
modes = s["modes"]
series = s["method"] != "invariant"
if series:
    time = ours("time")
    assert list(density.dims) == [time] + names, density.dims
    assert np.array_equal(ds[time].values, np.array(s["times"])), "times"
    npy = s["outputs"]["npy"]
    assert len(npy) == len(s["times"])
    for k, f in enumerate(npy):
        assert np.array_equal(density.values[k], np.load(os.path.join(run_dir, f))), f
    if len(modes) > 1:
        by_mode = ds[ours("density_by_mode")]
        assert list(by_mode.dims) == [time, ours("mode")] + names, by_mode.dims
        assert [str(m) for m in ds[ours("mode")].values] == modes
        for m, name in enumerate(modes):
            for k, f in enumerate(s["outputs"]["mode_npy"][name]):
                assert np.array_equal(by_mode.values[k, m], np.load(os.path.join(run_dir, f))), f
        assert np.allclose(by_mode.sum(ours("mode")).values, density.values, rtol=1e-15, atol=0)
    else:
        assert ours("density_by_mode") not in ds
    # The mass budget, and what no term accounts for computed here.
    for key in ["mass", "outflow", "atom"]:
        assert np.array_equal(ds[ours(key)].values, np.array(s[key])), key
    assert float(ds[ours("initial_mass")]) == s["initial_mass"]
    # The transfer operator's error per output time (null in summary.json: NaN here).
    if "transfer" in s and isinstance(s["transfer"].get("errors"), list):
        want = np.array([np.nan if e is None else e for e in s["transfer"]["errors"]])
        assert np.array_equal(ds[ours("density_error")].values, want, equal_nan=True)
    else:
        assert ours("density_error") not in ds
    unaccounted = s["initial_mass"] - np.array(s["mass"]) - np.array(s["outflow"]) - np.array(s["atom"])
    assert np.allclose(ds[ours("unaccounted")].values, unaccounted, rtol=0, atol=1e-15), "unaccounted"
    if "budget" in s and "mass_error" in s["budget"]:
        assert np.array_equal(ds[ours("mass_error")].values, np.array(s["budget"]["mass_error"]))
else:
    assert list(density.dims) == names, density.dims
    assert np.array_equal(density.values, np.load(os.path.join(run_dir, "invariant.npy")))
    ev = s["invariant"]["eigenvalues"]
    assert np.array_equal(ds[ours("eigenvalue_abs")].values, np.array([l["abs"] for l in ev]))
    assert np.array_equal(ds[ours("eigenvalue_real")].values, np.array([l["re"] for l in ev]))
    assert ds.attrs["spectral_gap"] == s["invariant"]["spectral_gap"]
    # The estimated errors travel with the numbers (docs/outputs.md).
    errors = np.array([np.nan if l.get("error") is None else l["error"] for l in ev])
    assert np.array_equal(ds[ours("eigenvalue_error")].values, errors, equal_nan=True), "eigenvalue_error"
    assert not np.isnan(errors).all(), "no eigenvalue carries an error"
    for key in ("spectral_gap_error", "decay_rate_error", "leak_rate_error"):
        assert ds.attrs[key] == s["invariant"][key], key
    assert ds.attrs["density_error"] == s["invariant"]["error"]
    assert ds.attrs["decays"] == ("true" if s["invariant"]["decays"] else "false")
    assert ds.attrs["leaks"] == ("true" if s["invariant"]["leaks"] else "false")

# Where it came from.
text = open(model_file, "rb").read()
assert ds.attrs["Conventions"] == "CF-1.8"
assert ds.attrs["model"] == s["model"] and ds.attrs["method"] == s["method"]
assert ds.attrs["model_sha256"] == hashlib.sha256(text).hexdigest()
assert ds.attrs["model_text"] == text.decode()
assert ds.attrs["equations"].startswith("model " + s["model"])
assert json.loads(ds.attrs["settings"])["method"] == s["method"]
for p, v in s["parameters"].items():
    assert ds.attrs["parameter_" + p] == v, p
# The history names the command, with every --set it applied (config.json has them).
sets = json.load(open(os.path.join(run_dir, "config.json")))["provenance"]["sets"]
history = ds.attrs["history"]
assert " hybgen run " in history, history
for kv in sets:
    assert (" --set " + kv) in history or (" --set '" + kv + "'") in history, (kv, history)
print("ok")
