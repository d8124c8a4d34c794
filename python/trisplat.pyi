"""trisplat: Gaussian avatars bound to triangle meshes, on the CPU (type stubs).

Arrays returned are the library's buffers handed to numpy without a copy; arrays passed in are
converted to the documented dtype when needed (``np.asarray``) and copied once into the
library. Library errors raise ``TrisplatError`` with the library's message.
"""

import os
from typing import Any, Dict, List, Literal, Optional, Sequence, Tuple, Union, final

import numpy as np
import numpy.typing as npt

__version__: str

_PathLike = Union[str, "os.PathLike[str]"]
_ArrayLike = npt.ArrayLike
_F32 = npt.NDArray[np.float32]
_F64 = npt.NDArray[np.float64]
_U32 = npt.NDArray[np.uint32]

class TrisplatError(Exception):
    """An error of the trisplat library; the message names the file, element or option at fault."""

@final
class Mesh:
    """A triangle mesh: float64 ``(N, 3)`` vertices, uint32 ``(M, 3)`` triangles, optional
    float32 per-vertex ``normals`` ``(N, 3)``, ``uvs`` ``(N, 2)``, ``colors`` RGBA ``(N, 4)``."""

    def __new__(
        cls,
        vertices: _ArrayLike,
        triangles: _ArrayLike,
        normals: Optional[_ArrayLike] = None,
        uvs: Optional[_ArrayLike] = None,
        colors: Optional[_ArrayLike] = None,
    ) -> "Mesh": ...
    @property
    def vertices(self) -> _F64: ...
    @property
    def triangles(self) -> _U32: ...
    @property
    def normals(self) -> Optional[_F32]: ...
    @property
    def uvs(self) -> Optional[_F32]: ...
    @property
    def colors(self) -> Optional[_F32]: ...
    @property
    def vertex_count(self) -> int: ...
    @property
    def triangle_count(self) -> int: ...
    def area(self) -> float:
        """Surface area (float64 sum of the triangle areas)."""
    def volume(self) -> float:
        """Signed volume (positive for a closed mesh with outward faces)."""
    def stats(self) -> Dict[str, Any]:
        """The mesh's structure, as ``eval``'s ``pred_structure``: vertices, triangles, area, components,
        largest_component_area_fraction, boundary_edges, non_manifold_edges, watertight,
        winding_consistent."""

@final
class PointCloud:
    """Points: float32 ``(N, 3)``, optional float32 ``normals`` ``(N, 3)`` and RGBA ``colors``
    ``(N, 4)``."""

    def __new__(
        cls, points: _ArrayLike, normals: Optional[_ArrayLike] = None, colors: Optional[_ArrayLike] = None
    ) -> "PointCloud": ...
    @property
    def points(self) -> _F32: ...
    @property
    def normals(self) -> Optional[_F32]: ...
    @property
    def colors(self) -> Optional[_F32]: ...
    def __len__(self) -> int: ...

@final
class Gaussians:
    """Gaussians (3DGS conventions): means ``(N, 3)``, natural-log scales ``(N, 3)``, ``w, x, y,
    z`` rotations ``(N, 4)``, opacity logits ``(N,)``, SH ``(N, 3 (degree + 1)²)`` in INRIA PLY
    order, all float32; ``binding`` uint32 ``(N,)`` or None; ``local``: parameters in the bound
    triangles' frames."""

    def __new__(
        cls,
        means: _ArrayLike,
        log_scales: _ArrayLike,
        rotations: _ArrayLike,
        opacity_logits: _ArrayLike,
        sh: Optional[_ArrayLike] = None,
        binding: Optional[_ArrayLike] = None,
        local: bool = False,
        surfels: bool = False,
    ) -> "Gaussians": ...
    @property
    def means(self) -> _F32: ...
    @property
    def log_scales(self) -> _F32: ...
    @property
    def rotations(self) -> _F32: ...
    @property
    def opacity_logits(self) -> _F32: ...
    @property
    def sh(self) -> _F32: ...
    @property
    def binding(self) -> Optional[_U32]: ...
    @property
    def sh_degree(self) -> int: ...
    @property
    def surfels(self) -> bool: ...
    @property
    def local(self) -> bool: ...
    @property
    def extra_names(self) -> List[str]:
        """The file's per-Gaussian properties beyond the standard ones (kept for writing)."""
    def __len__(self) -> int: ...

@final
class Camera:
    """A pinhole camera (OpenCV axes); ``rotation`` is camera-to-world, its columns the
    camera's axes in world space."""

    def __new__(
        cls,
        width: int,
        height: int,
        fx: float,
        fy: float,
        cx: float,
        cy: float,
        rotation: _ArrayLike,
        position: _ArrayLike,
        name: str = "",
        id: int = 0,
    ) -> "Camera": ...
    @staticmethod
    def look_at(
        eye: _ArrayLike,
        target: _ArrayLike,
        width: int,
        height: int,
        fov_y: float = 40.0,
        up: Optional[_ArrayLike] = None,
        name: str = "camera",
    ) -> "Camera": ...
    @property
    def name(self) -> str: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def fx(self) -> float: ...
    @property
    def fy(self) -> float: ...
    @property
    def cx(self) -> float: ...
    @property
    def cy(self) -> float: ...
    @property
    def rotation(self) -> _F64: ...
    @property
    def position(self) -> _F64: ...

@final
class Deformer:
    """Deforms bound Gaussians with a template frame after frame (``"binding"`` or
    ``"jacobian"``)."""

    def __new__(cls, template: Mesh, mode: Literal["binding", "jacobian"] = "binding") -> "Deformer": ...
    def deform(self, gaussians: Gaussians, vertices: _ArrayLike) -> Gaussians:
        """World-space Gaussians with the template's vertices at ``vertices`` (float64 ``(V, 3)``)."""

@final
class Session:
    """The main job of ``trisplat extract`` frame by frame, meshes in memory. ``template`` may
    be a LAM avatar folder (as ``extract --avatar``)."""

    def __new__(
        cls,
        template: _PathLike,
        animation: Optional[str] = None,
        gaussians: Optional[_PathLike] = None,
        methods: Sequence[Literal["tsdf", "delaunay", "alpha"]] = ("delaunay",),
        frames: Optional[str] = None,
        gt: Optional[str] = None,
        mode: Literal["binding", "jacobian", "lbs"] = "binding",
        per_triangle: Optional[int] = None,
        voxel: Optional[float] = None,
        views: Optional[int] = None,
        resolution: Optional[int] = None,
        alpha: Optional[float] = None,
        hop_threshold: Optional[float] = None,
        samples: Optional[int] = None,
        tau_fraction: Optional[float] = None,
        gt_sequence: Optional[str] = None,
        clip: Optional[str] = None,
        clip_from: Optional[_PathLike] = None,
        fps: Optional[float] = None,
        layout: Literal["bound", "lam"] = "bound",
        tsdf_depth: Literal["median", "expected"] = "median",
        tsdf_splat_depth: Literal["ray", "mean"] = "ray",
        tsdf_colors: bool = False,
        alpha_keep_clusters: int = 0,
        rebuild_every: int = 0,
        tau: Optional[float] = None,
        strict: bool = False,
        tsdf_alpha_cut: Optional[float] = None,
        min_contribution: Optional[float] = None,
        floater_std_ratio: Optional[float] = None,
        floater_neighbors: Optional[int] = None,
        topology: Literal["per-frame", "fixed", "adaptive"] = "adaptive",
    ) -> "Session": ...
    @property
    def unused_channels(self) -> List[str]: ...
    @property
    def gaussians_used(self) -> Dict[str, Any]:
        """``total``, ``kept``, ``hidden``, ``floaters``, ``poses`` and the rule, as in report.json."""
    @property
    def frames(self) -> List[int]: ...
    @property
    def template(self) -> Mesh: ...
    @property
    def gaussians(self) -> Gaussians: ...
    def positions(self, frame: int) -> _F64:
        """The template's vertices at animation frame ``frame``."""
    def world(self, frame: int) -> Gaussians:
        """The world-space Gaussians of animation frame ``frame``."""
    def frame(self, frame: int) -> Dict[str, Any]:
        """``frame``, ``time``, ``deform_ms`` and ``methods``: per method its frame record as in
        report.json (``ms``, ``render_ms``, ``vertices``, ``faces``, ``watertight``,
        ``metrics``) with ``mesh`` (Mesh) and ``delaunay`` (a dict as in report.json, or None)."""

def read_mesh(path: _PathLike) -> Mesh:
    """Reads a PLY, OBJ or glTF/GLB mesh (by extension)."""

def write_mesh(path: _PathLike, mesh: Mesh, ascii: bool = False) -> None:
    """Writes a mesh atomically (.ply, .obj, .gltf, .glb)."""

def read_points(path: _PathLike) -> PointCloud:
    """Reads a PLY point cloud (or the vertices of a mesh file)."""

def write_points(path: _PathLike, cloud: PointCloud, ascii: bool = False) -> None:
    """Writes a point cloud as PLY, atomically."""

def read_gaussians(path: _PathLike, axes: Optional[str] = "rdf") -> Gaussians:
    """Reads INRIA PLY, SPZ (returned in ``axes``) or glTF ``KHR_gaussian_splatting`` Gaussians."""

def write_gaussians(
    path: _PathLike,
    gaussians: Gaussians,
    ascii: bool = False,
    axes: Optional[str] = "rdf",
    spz_version: int = 3,
) -> None:
    """Writes Gaussians atomically by extension (.ply, .spz, .glb, .gltf)."""

def bind(
    mesh: Mesh,
    per_triangle: int = 1,
    opacity: float = 0.1,
    convention: Literal["gaussian_avatars", "surfhead"] = "gaussian_avatars",
) -> Gaussians:
    """New Gaussians bound to every triangle (GaussianAvatars' initialisation), in local frames."""

def attach(
    gaussians: Gaussians,
    mesh: Mesh,
    convention: Literal["gaussian_avatars", "surfhead"] = "gaussian_avatars",
    checked: bool = True,
) -> Gaussians:
    """World-space Gaussians bound to their nearest triangles (refused when implausible)."""

def deform(
    template: Mesh,
    gaussians: Gaussians,
    vertices: _ArrayLike,
    mode: Literal["binding", "jacobian"] = "binding",
) -> Gaussians:
    """One frame: ``Deformer(template, mode).deform(gaussians, vertices)``."""

def read_cameras(path: _PathLike, size: Optional[Tuple[int, int]] = None) -> List[Camera]:
    """The cameras of a 3DGS cameras.json or a NeRF transforms.json."""

def sphere_rig(
    center: _ArrayLike, radius: float, count: int, width: int, height: int, fov_y: float = 40.0
) -> List[Camera]:
    """``count`` cameras on a Fibonacci sphere around ``center``, framing a ball of ``radius``."""

def render(
    gaussians: Gaussians,
    camera: Camera,
    outputs: Sequence[Literal["rgb", "alpha", "depth", "median_depth", "normal"]] = (
        "rgb",
        "alpha",
        "depth",
        "normal",
    ),
    mode: Literal["3dgs", "2dgs", "perspective"] = "3dgs",
    rules: Literal["gsplat", "original"] = "gsplat",
    background: Tuple[float, float, float] = (0.0, 0.0, 0.0),
    near: float = 0.01,
    far: float = 1e10,
    antialiased: bool = False,
    normal_frame: Literal["world", "camera"] = "world",
    splat_depth: Literal["mean", "ray"] = "mean",
) -> Dict[str, _F32]:
    """Float32 images by name: rgb ``(H, W, 3)``, alpha, depth, median_depth ``(H, W)``,
    normal ``(H, W, 3)``."""

def tsdf(
    cameras: Sequence[Camera],
    depths: Sequence[_ArrayLike],
    colors: Optional[Sequence[_ArrayLike]] = None,
    voxel: Optional[float] = None,
    trunc: Optional[float] = None,
    depth_trunc: Optional[float] = None,
    keep_clusters: int = 1,
) -> Mesh:
    """Fuses one ``(H, W)`` depth map per camera (TSDF, Open3D's rules) into a cleaned mesh."""

def alpha_shape(points: _ArrayLike, alpha: float, keep_clusters: int = 0) -> Mesh:
    """The alpha shape of float32 ``(N, 3)`` points (Open3D's definition), faces outward."""

def delaunay(points: _ArrayLike) -> _U32:
    """The 3D Delaunay tetrahedra of float32 ``(N, 3)`` points: uint32 ``(T, 4)`` indices,
    positive in Shewchuk's orient3d convention."""

def eval(
    pred: Union[_PathLike, Mesh, PointCloud],
    gt: Union[_PathLike, Mesh, PointCloud],
    samples: int = 100_000,
    seed: int = 0,
    taus: Optional[Sequence[float]] = None,
    tau_fractions: Optional[Sequence[float]] = None,
    surface: bool = False,
    max_samples: int = 100_000_000,
) -> Dict[str, Any]:
    """The JSON object of ``trisplat eval --json`` as a dict: command ("eval"), the
    metrics (accuracy, completeness, chamfer_l1, chamfer_l2, normal_consistency,
    normal_angle_deg, n_pred, n_gt, thresholds, seconds), gt_bbox_diagonal, pred_structure,
    gt_structure, area_ratio, shared_vertex_fraction, relation."""

def set_num_threads(n: Optional[int] = None) -> None:
    """Sets the number of worker threads of every later call (the CLI's ``--threads``).
    ``None`` or ``0``: back to the default, all cores (or ``RAYON_NUM_THREADS``). Results do
    not depend on it."""

def get_num_threads() -> int:
    """The number of worker threads calls use now."""
