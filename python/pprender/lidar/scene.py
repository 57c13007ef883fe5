"""A mesh with its materials, ready to render (:class:`Scene`); loading and material
assignment are :mod:`pprender.mesh`'s."""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from .. import _core
from .._core import Error, Material


def _resolve_material(m: Any, wavelength: float) -> Material:
    if isinstance(m, Material):
        return m
    if isinstance(m, str):
        from .. import materials

        return materials.get(m, wavelength=wavelength)
    raise Error(f"invalid material {m!r}: expected a pprender.Material or a material name")


class Scene:
    """A mesh with its materials, ready to render.

    Loading and material assignment are :mod:`pprender.mesh`'s (:func:`pprender.mesh.flatten`,
    :func:`pprender.mesh.assign_materials`).

    Parameters
    ----------
    mesh : trimesh.Trimesh, trimesh.Scene or (vertices, faces)
        A ``trimesh.Trimesh``, a ``trimesh.Scene`` (e.g. ``trimesh.load("sat.glb")``; each
        node of ``scene.graph.nodes_geometry`` is a part, its geometry moved by the node's
        transform, instances included) or a ``(vertices, faces)`` pair of arrays. Vertices
        are taken in metres in the body frame as given, with no axis conversion (glTF is
        Y-up: rotate it yourself). :mod:`pprender.mesh` states all of this, the flattened
        face order and how to rotate a model.
    materials : Material, str, sequence or mapping
        One material for the whole mesh; a list indexed by ``face_material`` (default: the
        mesh's per-face part index, :func:`pprender.mesh.flatten`'s ``face_part``, so one
        material per part in ``parts`` order); or a mapping from name to material: a model's
        part names (:mod:`pprender.models`, ``metadata["pprender_parts"]``) or, for a
        ``trimesh.Scene``, node, geometry (``scene.geometry`` keys) or material
        (``geometry.visual.material.name``) names, each node taking the most specific key
        that names it (node > geometry > material). Materials may be
        :class:`pprender.Material` objects or names from :mod:`pprender.materials` (built at
        ``wavelength``).
    face_material : array_like, shape (F,), optional
        Indices into the material list, in the flattened face order.
    smooth : bool, optional
        True interpolates vertex normals (from the mesh, or ``normals``) for shading; the
        default (False) shades flat faces, which is right for boxes and panels.
    normals : array_like, shape (V, 3), optional
        Vertex normals, one per vertex of the flattened mesh, instead of the mesh's own.
    wavelength : float, optional
        Wavelength (m) at which materials given by name are built. Default 1064e-9.

    Attributes
    ----------
    materials : list of Material
        The materials, in material-index order.
    parts : list of str or None
        Their names (None without named parts).
    vertices : numpy.ndarray
        The flattened vertices (m, body frame).
    faces : numpy.ndarray
        The flattened faces.
    face_material : numpy.ndarray
        Each face's index into ``materials``.
    face_part : numpy.ndarray or None
        Each face's index into the mesh's parts, ``pprender.mesh.flatten(mesh).parts``; None
        without parts.
    matched : dict of str to pprender.mesh.Match, or None
        For a mapping: part or node name -> :class:`pprender.mesh.Match`, the key that gave it
        its material and whether it named the node, geometry or material.
    radius : float
        Bounding-sphere radius about the body origin (m): the image half-width.
    n_faces : int
        Number of faces.

    Raises
    ------
    pprender.Error
        For an invalid mesh or materials (:mod:`pprender.mesh`), ``normals`` that are not one
        (3,) vector per vertex, or ``smooth=True`` without vertex normals (neither
        ``normals`` nor a trimesh mesh).

    Warns
    -----
    pprender.mesh.UnitsWarning
        For a mesh more than 50 m across or in other units than metres.
    pprender.mesh.SkippedGeometryWarning
        For ``trimesh.Scene`` nodes whose geometry is not a triangle mesh (left out).
    """

    def __init__(
        self,
        mesh: Any,
        materials: Material | str | Sequence[Material | str] | Mapping[str, Material | str],
        *,
        face_material: Any = None,
        smooth: bool = False,
        normals: Any = None,
        wavelength: float = 1064e-9,
    ) -> None:
        from .. import mesh as _mesh

        flat = _mesh.flatten(mesh, normals=bool(smooth) and normals is None)
        a = _mesh.assign_materials(flat, materials, face_material, lambda m: _resolve_material(m, wavelength))
        vn = None
        if normals is not None:
            try:
                vn = np.asarray(normals, dtype=np.float64)
            except (TypeError, ValueError) as e:
                raise Error(f"invalid normals: cannot convert to a float64 array ({e})") from None
            if vn.shape != flat.vertices.shape:
                raise Error(f"invalid normals: shape {vn.shape}, expected {flat.vertices.shape} (one per vertex)")
        elif smooth:
            if flat.normals is None:
                raise Error("smooth=True needs vertex normals: pass normals= or a trimesh mesh")
            vn = flat.normals
        self.materials: list[Material] = a.materials
        self.parts: list[str] | None = a.parts
        self.matched: dict[str, _mesh.Match] | None = a.matched
        self.vertices: np.ndarray = flat.vertices
        self.faces: np.ndarray = flat.faces
        self.face_material: np.ndarray = a.face_material
        self.face_part: np.ndarray | None = flat.face_part
        # the core builds BRDF tables per material: give it each distinct Material once
        unique: dict[int, int] = {}
        core_mats: list[Material] = []
        for m in a.materials:
            if id(m) not in unique:
                unique[id(m)] = len(core_mats)
                core_mats.append(m)
        remap = np.array([unique[id(m)] for m in a.materials], dtype=np.int64)
        fm = a.face_material
        if len(remap) and len(fm) and 0 <= int(fm.min()) and int(fm.max()) < len(remap):
            fm = remap[fm]
        else:
            core_mats = list(a.materials)  # out of range: the core names the bad index
        self._core = _core.RenderScene(
            np.ascontiguousarray(flat.vertices, dtype=np.float64),
            np.ascontiguousarray(flat.faces, dtype=np.int64),
            np.ascontiguousarray(fm, dtype=np.int64),
            core_mats,
            None if vn is None else np.ascontiguousarray(vn, dtype=np.float64),
        )

    def __repr__(self) -> str:
        def mname(m: Material) -> str:
            return m.name or f"unnamed#{next(i for i, x in enumerate(self.materials) if x is m)}"

        head = f"pprender.Scene({self.n_faces} faces, radius {self.radius:.4g} m"
        if self.matched:
            items = [
                f"{p} = {mname(m.material)}"
                + {"part": "", "node": " (by node)"}.get(m.by, f" (by {m.by} {m.key!r})")
                for p, m in self.matched.items()
            ]
        elif self.parts is not None:
            items = [f"{p} = {mname(m)}" for p, m in zip(self.parts, self.materials)]
        else:
            items = [mname(m) for i, m in enumerate(self.materials) if all(x is not m for x in self.materials[:i])]
        more = f", ... ({len(items) - 8} more)" if len(items) > 8 else ""
        return head + f", {len(items)} {'part' if self.parts is not None else 'material'}{'' if len(items) == 1 else 's'}: " + ", ".join(items[:8]) + more + ")"

    @property
    def radius(self) -> float:
        """Bounding-sphere radius about the body origin (m): the image half-width."""
        return float(self._core.radius)

    @property
    def n_faces(self) -> int:
        return int(self._core.n_faces)

    def prepare(self, bistatic_angle: float = 0.0) -> float:
        """Build the materials' BRDF tables for a bistatic angle now (they are otherwise
        built on the first render and cached); returns the build time in seconds."""
        return float(self._core.prepare(float(bistatic_angle)))


def _mesh_arrays(mesh: Any) -> tuple[np.ndarray, np.ndarray, dict[str, Any], np.ndarray | None]:
    """(vertices, faces, metadata, vertex normals) as :class:`Scene` takes them
    (:func:`pprender.mesh.flatten`, unvalidated). A ``trimesh.Scene``'s metadata gets
    ``pprender_parts`` (its node names) and ``pprender_material`` (each face's node index),
    the parts :class:`Scene` gives it, in the same flattened order."""
    from .. import mesh as _mesh

    flat = _mesh.flatten(mesh, normals=True, check=False)
    meta = dict(flat.metadata)
    if flat.nodes is not None:
        meta["pprender_parts"] = list(flat.parts or [])
        meta["pprender_material"] = flat.face_part
    return flat.vertices, flat.faces, meta, flat.normals
