"""The command line, ``pprender`` (or ``python -m pprender``): the main jobs without Python.

* ``pprender render MESH --material NAME [options]``: render a mesh file (anything
  ``trimesh.load`` reads: .obj, .stl, .ply, .glb, ...) at one or more attitudes and write
  PNG pictures (:mod:`pprender.plot`: Stokes and polarization images, the range profile)
  and the profiles as data: ``profile.csv`` (a header naming the units) and
  ``render.npz`` (every array of the :class:`pprender.RenderResult`).
* ``pprender database CONFIG.toml --out PATH.zarr``: build a candidate database with
  :func:`pprender.build_database` from a small TOML file whose keys are that function's
  parameter names (``pprender database --help`` shows an example).
* ``pprender info``: the version and the rendering device (:func:`pprender.device_info`).

Each option sets one parameter of the Python function it is passed to (:class:`pprender.Lidar`,
:class:`pprender.Scene`, :func:`pprender.render`, :func:`pprender.device_info`,
:func:`pprender.build_database`), under the same name with dashes, and takes its help text
and default from that function's docstring and signature (``tests/test_cli.py`` checks
that they agree). A few defaults differ on purpose (:data:`CHANGED_DEFAULTS`). Bad
arguments print one line naming the option and exit with status 2; Ctrl-C exits with 130.
"""

from __future__ import annotations

import argparse
import inspect
import re
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, NoReturn, Sequence

import numpy as np

from ._core import Error, __version__

__all__ = ["CHANGED_DEFAULTS", "Option", "database_arguments", "main", "parser"]


# --------------------------------------------------------------------------- options


@dataclass(frozen=True)
class Option:
    """A command-line option that sets one parameter of a Python function or class.

    Parameters
    ----------
    flag : str
        The option, ``"--name"``; its value is stored under ``param``.
    target : callable
        The function or class that takes the parameter (its signature gives the default).
    param : str
        The parameter's name in ``target``'s signature.
    type : callable, optional
        Converts the option's text (argparse's ``type``); None for a flag without a value.
    metavar : str, optional
        The value's name in ``--help``.
    doc : callable, optional
        Where the parameter's help text is (default ``target``): :class:`pprender.Lidar`'s
        render settings are documented in :class:`pprender.Settings`.
    """

    flag: str
    target: Callable[..., Any]
    param: str
    type: Callable[[str], Any] | None = None
    metavar: str | None = None
    doc: Callable[..., Any] | None = None


#: Options whose default differs from the Python parameter's (``"command.parameter"``), and
#: what it is instead.
CHANGED_DEFAULTS: dict[str, str] = {
    "render.progress": "a progress bar unless --no-progress",
    "render.attitudes": "the identity when none is given (the sensor looks down the body's -Z axis)",
}

_RST = [
    (re.compile(r":\w+:`~?(?:[\w.]+\.)?([\w.]+)`"), r"\1"),  # :func:`~a.b` -> b
    (re.compile(r"``([^`]*)``"), r"\1"),
    (re.compile(r"\s+"), " "),
]
_SENTENCE = re.compile(r"(?<=\.)\s+(?=[A-Z0-9\"(])")


def _param_entry(obj: Any, name: str) -> tuple[str, str]:
    """The numpydoc ``Parameters`` entry of ``name`` in ``obj``'s docstring: (type, text)."""
    doc = inspect.getdoc(obj) or ""
    m = re.search(r"^Parameters\n-+\n(.*?)(?:^\w[\w ]*\n-+\n|\Z)", doc, re.S | re.M)
    lines = (m.group(1) if m else "").splitlines()
    for i, line in enumerate(lines):
        head = re.match(r"^([*\w][\w, *]*?) : (\S.*)$", line)
        if head and name in [n.strip() for n in head.group(1).split(",")]:
            body = []
            for more in lines[i + 1:]:
                if more and not more.startswith(" "):
                    break
                body.append(more.strip())
            return head.group(2), " ".join(body).strip()
    raise LookupError(f"{getattr(obj, '__qualname__', obj)} documents no parameter {name!r}")


def _clean(text: str) -> str:
    for pattern, repl in _RST:
        text = pattern.sub(repl, text)
    return text.strip()


def _shorten(text: str, limit: int = 160) -> str:
    """``text`` cut at the last clause boundary before ``limit`` characters (with " ...")."""
    if len(text) <= limit:
        return text
    cut = max(text.rfind(sep, 0, limit) for sep in (", ", "; ", ": "))
    return (text[:cut] if cut > 20 else text[:limit]).rstrip(" ,;:") + " ..."


def _help(opt: Option, python_default: Any, cli_default: Any, command: str) -> str:
    """The option's help: the first sentence of the parameter's documentation (and its
    "Default ..." sentence when it says more than the value), then the Python parameter it
    sets and its default (and the command line's, where :data:`CHANGED_DEFAULTS` says it
    differs)."""
    _, text = _param_entry(opt.doc or opt.target, opt.param)
    sentences = _SENTENCE.split(_clean(text))
    chosen = [_shorten(sentences[0])] + [
        _shorten(s) for s in sentences[1:] if s.startswith("Default") and not re.fullmatch(r"Default \S+\.", s)][:1]
    owner = getattr(opt.target, "__qualname__", str(opt.target))
    where = f"[{owner}({opt.param}=...)"
    if python_default is not inspect.Parameter.empty:
        where += f", default {python_default!r}"
    changed = CHANGED_DEFAULTS.get(f"{command}.{opt.param}")
    if changed:
        where += f"; here {cli_default!r}: {changed}"
    return (" ".join(chosen) + " " + where + "]").replace("%", "%%")


def _choices(opt: Option) -> list[str] | None:
    """The ``{"a", "b"}`` values of the parameter's documented type, if it has them."""
    kind, _ = _param_entry(opt.doc or opt.target, opt.param)
    m = re.match(r"^\{(.*?)\}", kind)
    if not m:
        return None
    vals = [v.strip().strip("\"'") for v in m.group(1).split(",")]
    return vals if all(v and not v.lstrip("-").isdigit() for v in vals) else None


def _python_default(opt: Option) -> Any:
    """The default of ``opt.param`` in ``opt.target``'s signature (``inspect.Parameter.empty``
    if it has none)."""
    return inspect.signature(opt.target).parameters[opt.param].default


def _add(p: argparse.ArgumentParser, opt: Option, **kw: Any) -> None:
    default = kw.pop("default", _python_default(opt))
    choices = _choices(opt) if opt.type is str else None
    if opt.type is None:  # a flag
        kw.setdefault("action", argparse.BooleanOptionalAction if default is True else "store_true")
    else:
        kw.setdefault("type", opt.type)
        kw.setdefault("metavar", opt.metavar or ("{" + ",".join(choices) + "}" if choices else None))
        if choices:
            kw.setdefault("choices", choices)
    default = None if default is inspect.Parameter.empty else default
    p.add_argument(opt.flag, dest=opt.param, default=default,
                   help=kw.pop("help", _help(opt, _python_default(opt), default, p.prog.split()[-1])), **kw)


# --------------------------------------------------------------------------- value parsers


def _floats(text: str, n: int | None = None) -> list[float]:
    try:
        vals = [float(x) for x in text.replace(",", " ").split()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of numbers") from None
    if n is not None and len(vals) != n:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {n} numbers separated by commas, got {len(vals)}")
    return vals


_STATES = {"H": (1.0, 1.0, 0.0, 0.0), "V": (1.0, -1.0, 0.0, 0.0), "D": (1.0, 0.0, 1.0, 0.0),
           "A": (1.0, 0.0, -1.0, 0.0)}


def _stokes(text: str) -> tuple[float, ...]:
    if text.upper() in _STATES:
        return _STATES[text.upper()]
    return tuple(_floats(text, 4))


def _quaternion(text: str) -> list[float]:
    return _floats(text, 4)


def _euler(text: str) -> list[float]:
    return _floats(text, 3)


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"{text!r} is negative")
    return v


def _literal(text: str) -> Any:
    """A material keyword's value: a number, True/False, or the text itself."""
    if text in ("True", "False", "true", "false"):
        return text.lower() == "true"
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    return text


def _material_arg(text: str) -> tuple[str | None, str, dict[str, Any]]:
    """``[PART=]NAME[,KEY=VALUE...]`` -> (part or None, name, materials.get keywords)."""
    head, *extra = text.split(",")
    part, _, name = head.rpartition("=")
    kwargs: dict[str, Any] = {}
    for item in extra:
        k, eq, v = item.partition("=")
        if not eq or not k.strip():
            raise argparse.ArgumentTypeError(f"{text!r}: {item!r} is not KEY=VALUE")
        kwargs[k.strip()] = _literal(v.strip())
    if not name.strip():
        raise argparse.ArgumentTypeError(f"{text!r}: no material name")
    return (part.strip() or None), name.strip(), kwargs


# --------------------------------------------------------------------------- render


def _render_options() -> list[Option]:
    from .lidar import Lidar, Scene, Settings
    from .lidar.dispatch import render

    def setting(flag: str, param: str, type: Callable[[str], Any], metavar: str | None = None) -> Option:
        return Option(flag, Lidar, param, type, metavar, doc=Settings)

    return [
        Option("--wavelength", Lidar, "wavelength", float, "M"),
        Option("--pulse-fwhm", Lidar, "pulse_fwhm", float, "S"),
        Option("--bin-width", Lidar, "bin_width", float, "M"),
        Option("--polarization", Lidar, "polarization", _stokes, "S0,S1,S2,S3|H|V|D|A"),
        Option("--bistatic-angle", Lidar, "bistatic_angle", float, "RAD"),
        setting("--quality", "quality", str),
        setting("--resolution", "resolution", int, "N"),
        setting("--supersampling", "supersampling", int, "N"),
        setting("--pixel-samples", "pixel_samples", int, "K"),
        setting("--coverage", "coverage", str),
        setting("--arithmetic", "arithmetic", str),
        setting("--bounces", "bounces", int, "N"),
        setting("--path-samples", "path_samples", int, "N"),
        setting("--path-seed", "path_seed", int, "SEED"),
        Option("--smooth", Scene, "smooth"),
        Option("--device", render, "device", str),
        Option("--progress", render, "progress"),
    ]


_RENDER_EPILOG = """\
examples:
  pprender render sat.glb --material aluminium --out out/
  pprender render sat.glb --material bus=aluminium,alpha=0.15 --material cells=fused_silica \\
      --material paint=white_paint --euler 0,30,0 --euler 0,60,0 --bounces 3 --out out/
  pprender render cube.stl --material gold --polarization H --attitude-file q.csv --pictures 0

files written in --out: profile.csv (one row per attitude and range bin: the attitude's
index, the bin's centre range_m (m) and round-trip delay_s (s), then the Mueller
elements Mij_m2 or, with --polarization, the Stokes components I_m2..V_m2, cross-section
per bin in m^2), render.npz (every array of the result, and the attitudes as quaternions
w,x,y,z) and, for the first --pictures attitudes, stokes_K.png, polarization_K.png and
profile_K.png (pprender.plot; a Mueller render is shown for horizontal transmission).
"""


def _render_parser(sub: Any) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "render", help="render a mesh file to pictures and profiles",
        description="Render a mesh at one or more attitudes (pprender.Scene, pprender.Lidar, pprender.render) "
                    "and write pictures and the range profiles.",
        epilog=_RENDER_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("mesh", metavar="MESH",
                   help="a mesh file trimesh reads (.obj, .stl, .ply, .glb, ...), vertices in metres in the body "
                        "frame, its origin the rotation centre [Scene(mesh=...)]")
    p.add_argument("--material", dest="materials", action="append", type=_material_arg, required=True,
                   metavar="[PART=]NAME[,KEY=VALUE...]",
                   help="a material name of pprender.materials (aluminium, gold, silver, copper, titanium, "
                        "fused_silica, kapton, white_paint, black_paint) for the whole mesh, or PART=NAME for a "
                        "part (a node, geometry or material name of the file); KEY=VALUE pairs are keywords of "
                        "pprender.materials.get (alpha=0.15, distribution=ggx). Repeat for several parts "
                        "[Scene(materials=...)]")
    att = p.add_mutually_exclusive_group()
    att.add_argument("--attitude", dest="attitudes", action="append", type=_quaternion, metavar="W,X,Y,Z",
                     help="a unit quaternion (scalar first) rotating the body into the telescope frame; repeat for "
                          f"more [render(attitudes=...); here: {CHANGED_DEFAULTS['render.attitudes']}]")
    att.add_argument("--euler", action="append", type=_euler, metavar="A,B,C",
                     help="an attitude as three Euler angles in degrees, in the order of --euler-seq; repeat for "
                          "more")
    att.add_argument("--attitude-file", metavar="PATH",
                     help="attitudes from a file: .npy of shape (N, 4), or text with four numbers w,x,y,z a line "
                          "(commas or spaces; lines starting with # are skipped)")
    p.add_argument("--euler-seq", default="xyz", metavar="SEQ",
                   help="axes of --euler for scipy.spatial.transform.Rotation.from_euler: lower case about the "
                        "fixed telescope axes, upper case about the body's (default: xyz)")
    for opt in _render_options():
        _add(p, opt, **({"default": True} if opt.param == "progress" else {}))
    p.add_argument("--pictures", type=_positive_int, default=4, metavar="N",
                   help="write pictures of the first N attitudes (default 4); 0 renders the profiles alone (no "
                        "images, less memory)")
    p.add_argument("--out", default="out", metavar="DIR", help="the directory the files go to (default: out)")
    p.set_defaults(run=_run_render, command_parser=p)
    return p


def _load_mesh(path: str) -> Any:
    import trimesh

    if not Path(path).is_file():
        raise Error(f"invalid MESH {path!r}: no such file")
    try:
        return trimesh.load(path)
    except (ValueError, KeyError, OSError) as e:
        raise Error(f"invalid MESH {path!r}: trimesh cannot read it ({e})") from None


def _materials(specs: Sequence[tuple[str | None, str, dict[str, Any]]], wavelength: float) -> Any:
    from . import materials

    whole = [s for s in specs if s[0] is None]
    if whole and len(specs) > 1:
        raise Error("invalid materials: give one --material NAME for the whole mesh, or PART=NAME for each part, "
                    "not both")

    def get(name: str, kwargs: dict[str, Any]) -> Any:
        try:
            return materials.get(name, wavelength=wavelength, **kwargs)
        except (TypeError, Error) as e:
            if "invalid wavelength" in str(e):  # the --wavelength's fault, not the material's
                raise
            raise Error(f"invalid materials ({name}): {e}") from None

    if whole:
        return get(whole[0][1], whole[0][2])
    out: dict[str, Any] = {}
    for part, name, kwargs in specs:
        assert part is not None
        if part in out:
            raise Error(f"invalid materials: part {part!r} given twice")
        out[part] = get(name, kwargs)
    return out


def _attitudes(args: argparse.Namespace) -> np.ndarray:
    """(N, 4) quaternions (w, x, y, z) from --attitude, --euler or --attitude-file."""
    if args.euler:
        from scipy.spatial.transform import Rotation

        try:
            xyzw = Rotation.from_euler(args.euler_seq, np.array(args.euler), degrees=True).as_quat()
        except ValueError as e:
            raise Error(f"invalid euler_seq = {args.euler_seq!r}: {e}") from None
        return np.ascontiguousarray(np.roll(xyzw.reshape(-1, 4), 1, axis=1))
    if args.attitude_file:
        path = Path(args.attitude_file)
        if not path.is_file():
            raise Error(f"invalid attitude_file {str(path)!r}: no such file")
        try:
            if path.suffix == ".npy":
                q = np.load(path)
            else:
                text = path.read_text()
                q = np.loadtxt(path, delimiter="," if "," in text else None, comments="#", ndmin=2)
        except ValueError as e:
            raise Error(f"invalid attitude_file {str(path)!r}: {e}") from None
        q = np.asarray(q, dtype=np.float64)
        if q.ndim != 2 or q.shape[1] != 4 or len(q) == 0:
            raise Error(f"invalid attitude_file {str(path)!r}: shape {q.shape}, expected (N, 4) quaternions w,x,y,z")
        return q
    if args.attitudes:
        return np.array(args.attitudes, dtype=np.float64)
    return np.array([[1.0, 0.0, 0.0, 0.0]])


def _csv(path: Path, res: Any, mueller: bool) -> None:
    p = res.profile  # (N, B, 4, 4) or (N, B, 4)
    n, b = p.shape[:2]
    cols = [f"M{i}{j}_m2" for i in range(4) for j in range(4)] if mueller else [f"{s}_m2" for s in "IQUV"]
    table = np.column_stack([
        np.repeat(np.arange(n), b).astype(np.float64),
        np.tile(res.range_axis, n),
        np.tile(res.time_axis, n),
        p.reshape(n * b, -1),
    ])
    fmt = ["%d"] + ["%.17g"] * (table.shape[1] - 1)
    np.savetxt(path, table, delimiter=",", fmt=fmt, header=",".join(["attitude", "range_m", "delay_s"] + cols),
               comments="")


def _npz(path: Path, res: Any, q: np.ndarray) -> None:
    arrays: dict[str, Any] = {"attitudes": q, "range_axis": res.range_axis, "time_axis": res.time_axis}
    for name in ("cross_section", "bin_edges", "profile", "mueller", "stokes", "range", "coverage"):
        v = getattr(res, name)
        if v is not None:
            arrays[name] = v
    for name, v in (res.by_bounce or {}).items():
        arrays[f"by_bounce_{name}"] = v
    for name in ("pixel_size", "extent", "wavelength"):
        arrays[name] = np.float64(getattr(res, name))
    arrays["device"] = np.str_(res.device)
    np.savez_compressed(path, **arrays)


def _run_render(args: argparse.Namespace) -> int:
    import pprender

    sensor_kw = {o.param: getattr(args, o.param) for o in _render_options() if o.target is pprender.Lidar}
    sensor = pprender.Lidar(**sensor_kw)
    mesh = _load_mesh(args.mesh)
    scene = pprender.Scene(mesh, _materials(args.materials, sensor.wavelength), smooth=args.smooth,
                           wavelength=sensor.wavelength)
    q = _attitudes(args)
    image = "mueller" if sensor.polarization is None else "stokes"
    outputs = ("profile", image, "range") if args.pictures > 0 else ("profile",)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    res = pprender.render(scene, sensor, q, outputs=outputs, device=args.device, progress=args.progress)
    seconds = time.perf_counter() - t0
    written = [out / "profile.csv", out / "render.npz"]
    _csv(written[0], res, image == "mueller")
    _npz(written[1], res, q)
    if args.pictures > 0:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from . import plot

        for k in range(min(args.pictures, len(q))):
            for name, fig in (("stokes", plot.stokes_images(res, k)), ("polarization", plot.polarization_images(res, k)),
                              ("profile", plot.profile(res, index=k))):
                fig.savefig(out / f"{name}_{k}.png", dpi=80)
                plt.close(fig)
                written.append(out / f"{name}_{k}.png")
    sigma = res.cross_section[:, 0, 0] if res.cross_section.ndim == 3 else res.cross_section[:, 0]
    print(f"rendered {len(q)} attitude(s) of {args.mesh} ({scene.n_faces} faces) in {seconds:.2f} s on {res.device}")
    print("cross-section (m^2, unpolarized): " + ", ".join(f"{s:.4g}" for s in sigma[:8])
          + (" ..." if len(sigma) > 8 else ""))
    for f in written:
        print(f)
    return 0


# --------------------------------------------------------------------------- database


def _database_options() -> list[Option]:
    from .inverse.database import build_database

    return [
        Option("--out", build_database, "path", str, "PATH.zarr"),
        Option("--overwrite", build_database, "overwrite"),
        Option("--progress", build_database, "progress"),
    ]


def _config_keys() -> list[str]:
    """The keys of a database config: :func:`pprender.build_database`'s parameters that
    describe the database (how to run the build is the command line's: --out, --overwrite,
    --progress; ``render`` is a Python callable)."""
    from .inverse.database import build_database

    skip = {"render", "overwrite", "progress"}
    return [n for n in inspect.signature(build_database).parameters if n not in skip]


_DATABASE_EPILOG = """\
The config is TOML; its keys are pprender.build_database's parameters (paths are relative
to the config's directory):

  path = "cubes.zarr"            # optional: --out replaces it
  chunk_attitudes = 64           # optional, like range_window, dtype, attitude_grid
  attitudes = { grid = 200 }     # pprender.so3.grid(200); or { random = 200, seed = 1 },
                                 # { file = "q.npy" }, or [[1, 0, 0, 0], [w, x, y, z], ...]
  [shapes]                       # name = a mesh file, or a table naming a pprender.models
  box = "box.stl"                #   function and its keywords
  sat = { model = "cubesat", units = "3U" }
  [materials]                    # name = a material name, a table with "name" and keywords
  al = "aluminium"               #   of pprender.materials.get, or a table part = material
  rough = { name = "aluminium", alpha = 0.3 }
  [sensor]                       # keywords of pprender.Lidar
  resolution = 32
  quality = "fast"
"""


def _database_parser(sub: Any) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "database", help="build a candidate database from a TOML config",
        description="Build a candidate database (pprender.build_database): every shape x material x attitude's "
                    "range profiles in a Zarr store. An interrupted build resumes where it stopped.",
        epilog=_DATABASE_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("config", metavar="CONFIG.toml", help="the database's description (below)")
    for opt in _database_options():
        _add(p, opt, **({"help": "the Zarr store's directory; default: the config's path "
                                 "[build_database(path=...)]"} if opt.param == "path" else {}))
    p.set_defaults(run=_run_database, command_parser=p)
    return p


def _read_toml(path: Path) -> dict[str, Any]:
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover - the databases need Python 3.11 (zarr 3)
        try:
            import tomli as tomllib
        except ImportError:
            raise Error("invalid config: reading TOML needs Python 3.11+ or the tomli package") from None
    if not path.is_file():
        raise Error(f"invalid config {str(path)!r}: no such file")
    try:
        with open(path, "rb") as f:
            return dict(tomllib.load(f))
    except tomllib.TOMLDecodeError as e:
        raise Error(f"invalid config {str(path)!r}: not TOML ({e})") from None


def _shape(name: str, value: Any, here: Path) -> Any:
    from . import models

    if isinstance(value, str):
        return _load_mesh(str(here / value))
    if isinstance(value, Mapping) and isinstance(value.get("model"), str):
        kw = {k: v for k, v in value.items() if k != "model"}
        fn = getattr(models, value["model"], None)
        if value["model"] not in models.__all__ or not callable(fn) or value["model"] in ("describe",):
            raise Error(f"invalid shapes.{name}: model {value['model']!r} is not a pprender.models function "
                        "(cubesat, sphere, plate, cone)")
        try:
            return fn(**kw)
        except TypeError as e:
            raise Error(f"invalid shapes.{name}: {e}") from None
    raise Error(f"invalid shapes.{name} = {value!r}: a mesh file name or a table {{ model = \"cubesat\", ... }}")


def _material_entry(where: str, value: Any, wavelength: float) -> Any:
    from . import materials

    if isinstance(value, str):
        return value
    if isinstance(value, Mapping) and "name" in value:
        kw = {k: v for k, v in value.items() if k != "name"}
        try:
            return materials.get(value["name"], wavelength=wavelength, **kw)
        except TypeError as e:
            raise Error(f"invalid {where}: {e}") from None
    raise Error(f"invalid {where} = {value!r}: a material name or a table {{ name = \"aluminium\", alpha = 0.3 }}")


def _config_attitudes(value: Any, here: Path) -> tuple[Any, Any]:
    """(attitudes, attitude_grid description or None)."""
    from .inverse import so3

    if isinstance(value, Mapping):
        if set(value) == {"grid"}:
            return so3.grid(value["grid"]), {"method": "so3.grid", "n": value["grid"]}
        if "random" in value and set(value) <= {"random", "seed"}:
            return (so3.random(value["random"], value.get("seed")),
                    {"method": "so3.random", "n": value["random"], "seed": value.get("seed")})
        if set(value) == {"file"}:
            path = here / str(value["file"])
            if not path.is_file():
                raise Error(f"invalid attitudes.file {str(path)!r}: no such file")
            q = np.load(path) if path.suffix == ".npy" else np.loadtxt(path, delimiter=",", comments="#", ndmin=2)
            return q, {"file": str(value["file"])}
        raise Error(f"invalid attitudes = {value!r}: {{ grid = N }}, {{ random = N, seed = S }}, {{ file = \"q.npy\" }} "
                    "or a list of quaternions [w, x, y, z]")
    return value, None


def database_arguments(config: str | Path) -> dict[str, Any]:
    """The keyword arguments of :func:`pprender.build_database` that a TOML config describes.

    Parameters
    ----------
    config : str or pathlib.Path
        The TOML file (``pprender database --help`` shows the format); its keys are
        ``build_database``'s parameters but ``render``, ``overwrite`` and ``progress``.

    Returns
    -------
    dict
        ``path`` (absent unless the config gives it), ``shapes``, ``materials``,
        ``attitudes``, ``sensor`` (a :class:`pprender.Lidar`) and the other keys given.

    Raises
    ------
    pprender.Error
        For a file that is missing or not TOML, an unknown key (naming it and the allowed
        ones), a missing required key, or an invalid value (naming its key).
    """
    from . import Lidar

    path = Path(config)
    cfg = _read_toml(path)
    here = path.parent
    allowed = _config_keys()
    unknown = [k for k in cfg if k not in allowed]
    if unknown:
        raise Error(f"invalid config key(s) {unknown} in {str(path)!r}: the keys are pprender.build_database's "
                    f"parameters {allowed}")
    missing = [k for k in ("shapes", "materials", "attitudes", "sensor") if k not in cfg]
    if missing:
        raise Error(f"invalid config {str(path)!r}: missing {missing}")
    for k in ("shapes", "materials", "sensor"):
        if not isinstance(cfg[k], Mapping):
            raise Error(f"invalid {k} in {str(path)!r}: a table [{k}]")
    try:
        sensor = Lidar(**cfg["sensor"])
    except TypeError as e:
        raise Error(f"invalid sensor in {str(path)!r}: {e}") from None
    except Error as e:
        raise Error(f"invalid sensor in {str(path)!r}: {e}") from None
    kw: dict[str, Any] = {k: v for k, v in cfg.items() if k not in ("shapes", "materials", "attitudes", "sensor")}
    if "path" in kw:
        kw["path"] = here / str(kw["path"])
    kw["sensor"] = sensor
    kw["shapes"] = {str(n): _shape(str(n), v, here) for n, v in cfg["shapes"].items()}
    mats: dict[str, Any] = {}
    for name, v in cfg["materials"].items():
        if isinstance(v, Mapping) and "name" not in v:
            mats[name] = {str(part): _material_entry(f"materials.{name}.{part}", pv, sensor.wavelength)
                          for part, pv in v.items()}
        else:
            mats[name] = _material_entry(f"materials.{name}", v, sensor.wavelength)
    kw["materials"] = mats
    kw["attitudes"], grid = _config_attitudes(cfg["attitudes"], here)
    if grid is not None and "attitude_grid" not in kw:
        kw["attitude_grid"] = grid
    return kw


def _run_database(args: argparse.Namespace) -> int:
    from .inverse.database import build_database

    kw = database_arguments(args.config)
    if args.path is not None:
        kw["path"] = Path(args.path)
    if "path" not in kw:
        raise Error("invalid path: give --out PATH.zarr (or path = \"...\" in the config)")
    t0 = time.perf_counter()
    ds = build_database(overwrite=args.overwrite, progress=args.progress, **kw)
    dims = ", ".join(f"{k} {v}" for k, v in ds.sizes.items())
    print(f"{kw['path']}: {dims} ({time.perf_counter() - t0:.1f} s)")
    return 0


# --------------------------------------------------------------------------- info


def _info_parser(sub: Any) -> argparse.ArgumentParser:
    from . import device_info

    p = sub.add_parser("info", help="print the version and the rendering device",
                       description="Print pprender's version and the device that renders (pprender.device_info).")
    _add(p, Option("--device", device_info, "device", str))
    p.set_defaults(run=_run_info, command_parser=p)
    return p


def _run_info(args: argparse.Namespace) -> int:
    import platform

    import pprender

    print(f"pprender {__version__} (Python {platform.python_version()}, numpy {np.__version__})")
    for k, v in pprender.device_info(args.device).items():
        print(f"{k}: {v}")
    print(f"cache_dir: {pprender.cache_dir()}")
    return 0


# --------------------------------------------------------------------------- main


class _Parser(argparse.ArgumentParser):
    """argparse, raising instead of exiting (``main`` turns it into a status)."""

    def exit(self, status: int = 0, message: str | None = None) -> NoReturn:
        if message:
            sys.stderr.write(message)
        raise _Exit(status)


class _Exit(Exception):
    def __init__(self, status: int) -> None:
        super().__init__(status)
        self.status = status


def parser() -> argparse.ArgumentParser:
    """The ``pprender`` argument parser, with its subcommands ``render``, ``database`` and ``info``.

    Returns
    -------
    argparse.ArgumentParser
        The parser (``parser().parse_args([...])``); :func:`main` runs what it parses.
    """
    p = _Parser(prog="pprender", description="Pulse Polarization Ranging renders from the command line. "
                                             "'pprender COMMAND --help' describes each command.")
    p.add_argument("--version", action="version", version=f"pprender {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser, required=True)
    _render_parser(sub)
    _database_parser(sub)
    _info_parser(sub)
    return p


def _name_option(message: str, flags: Mapping[str, str]) -> str:
    """Prefix a pprender.Error message with the option it is about (``argument --resolution:``):
    that of the parameter name it names first (``flags``: parameter name -> option, or the
    metavar of a positional argument, which the message then names already)."""
    found = [(m.start(), -len(dest), dest) for dest in flags
             for m in [re.search(rf"\b{re.escape(dest)}\b", message)] if m]
    if found:
        flag = flags[min(found)[2]]
        if flag.startswith("-"):
            return f"argument {flag}: {message}"
    return message


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line ``pprender`` with ``argv`` (default ``sys.argv[1:]``).

    Parameters
    ----------
    argv : sequence of str, optional
        The arguments, without the program name.

    Returns
    -------
    int
        The exit status: 0 on success (``--help`` too), 2 for bad arguments (one line on
        stderr naming the option, no traceback), 130 after Ctrl-C.
    """
    p = parser()
    try:
        args = p.parse_args(argv)
    except _Exit as e:
        return e.status
    command: argparse.ArgumentParser = args.command_parser
    prog = command.prog
    # each parameter name -> its option (--material for "materials"), the longest names
    # first ("path_samples" before "path")
    flags = {a.dest: (a.option_strings[0] if a.option_strings else str(a.metavar))
             for a in command._actions if a.dest != "help"}

    def warn(message: Any, category: Any, filename: str, lineno: int, file: Any = None, line: Any = None) -> None:
        print(f"{prog}: warning: {message}", file=sys.stderr)

    with warnings.catch_warnings():
        warnings.showwarning = warn
        try:
            status: int = args.run(args)
            return status
        except Error as e:
            print(f"{prog}: error: {_name_option(str(e), flags)}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print(f"{prog}: interrupted", file=sys.stderr)
            return 130
