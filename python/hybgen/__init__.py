"""hybgen from Python: run a model, or sweep it, with the installed ``hybgen`` and open its outputs.

    import hybgen
    ds = hybgen.run("models/bouncing_ball.model", e=0.8, t_end=5)   # run.nc as an xarray.Dataset
    table = hybgen.sweep("models/bouncing_ball.model", e="0.5:0.9:5", t_end=5)   # sweep.csv

Keyword arguments are hybgen's settings and the model's parameters (``hybgen run --help``,
docs/settings.md); each becomes one ``--set KEY=VALUE``. Numbers are passed exactly (a float as
its ``repr``, which reads back to the same double), ``grid=(75, 75)`` as ``75x75``, a sequence for
``outputs`` or ``figure_axes`` joined by ``+``, any other sequence (a domain) as ``[a,b]``, strings
as they are. ``domain__x=(0, 2)`` is ``domain.x=[0,2]``, ``observe__E="p^2/2 + x"`` an observable
(its mean per output time is ``ds["observable_E"]``, its error ``ds["observable_E_error"]``);
``sets={"domain.x": (0, 2)}`` takes any key. A bool is refused: no setting is true or false.

Importing needs only the standard library; ``run`` needs xarray (Debian's python3-xarray and
python3-netcdf4), ``sweep`` pandas. ``cmake --install`` puts this package beside ``bin/hybgen``
(cmake/HybgenInstall.cmake, docs/install.md), and ``find_exe`` finds that hybgen.
"""
import codecs
import contextlib
import json
import numbers
import os
import shutil
import subprocess
import sys
import tempfile
import warnings

__all__ = ["HybgenError", "run", "sweep", "summary", "find_exe"]

_JOINERS = {"grid": "x", "outputs": "+", "figure_axes": "+"}


class HybgenError(RuntimeError):
    """A hybgen command that failed.

    ``code``: its exit status (1 model error, 2 bad command line or setting, 3 numerical failure,
    4 build failed, 70 internal; negative: ended by that signal). ``output``: what it printed (its
    stderr; with ``quiet=False`` its stdout too). ``table``: for ``sweep``, sweep.csv as a DataFrame
    when the sweep wrote one (the failed points' rows have their status and exit), else None.
    """

    def __init__(self, message, code=None, output="", table=None):
        super().__init__(message)
        self.code, self.output, self.table = code, output, table


def find_exe(exe=None):
    """The hybgen executable: ``exe`` (a path, or a name on PATH), else $HYBGEN_EXE, else the hybgen
    that ``cmake --install`` put beside this package, else ``hybgen`` on PATH.

    Returns its path; raises FileNotFoundError if there is none. Example: ``hybgen.find_exe()``.
    """
    given = exe if exe is not None else os.environ.get("HYBGEN_EXE")
    if given:
        found = shutil.which(os.fspath(given))
        if found is None:
            raise FileNotFoundError(f"hybgen executable {os.fspath(given)!r} not found")
        return os.path.abspath(found)
    try:  # written at install time: the path from this directory to bin/hybgen
        from ._install import hybgen_exe
        here = os.path.dirname(os.path.realpath(__file__))
        path = os.path.normpath(os.path.join(here, hybgen_exe))
        if os.access(path, os.X_OK):
            return path
    except ImportError:  # the source tree's copy
        pass
    found = shutil.which("hybgen")
    if found is None:
        raise FileNotFoundError("cannot find hybgen: pass exe=..., set HYBGEN_EXE, or put hybgen "
                                "on PATH (cmake --install installs this package beside it)")
    return found


def run(model, out=None, *, exe=None, sets=None, quiet=True, **settings):
    """Run ``hybgen run MODEL --set KEY=VALUE ...`` and return its run.nc, loaded into memory.

    model: the .model file. out: the output directory; None runs in a temporary directory with
    ``outputs=netcdf``, removed after loading (with ``out``, ``netcdf`` is added to an ``outputs``
    setting that lacks it, and ``ds.attrs["hybgen_out_dir"]`` names the directory). exe: see
    ``find_exe``. sets: settings by their hybgen names (``{"domain.x": (0, 2)}``). quiet: False
    shows hybgen's progress and table on stderr. settings: parameters and settings (module
    docstring).

    Returns an xarray.Dataset (the file is closed). Raises HybgenError if hybgen fails; hybgen's
    warnings become Python warnings when quiet. Example:
    ``hybgen.run("models/bouncing_ball.model", e=0.8, t_end=5)["density"]``.
    """
    import xarray
    values = _merge(sets, settings)
    if out is None:
        values.setdefault("outputs", "netcdf")
    if "outputs" in values and "netcdf" not in _value("outputs", values["outputs"]).split("+"):
        values["outputs"] = _value("outputs", values["outputs"]) + "+netcdf"
    flags = [f for key, value in values.items() for f in ("--set", f"{key}={_value(key, value)}")]
    with _directory(out) as directory:
        _call(exe, "run", model, directory, flags, quiet)
        ds = xarray.load_dataset(os.path.join(directory, "run.nc"))
    if out is not None:
        ds.attrs["hybgen_out_dir"] = os.path.abspath(out)
    return ds


def sweep(model, out=None, *, exe=None, sets=None, quiet=True, jobs=None, **axes):
    """Run ``hybgen sweep MODEL --set KEY=VALUES ...`` and return its sweep.csv, one row per point.

    axes: parameters and settings as for ``run``; a list, tuple or array of values is an axis
    (``a=[0.5, 1.0]``: ``a=0.5,1.0``; a domain's axis is a list of pairs, and a pair alone is a
    fixed domain), a string passes as it is (``e="0.5:0.9:5"``: five values), a scalar is fixed.
    out, exe, sets, quiet: as for ``run`` (with ``out=None``, the points write only run.nc and
    ``table.attrs["hybgen_out_dir"]`` is not set). jobs: runners at a time (default: one per core).

    Returns a pandas.DataFrame (columns: docs/outputs.md and README.md, "Sweeps"). Raises
    HybgenError when the sweep or a point fails, with the table in ``.table`` if it was written.
    Example: ``hybgen.sweep("models/bouncing_ball.model", e=[0.6, 0.8], t_end=5)[["e", "mass"]]``.
    """
    import pandas
    values = _merge(sets, axes)
    if out is None:
        values.setdefault("outputs", "netcdf")
    flags = []
    for key, value in values.items():
        items = _items(value)
        # A flat sequence of numbers is one value for a domain ([a,b]) and for the joined
        # settings (grid=(75, 75): 75x75; outputs, figure_axes); an axis of those is a list of
        # sequences. Any other sequence is an axis.
        one_value = (key.startswith("domain.") or key in _JOINERS) and not any(
            _items(v) is not None for v in items or [])
        if items and not one_value:  # an axis
            flags += ["--set", f"{key}=" + ",".join(_value(key, v) for v in items)]
        else:
            flags += ["--set", f"{key}={_value(key, value)}"]
    flags += ["-j", str(int(jobs))] if jobs is not None else []
    with _directory(out) as directory:
        csv = os.path.join(directory, "sweep.csv")
        before = os.stat(csv).st_mtime_ns if os.path.exists(csv) else None
        try:
            _call(exe, "sweep", model, directory, flags, quiet)
        except HybgenError as error:  # the points that ran keep their rows
            if os.path.exists(csv) and os.stat(csv).st_mtime_ns != before:
                error.table = pandas.read_csv(csv)
            raise
        table = pandas.read_csv(csv)
    if out is not None:
        table.attrs["hybgen_out_dir"] = os.path.abspath(out)
    return table


def summary(out_dir):
    """summary.json of a run's output directory (or the file itself) as a dict.

    Raises FileNotFoundError if it is missing. Example, after
    ``hybgen.run("models/bouncing_ball.model", "out/bouncing_ball")``:
    ``hybgen.summary("out/bouncing_ball")["mass"]``.
    """
    path = os.fspath(out_dir)
    if os.path.isdir(path):
        path = os.path.join(path, "summary.json")
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def _merge(sets, keywords):
    """One dict of hybgen keys: ``sets`` as given, keywords with ``__`` read as ``.``."""
    merged = dict(sets or {})
    for key, value in keywords.items():
        key = key.replace("__", ".")
        if key in merged:
            raise TypeError(f"setting {key!r} given twice")
        merged[key] = value
    return merged


def _items(value):
    """The elements of a list, tuple, range or array (ndim >= 1), else None."""
    if isinstance(value, (list, tuple, range)) or getattr(value, "ndim", 0) >= 1:
        return list(value)
    return None


def _value(key, value):
    """One --set value as hybgen reads it (module docstring)."""
    if isinstance(value, str):
        return value
    if isinstance(value, bool):  # an Integral too, which would pass as 1 or 0
        raise TypeError(f"setting {key!r}: hybgen has no true/false setting; pass a number or a "
                        f"word (hybgen run --help), not {value!r}")
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        return repr(float(value))
    items = _items(value)
    if items is None:
        raise TypeError(f"setting {key!r}: cannot pass {value!r} to hybgen")
    parts = [_value(key, v) for v in items]
    return _JOINERS[key].join(parts) if key in _JOINERS else "[" + ",".join(parts) + "]"


def _directory(out):
    """``out`` as a context, or a temporary directory's ``run`` (its lock and staging beside it)."""
    if out is not None:
        return contextlib.nullcontext(os.fspath(out))

    @contextlib.contextmanager
    def temporary():
        with tempfile.TemporaryDirectory(prefix="hybgen-") as tmp:
            yield os.path.join(tmp, "run")
    return temporary()


def _call(exe, command, model, directory, flags, quiet):
    """Run ``hybgen COMMAND MODEL --out DIRECTORY FLAGS``, echoing what it prints to stderr unless
    quiet (then its warnings become Python warnings); raise HybgenError if it fails."""
    argv = [find_exe(exe), command, os.fspath(model), "--out", directory, *flags]
    argv += ["-q"] if quiet else []
    decoder, chunks = codecs.getincrementaldecoder("utf-8")("replace"), []
    with subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT) as proc:
        while chunk := proc.stdout.read1(65536):
            chunks.append(decoder.decode(chunk))
            if not quiet:
                sys.stderr.write(chunks[-1])
                sys.stderr.flush()
    output = "".join(chunks) + decoder.decode(b"", final=True)
    lines = [line.rsplit("\r", 1)[-1] for line in output.split("\n")]  # \r: a progress bar
    code = proc.returncode
    if code != 0:
        # hybgen's own lines say what failed (its exit codes: runtime/include/hybgen/rt/
        # exit_codes.hpp, README.md "Exit codes").
        tail = "\n".join(line for line in lines if line.strip())
        raise HybgenError(f"hybgen {command} {os.fspath(model)} exited with {code}:\n"
                          + tail[-4000:], code, output)
    for line in lines if quiet else []:
        if "warning:" in line:
            warnings.warn(line, stacklevel=3)
