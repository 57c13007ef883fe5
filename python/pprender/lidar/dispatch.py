"""One render call: attitudes checked and converted, the sensor's settings resolved, the
scene's tables prepared, the request handed to the Rust renderer and its arrays shaped
into a :class:`~pprender.lidar.result.RenderResult`."""

from __future__ import annotations

from typing import Any, Callable, Sequence

import numpy as np

from .. import _core
from .._core import Error
from .result import _OUTPUTS, RenderResult
from .scene import Scene
from .sensor import Lidar
from .settings import Settings


def device_info(device: str = "auto") -> dict[str, Any]:
    """Which adapter renders: name, backend, device type, driver and the limits used.

    Parameters
    ----------
    device : {"auto", "cpu", "gpu"}, optional
        ``"auto"`` (default: a GPU when present, else the CPU implementation lavapipe),
        ``"cpu"`` (lavapipe even when a GPU is present) or ``"gpu"`` (an error without one).

    Returns
    -------
    dict
        The adapter's ``name``, ``backend``, ``device_type``, ``driver``, ``driver_info`` and
        the limits used (``max_storage_buffer_binding_size``, ``max_texture_array_layers``,
        ``max_texture_dimension_2d``), and ``raster_views``: the attitudes (or visibility
        samples) one raster pass draws (the device's multiview view count, at most 32; 1
        without multiview; the environment variable ``PPRENDER_RASTER_VIEWS`` caps it).

    Raises
    ------
    pprender.Error
        For ``device="gpu"`` on a machine without one, or an unknown ``device``.
    """
    return dict(_core.device_info(device))


def _attitude_array(attitudes: Any) -> np.ndarray:
    """``attitudes`` as a float64 array of (N, 4) quaternions ``(w, x, y, z)`` or (N, 3, 3)
    rotation matrices, shapes checked (a single one becomes a batch of one; a scipy
    Rotation its quaternions). Their values are checked where they are used: by the
    renderer, or :func:`_rotations`."""
    from ..inverse.so3 import scipy_quaternions

    q = scipy_quaternions(attitudes)
    if q is not None:
        attitudes = q.reshape(-1, 4)
    try:
        a = np.asarray(attitudes, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise Error(f"invalid attitudes: not a float array ({e})") from None
    if a.shape in ((4,), (3, 3)):
        a = a[None]
    if (a.ndim == 2 and a.shape[1] == 4) or (a.ndim == 3 and a.shape[1:] == (3, 3)):
        return np.ascontiguousarray(a)
    raise Error(
        f"invalid attitudes: shape {a.shape}; expected (N, 4) quaternions (w, x, y, z), "
        "(N, 3, 3) rotation matrices or a scipy Rotation"
    )


def _rotations(attitudes: Any) -> np.ndarray:
    """(N, 3, 3) rotation matrices (body to telescope) from any accepted ``attitudes``."""
    a = _attitude_array(attitudes)
    if a.ndim == 2:
        return np.asarray(_core.quaternions_to_rotations(a))
    if not np.all(np.isfinite(a)):
        raise Error("invalid attitudes: non-finite rotation matrix entries")
    return a


class OffCentreWarning(UserWarning):
    """The mesh lies far from the body origin (the rotation centre, range reference and image centre).

    Most of each image and range window is empty, and attitudes swing the mesh about a point
    outside it. Usually a CAD model exported in another frame. :func:`render` warns when the
    mesh's bounding-box centre is farther from the body origin than the mesh's own size.
    """


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


class _Bar:
    """A ``tqdm.auto`` bar fed by the renderer's ``progress(done, total)`` reports, which
    may come from worker threads out of order (the bar only moves forward) and repeat the
    final count (the thin-pixel pass after a device's last chunk)."""

    def __init__(self, total: int) -> None:
        try:
            from tqdm.auto import tqdm
        except ImportError:
            raise Error("invalid progress = True: the progress bar needs tqdm (pip install tqdm, or the "
                        '"inverse" extra); pass a callable progress(done, total) instead') from None
        self._tqdm = tqdm(total=total, unit="attitude", desc="render", dynamic_ncols=True)

    def report(self, done: int, total: int) -> None:
        if total != self._tqdm.total:
            self._tqdm.total = total
        if done > self._tqdm.n:
            self._tqdm.update(done - self._tqdm.n)

    def complete(self) -> None:
        """The render returned: every attitude is done (a convex mesh's paths pass, which
        traces nothing, reports nothing)."""
        self.report(self._tqdm.total, self._tqdm.total)

    def close(self) -> None:
        self._tqdm.close()


def render(
    scene: Scene,
    sensor: Lidar,
    attitudes: Any,
    outputs: Sequence[str] = ("profile", "mueller", "range"),
    *,
    device: str = "auto",
    settings: Settings | None = None,
    progress: bool | Callable[[int, int], object] | None = None,
) -> RenderResult:
    """Render ``scene`` seen by ``sensor`` at every attitude, as one batch.

    Only what is requested is computed and read back. Batches are split into chunks that fit
    the device; results equal single calls.

    Parameters
    ----------
    scene : Scene
        The mesh and its materials, built at the sensor's wavelength.
    sensor : Lidar
        The laser, receiver and render settings.
    attitudes : array_like or scipy.spatial.transform.Rotation
        (N, 4) unit quaternions ``(w, x, y, z)`` (scalar first), (N, 3, 3) rotation matrices
        or a ``scipy.spatial.transform.Rotation``, body to telescope (module docstring).
    outputs : sequence of str, optional
        Any of ``"profile"``, ``"mueller"`` (needs ``polarization=None``), ``"stokes"``
        (needs a ``polarization``), ``"intensity"`` (needs ``intensity_only=True``),
        ``"range"`` (range map and coverage), ``"illuminated_area"`` (the effective
        illuminated area per range bin, :attr:`RenderResult.illuminated_area`, accumulated
        beside the profile, which it needs: the profile is computed for it and returned
        only when asked for too); ``cross_section`` is always returned. Default
        ``("profile", "mueller", "range")``.
    device : {"auto", "cpu", "gpu"}, optional
        ``"auto"`` (default), ``"cpu"`` (lavapipe) or ``"gpu"`` (see :func:`device_info`).
    settings : Settings, optional
        How to compute it (quality, resolution, samples, tables, arithmetic, ``bounces``):
        these replace the sensor's own (:attr:`Lidar.settings`), so one sensor can be
        rendered at several settings. Default: the sensor's. With ``bounces`` > 1 the light
        reflected between parts is added (traced on the CPU for every device) and
        ``RenderResult.by_bounce`` splits the outputs by the number of reflections.
    progress : bool or callable, optional
        ``True`` shows a progress bar on stderr (``tqdm.auto``: a widget in notebooks),
        counting attitudes; ``None`` or ``False`` (default) shows nothing. A callable is
        called as ``progress(done, total)`` as attitudes are done (after each chunk on a
        device, after each attitude on the CPU, then from worker threads and possibly out
        of order; with ``bounces`` > 1 the paths are a second pass, counted in
        ``total = 2 N``), e.g. to update a bar of your own. An exception it raises stops
        the render and propagates. Ctrl-C (KeyboardInterrupt), with or without
        ``progress``, stops the render at the next such report on every backend (after the
        device chunk, CPU attitude or path-traced attitude in progress; while the CPU shades
        the pixels with parts thinner than a pixel after a device's last chunk, the callback
        is called again with ``done`` equal to the device's count). The materials' tables,
        built on first use before any attitude, are not interrupted.

    Returns
    -------
    RenderResult
        The requested arrays and the cross-sections.

    Raises
    ------
    pprender.Error
        For a mesh too small for the image's pixels (under 2 across: it lies far from the body
        origin, or the resolution is tiny), outputs the sensor cannot give, materials built
        at another wavelength than the sensor's (beyond 1e-6 relative), an empty or invalid
        batch of attitudes, an unknown ``device``, or inter-reflections that would not fit
        in the memory available (naming ``bounces``).

    Warns
    -----
    OffCentreWarning
        For a mesh far from the body origin.
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
    if progress is not None and not isinstance(progress, bool) and not callable(progress):
        raise Error(f"invalid progress of type {type(progress).__name__}: True, False, None or a callable "
                    "progress(done, total)")
    rot = _attitude_array(attitudes)
    if len(rot) == 0:
        raise Error("invalid attitudes: empty batch (N = 0)")
    if settings is None:
        settings = sensor.settings
    elif not isinstance(settings, Settings):
        raise Error(f"invalid settings of type {type(settings).__name__}: expected pprender.Settings")
    st = settings
    reference = st.quality == "reference"
    topts: dict[str, Any] = {} if reference else dict(st.table_options())
    if st.brdf == "shader":
        topts["in_shader"] = True
    res = st.effective_resolution(scene.radius, sensor.range_fwhm)
    _check_framing(scene, res * int(st.supersampling))
    pol = None if sensor.polarization is None else [float(x) for x in sensor.polarization]
    request = _core.RenderRequest(
        resolution=res,
        supersampling=int(st.supersampling),
        samples=st.effective_pixel_samples(),
        bistatic_angle=float(sensor.bistatic_angle),
        polarization=pol,
        intensity_only=bool(sensor.intensity_only),
        sigma_range=sensor.sigma_range,
        bin_width=sensor.effective_bin_width(),
        image=("mueller" in outputs or "stokes" in outputs or "intensity" in outputs),
        range="range" in outputs,
        profile="profile" in outputs or "illuminated_area" in outputs,
        illuminated_area="illuminated_area" in outputs,
        device="reference" if reference else ("twin" if st.effective_arithmetic() == "f64" else device),
        pulse_samples=None if sensor.pulse_samples is None else list(sensor.pulse_samples),
        pulse_spacing=sensor.pulse_spacing_range if sensor.sampled else 0.0,
        analytic=st.coverage == "analytic",
        bounces=int(st.bounces),
        path_samples=st.effective_path_samples(),
        path_seed=int(st.path_seed),
        **topts,
    )
    bar = _Bar(len(rot) * (2 if st.bounces > 1 else 1)) if progress is True else None
    try:
        report = bar.report if bar is not None else (progress if callable(progress) else None)
        d = scene._core.render(rot, request, progress=report)
        if bar is not None:
            bar.complete()
    finally:
        if bar is not None:
            bar.close()
    n = len(rot)
    mueller_out = pol is None
    tot = d["total"]
    r = RenderResult(
        cross_section=tot.reshape(n, 4, 4) if mueller_out else (tot[:, 0] if sensor.intensity_only else tot),
        bin_edges=d["bin_edges"],
        pixel_size=float(d["pixel_size"]),
        extent=float(d["extent"]),
        device=str(d["device"]),
        table_seconds=float(d["table_seconds"]),
        stage_seconds={str(k): float(v) for k, v in d["stage_seconds"].items()},
        wavelength=float(sensor.wavelength),
    )
    if "profile" in outputs:
        p = d["profile"]
        r.profile = p.reshape(n, p.shape[1], 4, 4) if mueller_out else (p[..., 0] if sensor.intensity_only else p)
    if "area_moment" in d:
        # A_j = P_j^2 / Q_j with P_j the single-bounce S0 profile (channel 0 in every
        # layout; the direct part of by_bounce with inter-reflections)
        s0 = d["bounce_profile"][:, 0, :, 0] if "bounce_profile" in d else d["profile"][..., 0]
        r.illuminated_area = _area(s0, d["area_moment"])
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
    if "bounce_total" in d:
        bt = d["bounce_total"]
        k = bt.shape[1]
        by: dict[str, np.ndarray] = {
            "cross_section": bt.reshape(n, k, 4, 4) if mueller_out else (bt[..., 0] if sensor.intensity_only else bt)
        }
        if "bounce_profile" in d and "profile" in outputs:
            p = d["bounce_profile"]
            by["profile"] = (p.reshape(p.shape[:3] + (4, 4)) if mueller_out
                             else (p[..., 0] if sensor.intensity_only else p))
        if "bounce_image" in d:
            img = d["bounce_image"]
            if mueller_out:
                by["mueller"] = img.reshape(img.shape[:4] + (4, 4))
            elif sensor.intensity_only:
                by["intensity"] = img[..., 0]
            else:
                by["stokes"] = img
        r.by_bounce = by
    return r


def _area(s0: np.ndarray, moment: np.ndarray) -> np.ndarray:
    """The illuminated area per bin ``P^2 / Q`` from the single-bounce ``S0`` profile ``P``
    and the area moment ``Q`` (both (N, B)); 0 where ``Q`` is 0 or ``P`` is not positive."""
    p = np.asarray(s0, dtype=np.float64)
    q = np.asarray(moment, dtype=np.float64)
    out = np.zeros_like(q)
    ok = (q > 0) & (p > 0)
    out[ok] = p[ok] ** 2 / q[ok]
    return out
