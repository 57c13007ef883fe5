# Hand-written stubs for the compiled extension pprender._core (checked by
# mypy.stubtest in tests/test_stubs.py). Public documentation lives in the
# pure-Python modules that wrap these functions.

import os
import pathlib
from collections.abc import Sequence
from typing import Callable, Any, final

import numpy as np
import numpy.typing as npt

__version__: str
MODEL_VERSION: int

class Error(ValueError): ...

@final
class Material:
    """A polarized microfacet material.

    The parameters, their ranges and defaults are documented once, on the class in the
    extension (``src/python/brdf.rs``): ``help(pprender.Material)``.
    """

    def __new__(
        cls,
        distribution: str = "blinn_phong",
        *,
        m: float | None = None,
        alpha: float | None = None,
        eta: complex = ...,
        shadowing: str = "aps",
        correlation: str | None = None,
        smith_g1: str = "exact",
        masking: str = "table",
        terms: Sequence[str] = ...,
        diffuse_albedo: float = 0.0,
        name: str | None = None,
        double_order: int = ...,
        coherent_backscatter: bool = True,
        double_masking: str = "seed",
        wavelength: float = ...,
        correlation_length: float = ...,
        orders: str = "seed",
        bank_rays: int | None = ...,
        autocorrelation: str = "gaussian",
        alpha_step: float | None = None,
    ) -> Material: ...
    @property
    def distribution(self) -> str: ...
    @property
    def m(self) -> float | None: ...
    @property
    def alpha(self) -> float | None: ...
    @property
    def eta(self) -> complex: ...
    @property
    def shadowing(self) -> str: ...
    @property
    def correlation(self) -> str: ...
    @property
    def smith_g1(self) -> str: ...
    @property
    def masking(self) -> str: ...
    @property
    def terms(self) -> list[str]: ...
    @property
    def diffuse_albedo(self) -> float: ...
    @property
    def name(self) -> str | None: ...
    @property
    def double_order(self) -> int: ...
    @property
    def coherent_backscatter(self) -> bool: ...
    @property
    def double_masking(self) -> str: ...
    @property
    def wavelength(self) -> float: ...
    @property
    def correlation_length(self) -> float: ...
    @property
    def orders(self) -> str: ...
    @property
    def autocorrelation(self) -> str: ...
    @property
    def bank_rays(self) -> int: ...
    @property
    def alpha_step(self) -> float | None: ...
    @property
    def e_avg(self) -> float | None: ...
    @property
    def f_ms(self) -> float: ...

@final
class PathBank:
    """Order >= 2 paths traced on Gaussian random surfaces with a Gaussian or Matern
    height autocorrelation (src/brdf/bank.rs; issue 24)."""

    def __new__(
        cls,
        alpha: float,
        rays: int,
        surfaces: int = 64,
        grid: int = 256,
        correlation_length: float = 8.0,
        seed: int = 1,
        autocorrelation: str = "gaussian",
    ) -> PathBank: ...
    @property
    def albedo(self) -> npt.NDArray[np.float64]: ...
    @property
    def paths(self) -> npt.NDArray[np.uint64]: ...
    def paths_at(self, i: int, n: int = 2) -> npt.NDArray[np.float32]: ...
    @property
    def rays(self) -> int: ...
    @property
    def lost(self) -> int: ...
    @property
    def theta(self) -> list[float]: ...
    def table(self, eta: complex, orders: tuple[int, int] = ..., reciprocal: bool = True) -> OrderTable: ...

@final
class OrderTable:
    """A path bank's Mueller table on (theta_i, theta_o, phi) nodes (src/brdf/bank.rs)."""

    def eval(
        self, wi: npt.NDArray[np.float64], wo: npt.NDArray[np.float64], frame: str = "sp"
    ) -> npt.NDArray[np.float64]: ...
    def mix(self, other: OrderTable, w: float) -> OrderTable: ...
    def mix_alpha(self, other: OrderTable, a_lo: float, a_hi: float, alpha: float) -> OrderTable: ...
    @property
    def data(self) -> npt.NDArray[np.float64]: ...
    def node_albedo(self, i: int) -> float: ...

def set_cache_dir(path: str | os.PathLike[str] | None) -> None: ...
def cache_dir() -> pathlib.Path | None: ...
def prune_cache(all: bool, path: str | os.PathLike[str] | None) -> tuple[int, int, int]: ...
def brdf(
    material: Material, wi: npt.NDArray[np.float64], wo: npt.NDArray[np.float64], frame: str
) -> npt.NDArray[np.float64]: ...
def specular(material: Material, wi: npt.NDArray[np.float64], frame: str) -> npt.NDArray[np.float64]: ...
def albedo(material: Material, cos_theta_i: npt.NDArray[np.float64], order: int) -> npt.NDArray[np.float64]: ...
def double_jones(
    material: Material,
    wi: tuple[float, float, float] | Sequence[float],
    wo: tuple[float, float, float] | Sequence[float],
    h1: tuple[float, float, float] | Sequence[float],
    frame: str,
) -> tuple[list[list[complex]], list[float], list[float]] | None: ...
def cbe_gamma(
    material: Material, wi: tuple[float, float, float] | Sequence[float], wo: tuple[float, float, float] | Sequence[float]
) -> float: ...

# polarimetry
def polarimetry_dop(stokes: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
def polarimetry_dolp(stokes: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
def polarimetry_docp(stokes: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
def polarimetry_diattenuation(mueller: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
def polarimetry_diattenuation_vector(mueller: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
def polarimetry_polarizance(mueller: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
def polarimetry_polarizance_vector(mueller: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
def polarimetry_depolarization_index(mueller: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
def polarimetry_linear_depolarization_ratio(mueller: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
def polarimetry_circular_depolarization_ratio(mueller: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
def polarimetry_lu_chipman(
    mueller: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
def polarimetry_retardance(
    mueller: npt.NDArray[np.float64],
) -> tuple[
    npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]
]: ...
def polarimetry_cloude_eigenvalues(mueller: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
def polarimetry_is_physical(mueller: npt.NDArray[np.float64], tol: float = 1e-9) -> npt.NDArray[np.bool_]: ...

# microfacet (exact references and the seed's approximations)
def wallis(m: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
def wallis_factorial(m: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
def _wallis_lgamma(m: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
def seed_wallis(m: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
def incomplete_cos_pow(m: npt.ArrayLike, alpha: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
def _incomplete_cos_pow_beta_reg(m: npt.ArrayLike, alpha: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
def seed_incomplete_cos_pow(
    m: npt.ArrayLike, alpha: npt.ArrayLike, exact_wallis: bool = False
) -> npt.NDArray[np.float64]: ...
def seed_incomplete_cos_pow_printed(m: npt.ArrayLike, alpha: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
def seed_hk_plus(m: npt.ArrayLike, theta_k: npt.ArrayLike, exact_wallis: bool = False) -> npt.NDArray[np.float64]: ...
def seed_hk_plus_printed(m: npt.ArrayLike, theta_k: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
def seed_aps_p(m: npt.ArrayLike, theta_k: npt.ArrayLike, exact_wallis: bool = False) -> npt.NDArray[np.float64]: ...
def hk_plus_eq18(m: npt.ArrayLike, theta_k: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
def hk_plus(
    theta_k: npt.ArrayLike,
    distribution: str = "blinn_phong",
    m: npt.ArrayLike | None = None,
    alpha: npt.ArrayLike | None = None,
) -> npt.NDArray[np.float64]: ...
def aps_masking(
    theta_k: npt.ArrayLike,
    distribution: str = "blinn_phong",
    m: npt.ArrayLike | None = None,
    alpha: npt.ArrayLike | None = None,
) -> npt.NDArray[np.float64]: ...
def smith_g1(
    theta_k: npt.ArrayLike,
    distribution: str,
    m: npt.ArrayLike | None = None,
    alpha: npt.ArrayLike | None = None,
    variant: str = "exact",
) -> npt.NDArray[np.float64]: ...

# explicit-microsurface reference (src/reference)
def reference_microsurface(
    wi: npt.NDArray[np.float64],
    wo: npt.NDArray[np.float64],
    alpha: float | None,
    eta: complex,
    rays: int,
    grid: int,
    correlation_length: float,
    cone: float,
    max_order: int,
    frame: str,
    seed: int,
    batches: int,
    heights: npt.NDArray[np.float64] | None = None,
    wavelength: float | None = None,
    bistatic: npt.NDArray[np.float64] | None = None,
) -> dict[str, Any]: ...
def reference_height_field(
    alpha: float, grid: int, correlation_length: float, seed: int, batch: int
) -> dict[str, Any]: ...
def monostatic_table(
    material: Material, nodes: int = 64, double_order: int = 48, measure: bool = True
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], float, float | None]: ...
@final
class BrdfTable:
    """The total Mueller BRDF tabulated for the renderer (src/brdf/table.rs, docs/render-table.md)."""

    def eval(self, theta: float, psi: float) -> npt.NDArray[np.float64]: ...
    def eval_dirs(
        self, wi: tuple[float, float, float] | Sequence[float], wo: tuple[float, float, float] | Sequence[float]
    ) -> npt.NDArray[np.float64]: ...
    def max_error(self, theta_max: float = ..., dynamic_range: float = ...) -> dict[str, Any]: ...
    @property
    def build_seconds(self) -> float: ...
    @property
    def bistatic_angle(self) -> float: ...
    @property
    def frame(self) -> str: ...
    @property
    def kinds(self) -> list[str]: ...
    @property
    def cos_weighted(self) -> list[bool]: ...
    def arrays(self) -> list[tuple[float, int, int, npt.NDArray[np.float64]]]: ...

def brdf_table(
    material: Material,
    bistatic_angle: float = 0.0,
    n_z: int | None = None,
    n_psi: int | None = None,
    double_order: int | None = None,
    *,
    n_z_lambertian: int | None = None,
    n_psi_lambertian: int | None = None,
    n_z_double: int | None = None,
    n_psi_double: int | None = None,
    scale: float | None = None,
    scale_lambertian: float | None = None,
    scale_double: float | None = None,
    frame: str = "bisector",
) -> BrdfTable: ...

@final
class RenderScene:
    """Mesh + materials + cached GPU tables (wrapped by ``pprender.Scene``)."""

    def __new__(
        cls,
        vertices: npt.NDArray[np.float64],
        faces: npt.NDArray[np.int64],
        face_material: npt.NDArray[np.int64],
        materials: list[Material],
        normals: npt.NDArray[np.float64] | None = None,
    ) -> RenderScene: ...
    @property
    def radius(self) -> float: ...
    @property
    def bounds(self) -> tuple[list[float], list[float]]: ...
    @property
    def n_faces(self) -> int: ...
    def thin_pixels(self, rotations: npt.NDArray[np.float64], width: int) -> npt.NDArray[np.bool_]: ...
    def prepare(
        self,
        bistatic_angle: float,
        *,
        n_z: int | None = None,
        n_psi: int | None = None,
        n_z_lambertian: int | None = None,
        n_psi_lambertian: int | None = None,
        n_z_double: int | None = None,
        n_psi_double: int | None = None,
        double_order: int | None = None,
        in_shader: bool = False,
    ) -> float: ...
    def render(
        self,
        rotations: npt.NDArray[np.float64],
        request: RenderRequest,
        *,
        progress: Callable[[int, int], object] | None = None,
    ) -> dict[str, Any]: ...

@final
class RenderRequest:
    """What to render and on what: sensor set-up, outputs, backend, table grid (checked once)."""

    def __new__(
        cls,
        *,
        resolution: int,
        supersampling: int,
        samples: int,
        bistatic_angle: float,
        polarization: Sequence[float] | None,
        intensity_only: bool,
        sigma_range: float,
        bin_width: float,
        image: bool,
        range: bool,
        profile: bool,
        device: str,
        pulse_samples: Sequence[float] | None = None,
        pulse_spacing: float = 0.0,
        analytic: bool = False,
        n_z: int | None = None,
        n_psi: int | None = None,
        n_z_lambertian: int | None = None,
        n_psi_lambertian: int | None = None,
        n_z_double: int | None = None,
        n_psi_double: int | None = None,
        double_order: int | None = None,
        in_shader: bool = False,
        bounces: int = 1,
        path_samples: int = 16,
        path_seed: int = 0,
        illuminated_area: bool = False,
    ) -> RenderRequest: ...

def quaternions_to_rotations(q: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
def sample_offsets(k: int) -> npt.NDArray[np.float64]: ...
def device_info(device: str = "auto") -> dict[str, Any]: ...
def ray_cast(
    vertices: npt.NDArray[np.float64],
    faces: npt.NDArray[np.int64],
    origins: npt.NDArray[np.float64],
    directions: npt.NDArray[np.float64],
    t_min: float = 0.0,
    device: str = "f64",
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]: ...
def ray_cast_timed(
    vertices: npt.NDArray[np.float64],
    faces: npt.NDArray[np.int64],
    origins: npt.NDArray[np.float64],
    directions: npt.NDArray[np.float64],
    t_min: float = 0.0,
    device: str = "f64",
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], dict[str, float]]: ...
