"""Loading meshes for :class:`pprender.Scene`: flattening, parts and material assignment.

What pprender takes (every route below):

* **Units: metres.** Vertices are used as given. A satellite is 0.1 m to ~50 m across, so
  a mesh more than :data:`MAX_EXTENT` (50 m) across, or one whose trimesh ``units`` are
  not metres (e.g. ``"mm"``, which many CAD exports are), gives a :class:`UnitsWarning`
  (it is not refused): scale it first, ``mesh.apply_scale(1e-3)`` for millimetres, or
  ``mesh.convert_units("meters")`` when trimesh knows its units.
* **Axes: the body frame, as given, no axis conversion.** pprender's attitudes rotate the
  body into the telescope frame, ``p_tel = R p_body`` (:mod:`pprender.lidar`'s module
  docstring): the identity attitude looks down the body's ``-Z`` axis from ``+Z`` (the
  receiver is along telescope ``+Z``), with body ``+Y`` up in the images. glTF (``.glb``,
  ``.gltf``) is Y-up by specification and trimesh loads it as it is, so a model whose
  designer's "up" (``+Z`` in the CAD tool) was exported as glTF's ``+Y`` has that axis at
  body ``+Y`` here. To have it at body ``+Z``, rotate the model before building the Scene,
  e.g. ``mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))``
  (a right-handed rotation by +90 deg about ``x`` takes ``+Y`` to ``+Z``, and ``+Z`` to
  ``-Y``); or keep the mesh as loaded and fold that rotation ``R_fix`` (file -> intended
  body axes, the 3x3 block above) into the attitudes, ``R = R_wanted @ R_fix``.
* **The origin** of the body frame is the range reference and the centre of the images
  (their half-width is the bounding-sphere radius about it), so a CAD model whose origin
  is far from the satellite should be re-centred too (``mesh.apply_translation(...)``).

Meshes (:func:`flatten`):

* ``trimesh.Trimesh``: vertices and faces as they are. Its parts, when present, are
  ``metadata["pprender_parts"]`` with ``metadata["pprender_material"]`` each face's
  index into them (:mod:`pprender.models` sets both).
* ``trimesh.Scene`` (what ``trimesh.load("sat.glb")`` gives for a CAD export): every node
  of ``scene.graph.nodes_geometry``, in that order, is one *part*: its geometry
  (``scene.graph.get(node)`` -> (transform, geometry name)) moved by the node's transform
  (vertices; vertex normals by the inverse transpose; a mirroring transform also reverses
  the winding so faces stay outward). A geometry instanced by several nodes is so several
  parts, each with its own material. The flattened faces are the nodes' faces one node
  after the other in this order, each node's in its geometry's order; :attr:`FlatMesh.face_part`
  is each face's node index into :attr:`FlatMesh.parts` (the node names). Geometries that
  are not triangle meshes (``Path3D`` lines, ``PointCloud``) or have no faces are
  skipped with a :class:`SkippedGeometryWarning` (CAD exports often carry edges or
  construction points; they have no area to reflect).
* ``(vertices, faces)``: (V, 3) floats (m) and (F, 3) integer indices.

Materials (:class:`pprender.Scene`'s ``materials``):

* one material (a :class:`pprender.Material` or a name from :mod:`pprender.materials`)
  for the whole mesh;
* a list, indexed by ``face_material``; without ``face_material``, by the mesh's per-face
  part index (:attr:`FlatMesh.face_part`: a model's parts, or a trimesh.Scene's nodes in
  ``scene.graph.nodes_geometry`` order, so the list then has one material per node in that
  order), or all faces the first material for a mesh without parts;
* a mapping from name to material. For a model mesh the names are its parts (all of them,
  no others). For a ``trimesh.Scene`` a key may be a **node name** (one instance), a
  **geometry name** (every node instancing that geometry, a key of ``scene.geometry``) or a
  **material name** (``geometry.visual.material.name``, every node whose geometry has that
  material, as a glTF file names its materials). Each node takes the most specific key that
  names it: **node name, then geometry name, then material name**; so
  ``{"cells": cells, "panel_3": broken_cells}`` gives every panel with the "cells" material
  ``cells`` except node ``panel_3``. Every node must get a material and every key must
  name some node, geometry or material, else :class:`pprender.Error` naming ``materials``
  and listing the names there are. :attr:`pprender.Scene.matched` says which key gave
  each node its material, and by what (``"node"``, ``"geometry"``, ``"material"``).
"""

from __future__ import annotations

import math
import os
import sys
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, NamedTuple

import numpy as np

from ._core import Error, Material

__all__ = [
    "MAX_EXTENT",
    "Assignment",
    "FlatMesh",
    "Match",
    "Node",
    "SkippedGeometryWarning",
    "UnitsWarning",
    "assign_materials",
    "flatten",
]

#: Largest extent (m, the bounding box's longest side) of a mesh taken without a
#: :class:`UnitsWarning`; a satellite in metres is 0.1 m to ~50 m across.
MAX_EXTENT = 50.0

_METRES = {"m", "meter", "meters", "metre", "metres"}
_MILLIMETRES = {"mm", "millimeter", "millimeters", "millimetre", "millimetres"}


class UnitsWarning(UserWarning):
    """The mesh does not look like it is in metres (too large, or trimesh says other units).

    Emitted by :func:`flatten` (with ``check=True``) for a mesh more than :data:`MAX_EXTENT`
    across or whose trimesh ``units`` are not metres.
    """


class SkippedGeometryWarning(UserWarning):
    """A trimesh.Scene node whose geometry is not a triangle mesh was left out.

    Emitted by :func:`flatten` for ``Path3D`` lines, ``PointCloud`` or geometries without
    faces (module docstring).
    """


@dataclass(frozen=True, eq=False)
class Node:
    """One node (instance) of a flattened trimesh.Scene.

    Parameters
    ----------
    name : str
        The node's name.
    geometry : str
        The name of its geometry (a key of ``scene.geometry``).
    material : str or None
        ``geometry.visual.material.name`` (None when the geometry has no named material).
    transform : numpy.ndarray
        (4, 4) the node's transform to the scene's base frame (the body frame).
    faces : slice
        Its faces in the flattened mesh.
    """

    name: str
    geometry: str
    #: ``geometry.visual.material.name`` (None when the geometry has no named material)
    material: str | None
    #: (4, 4) the node's transform to the scene's base frame (the body frame)
    transform: np.ndarray
    #: its faces in the flattened mesh
    faces: slice


@dataclass(eq=False)
class FlatMesh:
    """A mesh as pprender takes it (:func:`flatten`).

    Parameters
    ----------
    vertices : numpy.ndarray
        (V, 3) float64, m, body frame.
    faces : numpy.ndarray
        (F, 3) int64.
    normals : numpy.ndarray or None
        (V, 3) vertex normals (trimesh input and ``normals=True``).
    face_part : numpy.ndarray or None
        (F,) int64 each face's index into ``parts`` (None: a mesh without parts).
    parts : list of str or None
        Part names: a model's ``metadata["pprender_parts"]``, or a trimesh.Scene's node names.
    nodes : list of Node or None, optional
        A trimesh.Scene's nodes, in ``parts`` order (None for other meshes).
    skipped : list of tuple, optional
        ``(node, geometry, type)`` of the trimesh.Scene nodes left out (not triangle meshes).
    metadata : dict, optional
        The mesh's (or scene's) trimesh metadata.
    """

    vertices: np.ndarray  # (V, 3) float64, m, body frame
    faces: np.ndarray  # (F, 3) int64
    normals: np.ndarray | None  # (V, 3) vertex normals (trimesh input and normals=True)
    #: (F,) int64 each face's index into ``parts`` (None: a mesh without parts)
    face_part: np.ndarray | None
    #: part names: a model's ``metadata["pprender_parts"]``, or a trimesh.Scene's node names
    parts: list[str] | None
    #: a trimesh.Scene's nodes, in ``parts`` order (None for other meshes)
    nodes: list[Node] | None = None
    #: (node, geometry, type) of the trimesh.Scene nodes left out (not triangle meshes)
    skipped: list[tuple[str, str, str]] = field(default_factory=list)
    metadata: dict[str, Any] = field(default_factory=dict)


class Match(NamedTuple):
    """How a part got its material.

    Parameters
    ----------
    key : str
        The ``materials`` key.
    by : str
        What it named: ``"node"``, ``"geometry"``, ``"material"`` for a trimesh.Scene;
        ``"part"`` for a model's parts.
    material : Material
        The material.
    """

    key: str
    by: str
    material: Material


@dataclass(eq=False)
class Assignment:
    """Materials resolved for a mesh (:func:`assign_materials`).

    Parameters
    ----------
    materials : list of Material
        In material-index order.
    parts : list of str or None
        Names of ``materials`` (None: no named parts).
    face_material : numpy.ndarray
        (F,) int64 indices into ``materials``.
    matched : dict of str to Match, or None
        Part -> :class:`Match`, for a mapping.
    """

    materials: list[Material]  # in material-index order
    parts: list[str] | None  # names of ``materials`` (None: no named parts)
    face_material: np.ndarray  # (F,) int64 indices into ``materials``
    matched: dict[str, Match] | None  # part -> Match, for a mapping


def _warn(message: str, category: type[Warning]) -> None:
    """Warn at the first caller outside this package."""
    pkg = os.path.dirname(os.path.abspath(__file__))
    level, frame = 1, sys._getframe(0)
    while frame is not None and os.path.dirname(os.path.abspath(frame.f_code.co_filename)) == pkg:
        frame = frame.f_back  # type: ignore[assignment]
        level += 1
    warnings.warn(message, category, stacklevel=level)


def _check_units(vertices: np.ndarray, units: Any) -> None:
    u = None if units is None else str(units).strip().lower()
    extent = float(np.max(np.ptp(vertices, axis=0))) if len(vertices) else 0.0
    if u in _MILLIMETRES:
        _warn(
            f"the mesh's units are {units!r} ({extent:.4g} across): pprender takes metres; "
            "scale it first, mesh.apply_scale(1e-3) (and set mesh.units = 'meters'), or "
            "mesh.convert_units('meters')",
            UnitsWarning,
        )
    elif u and u not in _METRES:
        _warn(
            f"the mesh's units are {units!r} ({extent:.4g} across): pprender takes metres; "
            "convert it first, mesh.convert_units('meters') (mesh.apply_scale(1e-3) for "
            "millimetres)",
            UnitsWarning,
        )
    elif extent > MAX_EXTENT:
        _warn(
            f"the mesh is {extent:.4g} units across: pprender takes metres and a satellite is "
            f"0.1 m to ~{MAX_EXTENT:g} m across; a CAD export in millimetres needs "
            "mesh.apply_scale(1e-3) (or vertices * 1e-3) first",
            UnitsWarning,
        )


def _material_name(geometry: Any) -> str | None:
    mat = getattr(getattr(geometry, "visual", None), "material", None)
    name = getattr(mat, "name", None)
    return None if name is None else str(name)


def _flatten_scene(scene: Any, normals: bool) -> FlatMesh:
    import trimesh

    verts: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    vnorms: list[np.ndarray] = []
    nodes: list[Node] = []
    skipped: list[tuple[str, str, str]] = []
    nv = nf = 0
    for node in scene.graph.nodes_geometry:
        transform, gname = scene.graph.get(node)
        geom = scene.geometry.get(gname)
        if not isinstance(geom, trimesh.Trimesh) or len(geom.faces) == 0 or len(geom.vertices) == 0:
            kind = type(geom).__name__ if not isinstance(geom, trimesh.Trimesh) else "Trimesh without faces"
            skipped.append((str(node), str(gname), kind))
            continue
        t = np.asarray(transform, dtype=np.float64)
        lin = t[:3, :3]
        v = np.asarray(geom.vertices, dtype=np.float64) @ lin.T + t[:3, 3]
        f = np.asarray(geom.faces, dtype=np.int64)
        det = float(np.linalg.det(lin))
        if det < 0:
            f = f[:, ::-1]  # a mirror: keep the faces' winding outward
        verts.append(v)
        faces.append(f + nv)
        if normals:
            n = np.asarray(geom.vertex_normals, dtype=np.float64)
            if det != 0.0 and math.isfinite(det):
                n = n @ np.linalg.inv(lin)  # the inverse transpose, applied to rows
                n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
            vnorms.append(n)
        nodes.append(Node(str(node), str(gname), _material_name(geom), t, slice(nf, nf + len(f))))
        nv += len(v)
        nf += len(f)
    if skipped:
        _warn(
            "the trimesh.Scene's node(s) "
            + ", ".join(f"{n!r} (geometry {g!r}, {k})" for n, g, k in skipped)
            + " are not triangle meshes and are left out",
            SkippedGeometryWarning,
        )
    if not nodes:
        raise Error(
            "invalid mesh: the trimesh.Scene has no triangle geometry "
            f"({len(scene.geometry)} geometries, {len(skipped)} node(s) left out)"
        )
    face_part = np.concatenate([np.full(n.faces.stop - n.faces.start, i, dtype=np.int64) for i, n in enumerate(nodes)])
    return FlatMesh(
        vertices=np.concatenate(verts),
        faces=np.concatenate(faces),
        normals=np.concatenate(vnorms) if normals else None,
        face_part=face_part,
        parts=[n.name for n in nodes],
        nodes=nodes,
        skipped=skipped,
        metadata=dict(getattr(scene, "metadata", None) or {}),
    )


def flatten(mesh: Any, *, normals: bool = True, check: bool = True) -> FlatMesh:
    """The mesh as pprender takes it: vertices, faces, vertex normals and per-face part index.

    Vertices are in metres in the body frame; the module docstring says which inputs are
    taken, and in which order.

    Parameters
    ----------
    mesh : trimesh.Trimesh, trimesh.Scene or (vertices, faces)
        The mesh (module docstring).
    normals : bool, optional
        Compute vertex normals (trimesh inputs; for ``smooth=True``). Default True.
    check : bool, optional
        Validate (a non-empty mesh, finite vertices, face indices in range) and warn about
        units. Default True.

    Returns
    -------
    FlatMesh
        The flattened mesh.

    Raises
    ------
    pprender.Error
        For an input of another type, a ``trimesh.Scene`` without triangle geometry, or
        arrays of the wrong shape; with ``check``, for an empty mesh, non-finite vertices or
        face indices out of range (naming ``mesh``, ``vertices`` or ``faces``).

    Warns
    -----
    UnitsWarning
        With ``check``, for a mesh that does not look like it is in metres.
    SkippedGeometryWarning
        For ``trimesh.Scene`` nodes that are not triangle meshes.
    """
    import trimesh

    units = getattr(mesh, "units", None)
    if isinstance(mesh, trimesh.Scene):
        flat = _flatten_scene(mesh, normals)
        if units is None:  # mixed or unset: any geometry's not in metres (e.g. "mm")
            units = next((u for g in mesh.geometry.values() if (u := getattr(g, "units", None))
                          and str(u).strip().lower() not in _METRES), None)
    elif isinstance(mesh, trimesh.Trimesh):
        v = np.asarray(mesh.vertices, dtype=np.float64)
        f = np.asarray(mesh.faces, dtype=np.int64)
        meta = dict(mesh.metadata or {})
        parts = meta.get("pprender_parts")
        fp = meta.get("pprender_material") if parts is not None else None
        flat = FlatMesh(
            vertices=v,
            faces=f,
            normals=np.asarray(mesh.vertex_normals, dtype=np.float64) if (normals and len(f)) else None,
            face_part=None if fp is None else np.asarray(fp).astype(np.int64),
            parts=None if parts is None else [str(p) for p in parts],
            metadata=meta,
        )
    elif isinstance(mesh, (tuple, list)) and len(mesh) == 2:
        try:
            v = np.asarray(mesh[0], dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise Error(f"invalid vertices: cannot convert to a float64 array ({e})") from None
        f = np.asarray(mesh[1])
        if v.ndim != 2 or v.shape[1:] != (3,):
            raise Error(f"invalid vertices: shape {v.shape}, expected (V, 3)")
        if f.ndim != 2 or f.shape[1:] != (3,) or not (np.issubdtype(f.dtype, np.integer) or f.size == 0):
            raise Error(f"invalid faces: shape {f.shape} dtype {f.dtype}, expected (F, 3) integers")
        flat = FlatMesh(vertices=v, faces=f.astype(np.int64), normals=None, face_part=None, parts=None)
    else:
        raise Error(
            f"invalid mesh of type {type(mesh).__name__}: expected a trimesh.Trimesh, a "
            "trimesh.Scene (e.g. trimesh.load('sat.glb')) or a (vertices, faces) pair"
        )
    if check:
        v, f = flat.vertices, flat.faces
        if len(v) == 0 or len(f) == 0:
            raise Error(f"invalid mesh: empty ({len(v)} vertices, {len(f)} faces): need at least one triangle")
        bad = ~np.isfinite(v).all(axis=1)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise Error(f"invalid vertices: non-finite coordinates {v[i].tolist()} at index {i} "
                        f"({int(bad.sum())} such vertices)")
        out = (f < 0).any(axis=1) | (f >= len(v)).any(axis=1)
        if out.any():
            i = int(np.flatnonzero(out)[0])
            raise Error(f"invalid faces = {f[i].tolist()} at index {i}: vertex indices in [0, {len(v)})")
        _check_units(v, units)
    return flat


def _names(flat: FlatMesh) -> str:
    nodes = flat.nodes or []
    geoms = list(dict.fromkeys(n.geometry for n in nodes))
    mats = list(dict.fromkeys(n.material for n in nodes if n.material is not None))
    text = f"nodes {[n.name for n in nodes]}, geometries {geoms}, materials {mats}"
    if flat.skipped:
        text += f" (left out, not triangle meshes: nodes {[s[0] for s in flat.skipped]})"
    return text


def _face_material_array(fm: Any, n_faces: int) -> np.ndarray:
    a = np.asarray(fm)
    if a.shape != (n_faces,):
        raise Error(f"invalid face_material: shape {a.shape}, expected ({n_faces},)")
    if not np.issubdtype(a.dtype, np.integer):
        raise Error(f"invalid face_material: dtype {a.dtype}, expected integers")
    return a.astype(np.int64)


def assign_materials(
    flat: FlatMesh,
    materials: Any,
    face_material: Any = None,
    resolve: Callable[[Any], Material] | None = None,
) -> Assignment:
    """Resolve :class:`pprender.Scene`'s ``materials`` (and ``face_material``) for a flattened mesh.

    The module docstring gives the forms and the name precedence.

    Parameters
    ----------
    flat : FlatMesh
        The flattened mesh (:func:`flatten`).
    materials : Material, str, sequence or mapping
        One material, a list, or a mapping from name to material (module docstring).
    face_material : array_like, optional
        (F,) integer indices into the returned material list; when given, it overrides the
        per-face index.
    resolve : callable, optional
        Turns a material name into a :class:`pprender.Material` (default: the Material itself
        only).

    Returns
    -------
    Assignment
        The materials, their part names, each face's material index and, for a mapping, which
        key matched each part.

    Raises
    ------
    pprender.Error
        For a mapping whose keys name nothing or leave a node or part without a material
        (naming ``materials`` and listing the names there are), a list too short for the
        mesh's parts, a ``face_material`` that is not (F,) integers, or a material name
        without ``resolve``.
    """
    cache: dict[Any, Material] = {}

    def res(m: Any) -> Material:
        key = m if isinstance(m, str) else id(m)
        if key not in cache:
            if isinstance(m, Material):
                cache[key] = m
            elif resolve is not None:
                cache[key] = resolve(m)
            else:
                raise Error(f"invalid material {m!r}: expected a pprender.Material")
        return cache[key]

    n_faces = len(flat.faces)
    matched: dict[str, Match] | None = None
    parts: list[str] | None = flat.parts
    fm: np.ndarray | None
    if isinstance(materials, Mapping):
        if flat.nodes is not None:
            nodes = flat.nodes
            names = (
                {n.name for n in nodes} | {n.geometry for n in nodes} | {n.material for n in nodes if n.material}
            )
            unknown = [k for k in materials if k not in names]
            if unknown:
                raise Error(
                    f"invalid materials: key(s) {unknown} name no node, geometry or material of "
                    f"the trimesh.Scene; it has {_names(flat)}"
                )
            matched = {}
            missing = []
            for n in nodes:
                for by, name in (("node", n.name), ("geometry", n.geometry), ("material", n.material)):
                    if name is not None and name in materials:
                        matched[n.name] = Match(name, by, res(materials[name]))
                        break
                else:
                    missing.append(f"{n.name!r} (geometry {n.geometry!r}, material {n.material!r})")
            if missing:
                raise Error(
                    f"invalid materials: no material for node(s) {', '.join(missing)}; key "
                    f"materials by node, geometry or material name: {_names(flat)}"
                )
            mat_list = [matched[n.name].material for n in nodes]
            fm = flat.face_part
        elif flat.parts is not None:
            fparts = flat.parts
            missing_parts = [p for p in fparts if p not in materials]
            if missing_parts:
                raise Error(
                    f"invalid materials: no material for part(s) {missing_parts}; "
                    f"the mesh has parts {fparts}"
                )
            extra = [k for k in materials if k not in fparts]
            if extra:
                raise Error(f"invalid materials: unknown part(s) {extra}; parts are {fparts}")
            mat_list = [res(materials[p]) for p in fparts]
            matched = {p: Match(p, "part", m) for p, m in zip(fparts, mat_list)}
            fm = flat.face_part
        else:
            raise Error(
                "invalid materials: a mapping needs a mesh with named parts: a trimesh.Scene "
                "(e.g. trimesh.load('sat.glb'); keys are its node, geometry or material names) "
                "or a mesh with metadata['pprender_parts'] (pprender.models); else pass one "
                "material, or a list and face_material"
            )
    elif isinstance(materials, (Material, str)):
        mat_list = [res(materials)]
        fm = None
        parts = None
    else:
        try:
            seq = list(materials)
        except TypeError:
            raise Error(
                f"invalid materials of type {type(materials).__name__}: expected a Material, a "
                "material name, a list or a mapping"
            ) from None
        mat_list = [res(m) for m in seq]
        fm = flat.face_part if face_material is None else None
        if fm is not None and len(fm) and int(fm.max()) >= len(mat_list):
            raise Error(
                f"invalid materials: a list of {len(mat_list)} for a mesh with {len(flat.parts or [])} "
                f"parts {flat.parts}: give one material per part, in this order, or face_material"
            )
        if face_material is not None or len(mat_list) != len(parts or []):
            parts = None  # the list is indexed by the caller's face_material, not by parts
    if face_material is not None:
        fm = _face_material_array(face_material, n_faces)
    if fm is None:
        fm = np.zeros(n_faces, dtype=np.int64)
    fm = _face_material_array(fm, n_faces)
    return Assignment(mat_list, None if parts is None else list(parts), fm, matched)
