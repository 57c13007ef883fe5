"""The command line (``pprender``, ``python -m pprender``; issue 25): ``--help`` states the
Python API it calls (each option names its Python parameter, whose signature has the same
default), ``render`` writes pictures and a profile equal to ``pprender.render``'s,
``database`` builds the database ``pprender.build_database`` builds from the same
arguments, and bad arguments give one line naming the option and status 2."""

from __future__ import annotations

import inspect
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

import pprender
from pprender import cli

# The Python objects the options' help may name, by the name it uses.
OWNERS = {"Lidar": pprender.Lidar, "Scene": pprender.Scene, "render": pprender.render,
          "device_info": pprender.device_info, "build_database": pprender.build_database}
# Options that set no single Python parameter (where files go, how attitudes are spelled).
CLI_ONLY = {"render": {"euler", "euler_seq", "attitude_file", "out", "pictures"}, "database": {"config"},
            "info": set()}


def _subparsers() -> dict[str, object]:
    p = cli.parser()
    sub = next(a for a in p._actions if a.__class__.__name__ == "_SubParsersAction")
    return dict(sub.choices)  # type: ignore[attr-defined]


@pytest.mark.parametrize("command", ["render", "database", "info"])
def test_every_option_is_a_python_parameter_with_the_same_default(command) -> None:
    """Each option's help names ``Owner(param=...)``; ``param`` is in that object's
    signature (inspect.signature) with the option's default, except the defaults the command
    line changes on purpose (``cli.CHANGED_DEFAULTS``, which the help then states); a
    parameter without a Python default is required, or its default comes from elsewhere
    (the identity attitude, the config's path). Choices are those the docstring lists, and
    each is accepted by the Python object."""
    sub = _subparsers()[command]
    checked = 0
    for action in sub._actions:  # type: ignore[attr-defined]
        if action.dest in ("help", "command_parser") or action.dest in CLI_ONLY[command]:
            continue
        m = re.search(r"\[(?:pprender\.)?(\w+)\((\w+)=\.\.\.\)", action.help or "")
        assert m, f"{action.option_strings or action.dest}: the help names no Python parameter: {action.help!r}"
        owner, param = OWNERS[m.group(1)], m.group(2)
        assert param == action.dest
        params = inspect.signature(owner).parameters
        assert param in params, f"{m.group(1)} has no parameter {param}"
        default = params[param].default
        changed = cli.CHANGED_DEFAULTS.get(f"{command}.{param}")
        if changed:
            assert action.default != default and changed in " ".join(action.help.split())
        elif default is inspect.Parameter.empty:
            assert action.required or action.default in (None,) or param in ("mesh", "attitudes"), param
        else:
            assert action.default == default, (param, action.default, default)
            assert f"default {default!r}" in action.help
        for choice in action.choices or []:
            if owner is pprender.Lidar:
                pprender.Lidar(**{param: choice})  # accepted (else pprender.Error)
        checked += 1
    assert checked >= {"render": 18, "database": 3, "info": 1}[command]


def test_help_exits_0_in_process_and_from_python_m(capsys) -> None:
    for argv in (["--help"], ["render", "--help"], ["database", "--help"], ["info", "--help"]):
        assert cli.main(argv) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "--resolution N" in out and "[Lidar(resolution=...), default None]" in out
    assert "Image side in pixels" in out  # from Settings' docstring
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in [str(Path(pprender.__file__).parents[1]),
                                                                   os.environ.get("PYTHONPATH", "")] if p))
    r = subprocess.run([sys.executable, "-m", "pprender", "render", "--help"], capture_output=True, text=True,
                       env=env, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("usage: pprender render") and "--material" in r.stdout


def test_info_prints_the_version_and_the_device(capsys) -> None:
    assert cli.main(["info"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"pprender {pprender.__version__} ")
    assert f"name: {pprender.device_info()['name']}" in out
    assert cli.main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"pprender {pprender.__version__}"


@pytest.fixture(scope="module")
def box(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("mesh") / "box.obj"
    trimesh.creation.box((0.3, 0.2, 0.1)).export(path)
    return path


EULER = [[10.0, 20.0, 0.0], [0.0, 40.0, 5.0]]


@pytest.fixture(scope="module")
def reference(box):
    """pprender.render of the box, aluminium alpha 0.2, at 24 px and the attitudes EULER
    (given as a scipy Rotation)."""
    rot = Rotation.from_euler("xyz", EULER, degrees=True)
    scene = pprender.Scene(trimesh.load(box), pprender.materials.get("aluminium", alpha=0.2))
    return rot, pprender.render(scene, pprender.Lidar(resolution=24), rot, outputs=("profile", "mueller", "range"))


def _euler_args() -> list[str]:
    return [a for e in EULER for a in ("--euler", ",".join(map(str, e)))]


def test_render_writes_pictures_and_the_profile_of_pprender_render(box, reference, tmp_path, capsys) -> None:
    """Two attitudes as Euler angles; the .npz and the CSV hold pprender.render's profile for
    the same mesh, material and attitudes: the CSV to 17 significant digits, its range column
    the bin centres and its delay 2 r / c."""
    out = tmp_path / "out"
    assert cli.main(["render", str(box), "--material", "aluminium,alpha=0.2", "--resolution", "24", "--pictures",
                     "1", "--out", str(out)] + _euler_args()) == 0
    captured = capsys.readouterr()
    assert "2/2" in captured.err  # the progress bar, on by default
    for name in ("stokes_0.png", "polarization_0.png", "profile_0.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    assert not (out / "stokes_1.png").exists()

    rot, ref = reference
    saved = np.load(out / "render.npz")
    tol = 1e-12 * np.abs(ref.profile).max()
    np.testing.assert_allclose(saved["profile"], ref.profile, rtol=0, atol=tol)
    np.testing.assert_allclose(saved["mueller"], ref.mueller, rtol=0, atol=1e-12 * np.abs(ref.mueller).max())
    np.testing.assert_array_equal(saved["bin_edges"], ref.bin_edges)
    q = saved["attitudes"]  # (w, x, y, z), the same rotations as scipy's (up to sign)
    assert np.allclose(np.abs(np.sum(q[:, [1, 2, 3, 0]] * rot.as_quat(), axis=1)), 1.0, atol=1e-12)

    header = (out / "profile.csv").read_text().splitlines()[0].split(",")
    assert header[:4] == ["attitude", "range_m", "delay_s", "M00_m2"] and header[-1] == "M33_m2"
    table = np.loadtxt(out / "profile.csv", delimiter=",", skiprows=1)
    b = len(ref.bin_edges) - 1
    assert table.shape == (2 * b, 3 + 16)
    np.testing.assert_array_equal(table[:, 0], np.repeat([0, 1], b))
    centres = 0.5 * (ref.bin_edges[1:] + ref.bin_edges[:-1])
    np.testing.assert_allclose(table[:b, 1], centres, rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(table[:b, 2], 2 * centres / 299_792_458.0, rtol=1e-15, atol=1e-24)
    np.testing.assert_allclose(table[:, 3:].reshape(2, b, 4, 4), ref.profile, rtol=0, atol=tol)


def test_render_with_a_transmitted_polarization_saves_stokes_profiles(box, reference, tmp_path) -> None:
    """--polarization H: Stokes profiles, which are the Mueller profiles applied to
    (1, 1, 0, 0) (the kernel applies it in f32: within 1e-5 of the peak)."""
    out = tmp_path / "o"
    assert cli.main(["render", str(box), "--material", "aluminium,alpha=0.2", "--polarization", "H", "--resolution",
                     "24", "--pictures", "0", "--no-progress", "--out", str(out)] + _euler_args()) == 0
    _, ref = reference
    header = (out / "profile.csv").read_text().splitlines()[0]
    assert header == "attitude,range_m,delay_s,I_m2,Q_m2,U_m2,V_m2"
    table = np.loadtxt(out / "profile.csv", delimiter=",", skiprows=1)
    expected = ref.profile @ np.array([1.0, 1.0, 0.0, 0.0])
    np.testing.assert_allclose(table[:, 3:].reshape(expected.shape), expected, rtol=0,
                               atol=1e-5 * np.abs(expected).max())
    assert not list(out.glob("*.png")) and "stokes" not in np.load(out / "render.npz")


@pytest.mark.parametrize("args, option", [
    (["--resolution", "0"], "--resolution"),
    (["--bounces", "4"], "--bounces"),
    (["--quality", "slow"], "--quality"),
    (["--attitude", "1,0,0"], "--attitude"),
    (["--attitude", "2,0,0,0"], "--attitude"),
    (["--polarization", "1,2,0,0"], "--polarization"),
    (["--wavelength", "9e-7"], "--wavelength"),
    (["--material", "unobtainium"], "--material"),
])
def test_bad_arguments_give_one_line_naming_the_option_and_status_2(box, tmp_path, capsys, args, option) -> None:
    argv = ["render", str(box), "--no-progress", "--pictures", "0", "--out", str(tmp_path)]
    if "--material" not in args:
        argv += ["--material", "aluminium"]
    assert cli.main(argv + args) == 2
    err = capsys.readouterr().err
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"pprender render: error: argument {option}: ") and "Traceback" not in err
    assert not (tmp_path / "profile.csv").exists()


def test_a_missing_mesh_and_ctrl_c(tmp_path, capsys, monkeypatch, box) -> None:
    """A mesh file that is not there: status 2 naming it. Ctrl-C during the render
    (KeyboardInterrupt): status 130 and one line."""
    assert cli.main(["render", str(tmp_path / "nope.stl"), "--material", "gold"]) == 2
    assert "invalid MESH" in capsys.readouterr().err

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(pprender, "render", interrupted)
    assert cli.main(["render", str(box), "--material", "gold", "--out", str(tmp_path)]) == 130
    assert capsys.readouterr().err.strip() == "pprender render: interrupted"


CONFIG = """\
chunk_attitudes = 2
attitudes = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]]

[shapes]
box = "box.obj"
sphere = {{ model = "sphere", radius = 0.1, subdivisions = 1 }}

[materials]
al = "aluminium"

[sensor]
resolution = 16
quality = "fast"
{extra}"""


def test_database_from_a_config_equals_build_database(box, tmp_path, capsys) -> None:
    """The config's keys are build_database's parameters: the store equals the one
    build_database writes from the same arguments, given directly."""
    (tmp_path / "box.obj").write_bytes(box.read_bytes())
    (tmp_path / "db.toml").write_text(CONFIG.format(extra=""))
    assert cli.main(["database", str(tmp_path / "db.toml"), "--out", str(tmp_path / "cli.zarr"),
                     "--no-progress"]) == 0
    assert "cli.zarr" in capsys.readouterr().out
    q = np.eye(4)[:2]
    direct = pprender.build_database(
        tmp_path / "direct.zarr",
        {"box": trimesh.load(box), "sphere": pprender.models.sphere(radius=0.1, subdivisions=1)},
        {"al": "aluminium"}, q, pprender.Lidar(resolution=16, quality="fast"), chunk_attitudes=2, progress=False)
    ds = pprender.open_database(tmp_path / "cli.zarr")
    assert list(ds["shape"].values) == ["box", "sphere"] and list(ds["material"].values) == ["al"]
    np.testing.assert_array_equal(ds["profile"].values, direct["profile"].values)
    np.testing.assert_array_equal(ds["quaternion"].values, q)


def test_database_config_materials_and_attitude_grids(tmp_path) -> None:
    """A material as a table (materials.get's keywords) or per part; attitudes as
    ``{ grid = N }`` (so3.grid, recorded as the attitude_grid) or ``{ random = N, seed = S }``;
    the path relative to the config."""
    (tmp_path / "c.toml").write_text("""\
path = "db.zarr"
attitudes = { grid = 5 }
[shapes]
ball = { model = "sphere", radius = 0.2, subdivisions = 1 }
[materials]
rough = { name = "gold", alpha = 0.3 }
parts = { bus = "aluminium", solar_cells = { name = "fused_silica", alpha = 0.05 }, panel_back = "white_paint" }
[sensor]
wavelength = 532e-9
""")
    kw = cli.database_arguments(tmp_path / "c.toml")
    assert kw["path"] == tmp_path / "db.zarr" and kw["sensor"] == pprender.Lidar(wavelength=532e-9)
    np.testing.assert_array_equal(kw["attitudes"], pprender.so3.grid(5))
    assert kw["attitude_grid"] == {"method": "so3.grid", "n": 5}
    rough = kw["materials"]["rough"]
    assert (rough.name, rough.alpha, rough.wavelength) == ("gold", 0.3, 532e-9)
    assert rough.eta == pprender.materials.optical_constants("gold", 532e-9)
    parts = kw["materials"]["parts"]
    assert parts["bus"] == "aluminium" and parts["panel_back"] == "white_paint"
    assert (parts["solar_cells"].name, parts["solar_cells"].alpha) == ("fused_silica", 0.05)
    (tmp_path / "r.toml").write_text('attitudes = { random = 4, seed = 7 }\n[shapes]\nball = { model = "sphere" }\n'
                                     '[materials]\nal = "aluminium"\n[sensor]\n')
    np.testing.assert_array_equal(cli.database_arguments(tmp_path / "r.toml")["attitudes"],
                                  pprender.so3.random(4, 7))


def test_database_config_errors_name_the_key(tmp_path, capsys) -> None:
    (tmp_path / "box.obj").write_text("")
    (tmp_path / "bad.toml").write_text("chunk = 3\n" + CONFIG.format(extra=""))
    assert cli.main(["database", str(tmp_path / "bad.toml"), "--out", str(tmp_path / "x.zarr")]) == 2
    err = capsys.readouterr().err.strip()
    allowed = [n for n in inspect.signature(pprender.build_database).parameters
               if n not in ("render", "overwrite", "progress")]
    assert err.startswith("pprender database: error: invalid config key(s) ['chunk']") and str(allowed) in err
    (tmp_path / "res.toml").write_text(CONFIG.format(extra="").replace("resolution = 16", "resolution = 0"))
    assert cli.main(["database", str(tmp_path / "res.toml"), "--out", str(tmp_path / "x.zarr")]) == 2
    assert "invalid resolution = 0" in capsys.readouterr().err
    assert not (tmp_path / "x.zarr").exists()
