"""Lidar rendering: Mueller/Stokes images, range maps and range-resolved pulse profiles.

Conventions (written once in ``src/render/mod.rs``; summary):

* Units: metres, seconds, radians; cross-sections in m^2.
* Telescope frame ``(X, Y, Z)``: ``Z`` from the target toward the receiver, ``X`` right,
  ``Y`` up in the images. Receiver direction ``wo = Z``; transmitter direction
  ``wi = (sin beta, 0, cos beta)`` for the bistatic angle ``beta``.
* Attitudes rotate the body into the telescope frame, ``p_tel = R p_body``: (N, 3, 3)
  rotation matrices, (N, 4) unit quaternions ``(w, x, y, z)`` (scalar first; scipy's
  ``as_quat()`` is scalar-last ``(x, y, z, w)``), or a ``scipy.spatial.transform.Rotation``
  (single or stacked), which is converted without ambiguity. The body
  origin is the range reference.
* Images: (N, H, W, ...) with row 0 at the top (``+Y``) and column 0 at the left
  (``-X``); they span ``[-extent, extent]`` in X and Y, ``extent`` the radius of the
  mesh's bounding sphere about the body origin.
* Range ``r = -p . (wi + wo) / 2`` relative to the body origin, positive away from the
  sensor; time axis ``t = 2 r / c``.
* Stokes bases: received beam ``(X, Y)``; transmitted beam (propagating along ``-wi``)
  ``x = normalize(-wi x Y)`` (``X`` monostatic), ``y = -wi x x`` (``-Y`` monostatic). A
  mirror facing the sensor is ``R diag(1, 1, -1, -1)``.
* Pixel values are differential lidar cross-sections ``4 pi f cos(theta_i) delta^2`` (m^2).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from . import _core
from ._core import Error, Material

# Mesa's device-select layer complains when XDG_RUNTIME_DIR is unset (headless machines);
# it is not needed for compute. Must be set before the Vulkan loader starts.
os.environ.setdefault("NODEVICE_SELECT", "1")

SPEED_OF_LIGHT = 299_792_458.0
_FWHM_PER_SIGMA = 2.0 * math.sqrt(2.0 * math.log(2.0))

__all__ = ["Lidar", "OffCentreWarning", "RenderResult", "Scene", "device_info", "render", "SPEED_OF_LIGHT"]


def device_info(device: str = "auto") -> dict[str, Any]:
    """Which adapter renders: name, backend, device type, driver and the limits used.

    ``device``: ``"auto"`` (a GPU when present, else the CPU implementation lavapipe),
    ``"cpu"`` (lavapipe even when a GPU is present) or ``"gpu"`` (error without one).
    """
    return dict(_core.device_info(device))


def _is_real(x: Any) -> bool:
    """An int or float (NumPy's included), not a bool or a string."""
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))


def _is_int(x: Any) -> bool:
    return isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_))


def _resolve_material(m: Any, wavelength: float) -> Material:
    if isinstance(m, Material):
        return m
    if isinstance(m, str):
        from . import materials

        return materials.get(m, wavelength=wavelength)
    raise Error(f"invalid material {m!r}: expected a pprender.Material or a material name")


class Scene:
    """A mesh with its materials, ready to render.

    ``mesh``: a ``trimesh.Trimesh``, a ``trimesh.Scene`` (e.g. ``trimesh.load("sat.glb")``;
    each node of ``scene.graph.nodes_geometry`` is a part, its geometry moved by the node's
    transform, instances included) or a ``(vertices, faces)`` pair of arrays. Vertices are
    taken in metres in the body frame as given, with no axis conversion (glTF is Y-up:
    rotate it yourself); a mesh more than 50 m across or in other units gives a
    :class:`pprender.mesh.UnitsWarning`. :mod:`pprender.mesh` states all of this, the
    flattened face order and how to rotate a model.

    ``materials``: one material for the whole mesh; a list indexed by ``face_material``
    (default: the mesh's per-face part index, :func:`pprender.mesh.flatten`'s
    ``face_part``, so one material per part in ``parts`` order); or a mapping from name to
    material: a model's part names (:mod:`pprender.models`, ``metadata["pprender_parts"]``)
    or, for a ``trimesh.Scene``, node, geometry (``scene.geometry`` keys) or material
    (``geometry.visual.material.name``) names, each node taking the most specific key
    that names it (node > geometry > material). Materials may be :class:`pprender.Material`
    objects or names from :mod:`pprender.materials` (built at ``wavelength``, m).
    ``face_material``: (F,) indices into the material list, in the flattened face order.
    ``smooth=True`` interpolates vertex normals (from the mesh, or ``normals``) for
    shading; the default shades flat faces, which is right for boxes and panels.

    Attributes: ``materials`` (in material-index order) and ``parts`` (their names, None
    without named parts); ``vertices``, ``faces`` (flattened), ``face_material`` (each
    face's index into ``materials``), ``face_part`` (each face's index into the mesh's
    parts, ``pprender.mesh.flatten(mesh).parts``; None without parts) and ``matched``
    (for a mapping: part or node name -> :class:`pprender.mesh.Match`, the key that gave
    it its material and whether it named the node, geometry or material).
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
        from . import mesh as _mesh

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
    from . import mesh as _mesh

    flat = _mesh.flatten(mesh, normals=True, check=False)
    meta = dict(flat.metadata)
    if flat.nodes is not None:
        meta["pprender_parts"] = list(flat.parts or [])
        meta["pprender_material"] = flat.face_part
    return flat.vertices, flat.faces, meta, flat.normals


@dataclass(frozen=True)
class Lidar:
    """The laser and receiver.

    ``pulse_fwhm`` (s): Gaussian pulse full width at half maximum (the received pulse; a
    range FWHM of ``c pulse_fwhm / 2``). ``pulse_samples``: a measured or modelled pulse
    shape instead (received power, any scale, >= 0) sampled every ``pulse_sample_spacing``
    seconds; the samples are joined linearly (going to zero one spacing beyond each end)
    and the shape is placed with its centroid at range 0, as the Gaussian's centre. Its
    profile is exact in f64 but accumulated on the host from the kernel's per-pixel range
    footprints, several times slower than the Gaussian's on-device accumulation
    (docs/render-benchmark.md); ``pulse_fwhm`` is then ignored and the defaults below use
    the FWHM of the Gaussian with the sampled shape's variance. ``bin_width`` (m of range): profile bin width,
    default a quarter of the range FWHM. ``resolution``: image side in pixels, default
    such that a pixel is a quarter of the range FWHM across (clamped to [64, 1024]): about
    1e-3 relative error of cross-sections for generic orientations (edges aligned with the
    pixel grid alias more; docs/render-accuracy.md).
    ``supersampling``: sub-pixels per pixel side for visibility and the profile.
    ``pixel_samples``: visibility samples per (sub-)pixel, 1, 2, 4, 8 or 16 (default: the
    quality preset's). The pixel's area is shared among the surfaces its samples see, each
    shaded once at the mean of its samples (a (0, m, 2)-net: one sample in each of the
    ``K`` rows and columns of the pixel, so an edge's coverage is resolved to ``1/K`` of a
    pixel, and a sliver thinner than a pixel is still seen); pixels that see one surface
    cost one shading as with ``1``. This is what makes silhouettes, panel edges and thin
    parts area-correct (docs/render-accuracy.md); ``supersampling`` refines everything at
    ``supersampling^2`` times the cost.
    ``coverage``: ``"sampled"`` (default: the ``pixel_samples`` above) or ``"analytic"``:
    one raster sample per pixel finds the triangles around it (those seen at the centres of
    the pixel's 3x3 neighbourhood, and their edge neighbours on the mesh), and each one's
    visible part of the pixel is computed exactly by clipping the triangles to the pixel in
    depth order; each is shaded once at the centroid of its part. Edges then cost no more
    samples: coverage is exact to f32 rounding wherever at most 32 triangles overlap a pixel
    (else, at a vertex shared by dozens of triangles, the pixel falls back to its centre
    sample). Needs ``pixel_samples`` 1 (or unset).
    ``quality``: the speed/accuracy dial (:data:`QUALITY`; docs/tradeoff.md measures each):
    ``"fast"`` (coarse BRDF tables, pixels half the range FWHM across), ``"balanced"``
    (the default grids and resolution), ``"accurate"`` (fine tables, double bounce at
    order 96, pixels an eighth of the range FWHM) or ``"reference"`` (the exact f64 CPU
    renderer: every pixel's BRDF evaluated by the core, no tables; slow). ``table``:
    individual overrides of the preset's BRDF table grid, a mapping with any of ``n_z``,
    ``n_psi`` (single term), ``n_z_lambertian``, ``n_psi_lambertian`` (multiple + diffuse),
    ``n_z_double``, ``n_psi_double``, ``double_order`` (:func:`pprender.brdf_table`).
    ``resolution`` and ``pixel_samples`` given explicitly override the preset's.
    ``arithmetic``: ``"f32"`` (the device kernel, default) or ``"f64"``: the kernel's f64
    CPU twin, the same tables, visibility samples and pulse integration in double precision
    (with rayon, on the CPU whatever ``device``; bistatic cast shadows by exact rays instead
    of the kernel's shadow map). It isolates what f32 arithmetic costs in accuracy: about
    3e-5 of a pixel's M00, half the tables' own interpolation error, and 1e-6 to 1e-4 of
    a profile, growing with the pixel's range footprint (docs/tradeoff.md measures both).
    It is also a native CPU renderer: on a machine without a GPU it can be faster than
    lavapipe (1.3x for profiles, 4x to 5x for images on 2 cores here,
    docs/render-benchmark.md, docs/equal-error.md); on a GPU ``"f32"`` is
    the choice. ``quality="reference"`` is f64 already (``arithmetic`` unset or ``"f64"``).
    ``brdf``: ``"table"`` (default) looks every term up in the per-material tables of
    :func:`pprender.brdf_table`; ``"shader"`` evaluates the single, multiple and diffuse
    terms per pixel in the kernel instead (and in its twin for ``arithmetic="f64"``): the
    microfacet distribution, the complex Fresnel amplitudes and their Mueller matrix, the
    masking correlation, the masking excess and the albedos from the material's own 1D
    tables. That is the core's model for the default ``masking="table"`` (the Smith and
    seed closed forms and ``"exact"`` go through a 512-node table of theirs, within 1e-6
    and 5e-6 of M00), so only f32 arithmetic remains: the tables' grids (``n_z``,
    ``n_psi``, ``n_z_lambertian``, ``n_psi_lambertian``) and their interpolation error drop
    out, and no such tables are built. The double bounce stays tabulated (it is an integral
    per pixel). What it costs and gains is in docs/tradeoff.md.
    ``intensity_only``: with a ``polarization``, compute only the received intensity ``S0``
    (``"intensity"`` images (N, H, W), profiles (N, B), cross-sections (N,)); the kernel
    then looks up only the Mueller elements it needs (``M00`` alone for an unpolarized
    transmitter).
    ``bistatic_angle`` (rad) in [0, pi/2). ``polarization``: transmitted Stokes vector
    (4,) in the transmit basis, or None for full Mueller output. ``wavelength`` (m) must
    match the materials' wavelength (their refractive indices are for one wavelength).
    """

    wavelength: float = 1064e-9
    pulse_fwhm: float = 100e-12
    bin_width: float | None = None
    resolution: int | None = None
    bistatic_angle: float = 0.0
    polarization: Sequence[float] | None = None
    supersampling: int = 1
    pixel_samples: int | None = None
    coverage: str = "sampled"
    pulse_samples: Sequence[float] | None = None
    pulse_sample_spacing: float | None = None
    quality: str = "balanced"
    table: Any = None
    intensity_only: bool = False
    arithmetic: str | None = None
    brdf: str = "table"

    def __post_init__(self) -> None:
        if self.brdf not in ("table", "shader"):
            raise Error(f'invalid brdf = {self.brdf!r}: "table" (per-material tables) or "shader" '
                        "(the single, multiple and diffuse terms evaluated per pixel)")
        if self.quality == "reference" and self.brdf == "shader":
            raise Error('invalid brdf = "shader" with quality = "reference": the reference evaluates '
                        'every term exactly per pixel already (leave brdf = "table")')
        if self.arithmetic not in (None, "f32", "f64"):
            raise Error(f'invalid arithmetic = {self.arithmetic!r}: "f32" (the device kernel) or "f64" '
                        "(its CPU twin in double precision)")
        if self.quality == "reference" and self.arithmetic == "f32":
            raise Error('invalid arithmetic = "f32" with quality = "reference": the reference is the '
                        'exact f64 renderer (leave arithmetic unset)')
        if not isinstance(self.intensity_only, (bool, np.bool_)):
            raise Error(f"invalid intensity_only = {self.intensity_only!r}: True or False")
        if self.intensity_only and self.polarization is None:
            raise Error("invalid intensity_only = True: needs a transmitted polarization (a Stokes vector); "
                        "without one the output is the Mueller matrix")
        if self.quality not in QUALITY:
            raise Error(f"invalid quality = {self.quality!r}: one of {tuple(QUALITY)}")
        if self.table is not None:
            try:
                items = dict(self.table).items()
            except (TypeError, ValueError):
                raise Error(f"invalid table = {self.table!r}: a mapping of grid keywords to integers") from None
            bad = [k for k, _ in items if k not in _TABLE_KEYS]
            if bad:
                raise Error(f"invalid table keys {bad}: choose from {_TABLE_KEYS}")
            for k, v in items:
                if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or not 2 <= v <= 65536:
                    raise Error(f"invalid table[{k!r}] = {v!r}: an integer in [2, 65536]")
            object.__setattr__(self, "table", tuple(sorted((k, int(v)) for k, v in items)))
        for name in ("wavelength", "pulse_fwhm"):
            v = getattr(self, name)
            if not (_is_real(v) and math.isfinite(v) and v > 0):
                raise Error(f"invalid {name} = {v!r}: a positive, finite number (SI units)")
        if self.bin_width is not None and not (
            _is_real(self.bin_width) and math.isfinite(self.bin_width) and self.bin_width > 0
        ):
            raise Error(f"invalid bin_width = {self.bin_width!r}: a positive length in metres")
        if self.resolution is not None and (
            not _is_int(self.resolution) or not 1 <= self.resolution <= 8192
        ):
            raise Error(f"invalid resolution = {self.resolution!r}: an integer in [1, 8192]")
        if not _is_int(self.supersampling) or not 1 <= self.supersampling <= 64:
            raise Error(f"invalid supersampling = {self.supersampling!r}: an integer in [1, 64]")
        k = self.pixel_samples
        if k is not None and (
            not isinstance(k, (int, np.integer)) or isinstance(k, bool) or k not in (1, 2, 4, 8, 16)
        ):
            raise Error(f"invalid pixel_samples = {k!r}: visibility samples per pixel, one of 1, 2, 4, 8, 16")
        if self.coverage not in ("sampled", "analytic"):
            raise Error(f"invalid coverage = {self.coverage!r}: \"sampled\" or \"analytic\"")
        if self.coverage == "analytic" and k is not None and k != 1:
            raise Error(f"invalid pixel_samples = {k!r} with coverage=\"analytic\": 1 (or None); "
                        "analytic coverage samples each pixel once to find its triangles")
        b = self.bistatic_angle
        if not (_is_real(b) and 0.0 <= b < math.pi / 2):
            raise Error(f"invalid bistatic_angle = {b!r}: radians in [0, pi/2)")
        if self.polarization is not None:
            try:
                p = np.asarray(self.polarization, dtype=np.float64)
            except (TypeError, ValueError):
                p = np.full(1, np.nan)
            if isinstance(self.polarization, (str, bytes)) or p.shape != (4,) or not np.all(np.isfinite(p)) or p[0] <= 0:
                raise Error(
                    f"invalid polarization = {self.polarization!r}: a Stokes vector (4,) with S0 > 0"
                )
            if np.linalg.norm(p[1:]) > p[0] * (1 + 1e-9):
                raise Error(
                    f"invalid polarization = {self.polarization!r}: not physical "
                    "(sqrt(S1^2 + S2^2 + S3^2) > S0)"
                )

        if self.pulse_samples is not None or self.pulse_sample_spacing is not None:
            if self.pulse_samples is None or self.pulse_sample_spacing is None:
                raise Error(
                    "invalid pulse: pulse_samples and pulse_sample_spacing go together "
                    "(samples of the received power every pulse_sample_spacing seconds)"
                )
            dt = self.pulse_sample_spacing
            if not (_is_real(dt) and math.isfinite(dt) and dt > 0):
                raise Error(f"invalid pulse_sample_spacing = {dt!r}: a positive, finite time in seconds")
            try:
                ps = np.asarray(self.pulse_samples, dtype=np.float64)
            except (TypeError, ValueError):
                raise Error("invalid pulse_samples: not an array of numbers") from None
            if ps.ndim != 1 or not 1 <= len(ps) <= 100_000:
                raise Error(f"invalid pulse_samples: shape {ps.shape}, expected (n,) with 1 <= n <= 100000")
            if not np.all(np.isfinite(ps)) or np.any(ps < 0) or not ps.sum() > 0:
                raise Error("invalid pulse_samples: finite values >= 0 with a positive sum")
            object.__setattr__(self, "pulse_samples", tuple(float(x) for x in ps))

    @property
    def sampled(self) -> bool:
        """Whether the pulse is a sampled shape (``pulse_samples``) rather than a Gaussian."""
        return self.pulse_samples is not None

    @property
    def pulse_spacing_range(self) -> float:
        """Sample spacing of a sampled pulse in range units, ``c pulse_sample_spacing / 2`` (m)."""
        if self.pulse_sample_spacing is None:
            raise Error("this Lidar has a Gaussian pulse (no pulse_samples)")
        return SPEED_OF_LIGHT * self.pulse_sample_spacing / 2.0

    @property
    def pulse_variance_range(self) -> float:
        """Variance of the pulse in range units (m^2): sigma^2 for the Gaussian; for a
        sampled shape that of its piecewise-linear interpolation (each hat adds dt^2/6)."""
        if self.pulse_samples is None:
            return self.sigma_range**2
        p = np.asarray(self.pulse_samples)
        dt = self.pulse_spacing_range
        r = dt * np.arange(len(p))
        w = p / p.sum()
        mu = float((w * r).sum())
        return float((w * (r - mu) ** 2).sum()) + dt * dt / 6.0

    @property
    def range_fwhm(self) -> float:
        """Range FWHM of the pulse, ``c pulse_fwhm / 2`` (m); for a sampled shape, the FWHM
        of the Gaussian with its variance."""
        if self.pulse_samples is not None:
            return _FWHM_PER_SIGMA * math.sqrt(self.pulse_variance_range)
        return SPEED_OF_LIGHT * self.pulse_fwhm / 2.0

    @property
    def sigma_range(self) -> float:
        return self.range_fwhm / _FWHM_PER_SIGMA

    def effective_bin_width(self) -> float:
        return self.bin_width if self.bin_width is not None else self.range_fwhm / 4.0

    def effective_resolution(self, radius: float) -> int:
        """Image side in pixels: ``resolution``, or the quality preset's default for an
        object of bounding ``radius`` (m): a pixel ``range_fwhm / pixels_per_fwhm`` across,
        clamped to [64, 1024] (``"fast"``: [32, 1024])."""
        if self.resolution is not None:
            return int(self.resolution)
        q = QUALITY[self.quality]
        n = math.ceil(2.0 * radius / (self.range_fwhm / q["pixels_per_fwhm"]))
        return int(min(1024, max(q["min_resolution"], n)))

    def effective_pixel_samples(self) -> int:
        """Visibility samples per pixel: ``pixel_samples``, or the quality preset's (1 with
        analytic ``coverage``)."""
        if self.coverage == "analytic":
            return 1
        if self.pixel_samples is not None:
            return int(self.pixel_samples)
        return int(QUALITY[self.quality]["pixel_samples"])

    def effective_arithmetic(self) -> str:
        """``"f64"`` for the twin or the reference, else ``"f32"`` (the device kernel)."""
        if self.quality == "reference":
            return "f64"
        return self.arithmetic or "f32"

    def table_options(self) -> dict[str, int]:
        """The BRDF table grid the renderer uses: the preset's, then ``table``'s overrides
        (keys absent: the defaults of :func:`pprender.brdf_table`)."""
        d = dict(QUALITY[self.quality]["table"])
        d.update(dict(self.table or ()))
        return d


@dataclass
class RenderResult:
    """What :func:`render` returns; arrays are NumPy, only the requested ones are set.

    ``cross_section``: (N, 4, 4) total Mueller lidar cross-section in m^2, or (N, 4) Stokes
    when the sensor has a ``polarization``. ``profile``: (N, B, 4, 4) or (N, B, 4), m^2 per
    bin, summing over bins to ``cross_section``; ``range_axis`` (B,) bin centres (m),
    ``bin_edges`` (B+1,), ``time_axis`` (B,) round-trip delays ``2 r / c`` (s).
    ``mueller`` (N, H, W, 4, 4) / ``stokes`` (N, H, W, 4) / ``intensity`` (N, H, W): m^2 per pixel. ``range``
    (N, H, W) metres, the mean over the pixel's covered visibility samples, NaN where
    nothing is seen; ``coverage`` (N, H, W) the covered fraction of its samples.
    """

    cross_section: np.ndarray
    bin_edges: np.ndarray
    pixel_size: float
    extent: float
    device: str
    profile: np.ndarray | None = None
    mueller: np.ndarray | None = None
    stokes: np.ndarray | None = None
    intensity: np.ndarray | None = None
    range: np.ndarray | None = None
    coverage: np.ndarray | None = None
    table_seconds: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)
    #: The sensor's wavelength (m) the render was made at (the materials' wavelength);
    #: None for a result assembled by hand.
    wavelength: float | None = None

    @property
    def range_axis(self) -> np.ndarray:
        return 0.5 * (self.bin_edges[1:] + self.bin_edges[:-1])

    @property
    def time_axis(self) -> np.ndarray:
        return 2.0 * self.range_axis / SPEED_OF_LIGHT

    @property
    def mask(self) -> np.ndarray | None:
        return None if self.coverage is None else self.coverage > 0


_OUTPUTS = ("profile", "mueller", "stokes", "intensity", "range", "cross_section")
_TABLE_KEYS = ("n_z", "n_psi", "n_z_lambertian", "n_psi_lambertian", "n_z_double", "n_psi_double",
               "double_order")

#: The quality presets of :class:`Lidar` (``quality=``): BRDF table grids (keywords of
#: :func:`pprender.brdf_table`; absent keys take its defaults: single n_z 256 / n_psi 32,
#: multiple + diffuse 256 / 8, double 32 / 8 at order 48) and the default image
#: resolution (pixels across one range FWHM) and visibility samples per pixel.
#: ``"reference"`` renders on the CPU in f64
#: with exact BRDFs (no tables). Their cost and error are measured in docs/tradeoff.md.
QUALITY: dict[str, dict[str, Any]] = {
    "fast": {"table": {"n_z": 64, "n_psi": 16, "n_z_lambertian": 64, "n_psi_lambertian": 4,
                       "n_z_double": 16, "n_psi_double": 4, "double_order": 32},
             "pixels_per_fwhm": 2.0, "min_resolution": 32, "pixel_samples": 1},
    "balanced": {"table": {}, "pixels_per_fwhm": 4.0, "min_resolution": 64, "pixel_samples": 8},
    "accurate": {"table": {"n_z": 1024, "n_psi": 64, "n_z_lambertian": 512,
                           "n_psi_lambertian": 16, "n_z_double": 64, "n_psi_double": 16,
                           "double_order": 96},
                 "pixels_per_fwhm": 8.0, "min_resolution": 64, "pixel_samples": 16},
    "reference": {"table": {}, "pixels_per_fwhm": 4.0, "min_resolution": 64, "pixel_samples": 16},
}


def _rotations(attitudes: Any) -> np.ndarray:
    from .so3 import scipy_quaternions

    q = scipy_quaternions(attitudes)
    if q is not None:
        attitudes = q.reshape(-1, 4)
    try:
        a = np.asarray(attitudes, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise Error(f"invalid attitudes: not a float array ({e})") from None
    if a.ndim == 1 and a.shape == (4,):
        a = a[None]
    if a.ndim == 2 and a.shape == (3, 3):
        a = a[None]
    if a.ndim == 2 and a.shape[1] == 4:
        return np.asarray(_core.quaternions_to_rotations(np.ascontiguousarray(a)))
    if a.ndim == 3 and a.shape[1:] == (3, 3):
        if not np.all(np.isfinite(a)):
            raise Error("invalid attitudes: non-finite rotation matrix entries")
        return np.ascontiguousarray(a)
    raise Error(
        f"invalid attitudes: shape {a.shape}; expected (N, 4) quaternions (w, x, y, z), "
        "(N, 3, 3) rotation matrices or a scipy Rotation"
    )


class OffCentreWarning(UserWarning):
    """The mesh lies far from the body origin (the rotation centre, range reference and
    image centre): most of each image and range window is empty, and attitudes swing the
    mesh about a point outside it. Usually a CAD model exported in another frame."""


def _check_framing(scene: Scene, width: int) -> None:
    """Refuse a render whose pixels are too coarse to see the mesh at all, and warn when
    the mesh lies far from the body origin (the case that makes them so).

    The image spans the bounding sphere about the body origin (radius ``scene.radius``),
    ``width`` (sub-)pixels across. The mesh's own size is its bounding-box diagonal: no
    attitude shows it wider. Below 2 pixels across, visibility samples can miss it
    entirely (a cross-section of 0, or of whichever pixel a sample hits): no right answer
    is possible, so the render is refused."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in scene._core.bounds)
    size = float(np.linalg.norm(hi - lo))
    offset = float(np.linalg.norm(0.5 * (lo + hi)))
    pixel = 2.0 * scene.radius / width
    if offset > size:
        import warnings

        warnings.warn(
            f"the mesh's bounding-box centre is {offset:.4g} m from the body origin, more than "
            f"its own size ({size:.4g} m): attitudes rotate the body about the origin, ranges "
            f"are measured from it, and each image spans the sphere of radius "
            f"{scene.radius:.4g} m about it, so the mesh covers about {size / pixel:.3g} of "
            f"{width} pixels across. If the offset is not intended (a CAD model in another "
            "frame), centre the mesh on its centre of mass, e.g. "
            "mesh.apply_translation(-mesh.center_mass)",
            OffCentreWarning,
            stacklevel=3,
        )
    if size < 2.0 * pixel:
        raise Error(
            f"invalid resolution = {width}: the mesh ({size:.4g} m across) spans "
            f"{size / pixel:.3g} pixel(s) of the {2 * scene.radius:.4g} m image (the sphere "
            "about the body origin): too few to resolve it (at least 2 needed); raise "
            "resolution or supersampling, or centre the mesh on the body origin"
        )


def render(
    scene: Scene,
    sensor: Lidar,
    attitudes: Any,
    outputs: Sequence[str] = ("profile", "mueller", "range"),
    *,
    device: str = "auto",
) -> RenderResult:
    """Render ``scene`` seen by ``sensor`` at every attitude, as one batch.

    ``attitudes``: (N, 4) unit quaternions ``(w, x, y, z)`` (scalar first), (N, 3, 3)
    rotation matrices or a ``scipy.spatial.transform.Rotation``, body to telescope
    (module docstring). A mesh too small for the image's pixels (under 2 across: it lies
    far from the body origin, or the resolution is tiny) is refused; one far from the body
    origin warns (:class:`OffCentreWarning`).

    ``outputs``: any of ``"profile"``, ``"mueller"`` (needs ``polarization=None``),
    ``"stokes"`` (needs a ``polarization``), ``"range"`` (range map and coverage);
    ``cross_section`` is always returned. Only what is requested is computed and read
    back. Batches are split into chunks that fit the device; results equal single calls.
    ``device``: ``"auto"``, ``"cpu"`` (lavapipe) or ``"gpu"`` (see :func:`device_info`).
    """
    if not isinstance(scene, Scene):
        raise Error(f"invalid scene of type {type(scene).__name__}: expected pprender.Scene")
    if not isinstance(sensor, Lidar):
        raise Error(f"invalid sensor of type {type(sensor).__name__}: expected pprender.Lidar")
    if isinstance(outputs, str):
        outputs = (outputs,)
    bad = [o for o in outputs if o not in _OUTPUTS]
    if bad:
        raise Error(f"invalid outputs {bad}: choose from {_OUTPUTS}")
    if "mueller" in outputs and sensor.polarization is not None:
        raise Error(
            'invalid outputs: "mueller" needs Lidar(polarization=None); with a transmitted '
            'polarization request "stokes"'
        )
    if sensor.intensity_only and ("stokes" in outputs or "mueller" in outputs):
        raise Error('invalid outputs: Lidar(intensity_only=True) renders "intensity" images, not '
                    '"stokes" or "mueller"')
    if "intensity" in outputs and not sensor.intensity_only:
        raise Error('invalid outputs: "intensity" needs Lidar(intensity_only=True, polarization=...)')
    if "stokes" in outputs and sensor.polarization is None:
        raise Error('invalid outputs: "stokes" needs Lidar(polarization=...) (a Stokes vector)')
    for m in scene.materials:
        if abs(m.wavelength - sensor.wavelength) > 1e-6 * sensor.wavelength:
            raise Error(
                f"invalid wavelength = {sensor.wavelength!r}: the scene's material "
                f"{m.name or m!r} was built for {m.wavelength!r} m; build the materials at "
                "the sensor's wavelength"
            )
    if device not in ("auto", "cpu", "lavapipe", "gpu"):
        raise Error(f'invalid device = {device!r}: one of "auto", "cpu" (lavapipe), "gpu"')
    rot = _rotations(attitudes)
    if len(rot) == 0:
        raise Error("invalid attitudes: empty batch (N = 0)")
    reference = sensor.quality == "reference"
    topts: dict[str, Any] = {} if reference else dict(sensor.table_options())
    if sensor.brdf == "shader":
        topts["in_shader"] = True
    t_tables = 0.0 if reference else float(scene._core.prepare(float(sensor.bistatic_angle), **topts))
    res = sensor.effective_resolution(scene.radius)
    _check_framing(scene, res * int(sensor.supersampling))
    pol = None if sensor.polarization is None else [float(x) for x in sensor.polarization]
    d = scene._core.render(
        rot,
        resolution=res,
        supersampling=int(sensor.supersampling),
        samples=sensor.effective_pixel_samples(),
        bistatic_angle=float(sensor.bistatic_angle),
        polarization=pol,
        intensity_only=bool(sensor.intensity_only),
        sigma_range=sensor.sigma_range,
        bin_width=sensor.effective_bin_width(),
        image=("mueller" in outputs or "stokes" in outputs or "intensity" in outputs),
        range="range" in outputs,
        profile="profile" in outputs,
        device="reference" if reference else ("twin" if sensor.effective_arithmetic() == "f64" else device),
        pulse_samples=None if sensor.pulse_samples is None else list(sensor.pulse_samples),
        pulse_spacing=sensor.pulse_spacing_range if sensor.sampled else 0.0,
        analytic=sensor.coverage == "analytic",
        **topts,
    )
    n = len(rot)
    mueller_out = pol is None
    tot = d["total"]
    r = RenderResult(
        cross_section=tot.reshape(n, 4, 4) if mueller_out else (tot[:, 0] if sensor.intensity_only else tot),
        bin_edges=d["bin_edges"],
        pixel_size=float(d["pixel_size"]),
        extent=float(d["extent"]),
        device=str(d["device"]),
        table_seconds=t_tables,
        wavelength=float(sensor.wavelength),
    )
    if "profile" in d:
        p = d["profile"]
        r.profile = p.reshape(n, p.shape[1], 4, 4) if mueller_out else (p[..., 0] if sensor.intensity_only else p)
    if "image" in d:
        img = d["image"]
        if mueller_out:
            r.mueller = img.reshape(img.shape[:3] + (4, 4))
        else:
            if sensor.intensity_only:
                r.intensity = img[..., 0]
            else:
                r.stokes = img
    if "range" in d:
        r.range = d["range"]
        r.coverage = d["coverage"]
    return r
