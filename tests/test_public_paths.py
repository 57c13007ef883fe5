"""Every public import path written before the package was split into subpackages
(issue 22) still works: each module's ``__all__`` as it was at 734d162 (the last commit
before the split), the same objects at the old and new paths, and a few private names
that scripts and notebooks reach for. The lists are the old API, copied from that commit's
source; a name dropped from a module fails here."""

from __future__ import annotations

import importlib

import pytest

import pprender

OLD = {
    "pprender": ["BrdfTable", "Classifier", "Instrument", "Measurement", "expected_counts", "instrument", "measure",
                 "build_database", "build_database_distributed", "distributed", "classify", "database",
                 "open_database", "so3", "Error", "Lidar", "Material", "MonostaticTable", "NoMatchWarning",
                 "PileUpWarning", "OffCentreWarning", "RenderResult", "SPEED_OF_LIGHT", "Scene", "device_info",
                 "render", "__version__", "albedo", "brdf", "brdf_table", "monostatic_table", "specular",
                 "white_furnace", "models", "fit", "plot", "materials", "mesh"],
    "pprender.lidar": ["Lidar", "OffCentreWarning", "RenderResult", "Scene", "device_info", "render",
                       "SPEED_OF_LIGHT", "QUALITY", "_rotations", "_mesh_arrays"],
    "pprender.instrument": ["PLANCK", "PILE_UP_THRESHOLD", "CHANNEL_PRESETS", "Channels", "Instrument",
                            "Measurement", "PileUpWarning", "channel_set", "expected_counts", "jitter_matrix",
                            "measure", "snr"],
    "pprender.database": ["Chunk", "build_database", "create_database", "list_chunks", "open_database",
                          "pad_profile", "write_chunk"],
    "pprender.distributed": ["BuildSummary", "ChunkReport", "WorkerThroughput", "build_database_distributed",
                             "describe_workers"],
    "pprender.classify": ["Classifier", "Matches", "NoMatchWarning", "Projection", "co_cross_projection",
                          "mueller_projection", "stokes_projection"],
    "pprender.fit": ["DEFAULT_BOUNDS", "PARAMETERS", "FitResult", "ForwardModel", "attitude_error",
                     "fisher_information", "fit_nlopt", "poisson_log_likelihood", "sample_emcee"],
    "pprender.so3": ["scipy_quaternions", "angular_distance", "ball_radius", "covering_radius", "grid", "nearest",
                     "nearest_neighbour_distances", "random"],
    "pprender.materials": ["NAMES", "ALIASES", "WAVELENGTHS", "optical_constants", "diffuse_albedo",
                           "material_kwargs", "get"],
    "pprender.models": ["BUS_EXTENTS", "cone", "cubesat", "describe", "plate", "sphere"],
    "pprender.plot": ["attitude_errors", "confusion_matrix", "corner", "polarization_images", "profile",
                      "stokes_images"],
    "pprender.polarimetry": ["dop", "dolp", "docp", "diattenuation", "diattenuation_vector", "polarizance",
                             "polarizance_vector", "depolarization_index", "linear_depolarization_ratio",
                             "circular_depolarization_ratio", "lu_chipman", "retardance", "linear_retardance",
                             "optical_rotation", "retardance_vector", "cloude_eigenvalues", "is_physical"],
    "pprender.microfacet": ["wallis", "wallis_factorial", "seed_wallis", "incomplete_cos_pow",
                            "seed_incomplete_cos_pow", "seed_incomplete_cos_pow_printed", "hk_plus", "hk_plus_eq18",
                            "seed_hk_plus", "seed_hk_plus_printed", "aps_masking", "seed_aps_p", "smith_g1"],
    "pprender.reference": ["microsurface", "height_field", "ORDERS"],
    "pprender.mesh": ["MAX_EXTENT", "Assignment", "FlatMesh", "Match", "Node", "SkippedGeometryWarning",
                      "UnitsWarning", "assign_materials", "flatten"],
}

MOVED = ["instrument", "database", "distributed", "classify", "fit", "so3"]


@pytest.mark.parametrize("module", sorted(OLD))
def test_old_module_paths_and_names(module) -> None:
    m = importlib.import_module(module)
    missing = [n for n in OLD[module] if not hasattr(m, n)]
    assert not missing, f"{module} lost {missing}"


@pytest.mark.parametrize("name", MOVED)
def test_moved_modules_are_the_same_objects(name) -> None:
    new = importlib.import_module(f"pprender.inverse.{name}")
    assert importlib.import_module(f"pprender.{name}") is new
    assert getattr(pprender, name) is new
    assert getattr(pprender.inverse, name) is new
    exec(f"from pprender.{name} import *", {})  # star imports of the old path work too


def test_top_level_names_are_the_subpackages_objects() -> None:
    from pprender.inverse.classify import Classifier
    from pprender.inverse.instrument import Instrument, measure
    from pprender.lidar.dispatch import render
    from pprender.lidar.sensor import Lidar

    assert pprender.Instrument is Instrument and pprender.measure is measure
    assert pprender.Classifier is Classifier
    assert pprender.render is render and pprender.lidar.render is render
    assert pprender.Lidar is Lidar and pprender.lidar.Lidar is Lidar


def test_no_module_level_import_cycles() -> None:
    """The package's modules import each other at module level without a cycle (imports
    inside functions, the lazy ones, are left out; the old-path forwarding modules are
    leaves that point into their subpackage)."""
    import ast
    from pathlib import Path

    root = Path(pprender.__file__).parent
    graph: dict[str, set[str]] = {}
    for path in root.rglob("*.py"):
        rel = path.relative_to(root.parent).with_suffix("")
        name = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        package = name if rel.name == "__init__" else name.rpartition(".")[0]
        deps = graph.setdefault(name, set())
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.ImportFrom) and node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    deps.add(sub if (root.parent / Path(*sub.split("."))).with_suffix(".py").exists()
                             or (root.parent / Path(*sub.split("."))).is_dir() else target)
            elif isinstance(node, ast.Import):
                deps.update(a.name for a in node.names if a.name.startswith("pprender."))
    for deps in graph.values():
        deps.discard("pprender")  # the package's __init__ re-exports; its submodules never need it
    state: dict[str, int] = {}

    def visit(n: str, stack: list[str]) -> None:
        state[n] = 1
        for d in sorted(graph.get(n, ())):
            if state.get(d) == 1:
                raise AssertionError("import cycle: " + " -> ".join(stack[stack.index(d):] + [d]))
            if d not in state:
                visit(d, stack + [d])
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n, [n])
    assert len(graph) > 25
