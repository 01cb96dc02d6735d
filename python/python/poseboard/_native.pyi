# Types of the compiled module (python/src). Arrays cross as the native-endian bytes of
# C-contiguous numpy arrays; poseboard/__init__.py builds them and is the public API.

from typing import Callable, Optional, Union
import os
import pathlib

EVALUATOR_VERSION: str

Rt = tuple[list[float], list[float]]

class Dataset:
    def __init__(
        self, path: Union[str, os.PathLike[str]], targets_file: Optional[str] = None
    ) -> None: ...
    @property
    def name(self) -> str: ...
    @property
    def root(self) -> pathlib.Path: ...
    @property
    def obj_ids(self) -> list[int]: ...
    def model(self, obj_id: int) -> tuple[bytes, bytes]: ...
    def model_info(
        self, obj_id: int
    ) -> tuple[float, list[list[float]], list[tuple[list[float], list[float]]]]: ...
    def load_depth(self, scene_id: int, im_id: int) -> tuple[bytes, int, int]: ...

def evaluate(
    dataset: Union[Dataset, str],
    protocol: str,
    *,
    results_path: Optional[str] = None,
    results_csv: Optional[bytes] = None,
    threads: Optional[int] = None,
    progress: Optional[Callable[[int, int], object]] = None,
    with_errors: bool = False,
    prepared: Optional[str] = None,
    unprepared: bool = False,
    visib_mode: Optional[str] = None,
    tau: Optional[list[float]] = None,
    tau_normalized: Optional[bool] = None,
    theta: Optional[list[float]] = None,
    delta: Optional[float] = None,
    n_top: Optional[int] = None,
    visib_gt_min: Optional[float] = None,
    max_sym_disc_step: Optional[float] = None,
    extra_errors: list[str] = ...,
    ad_threshold: float = 0.1,
    max_estimates_per_image: Optional[int] = None,
) -> tuple[str, Optional[str]]: ...
def check_results(
    path: str, dataset: Union[Dataset, str, None] = None
) -> dict[str, Union[int, str]]: ...
def results_csv(ids: bytes, score: bytes, r: bytes, t: bytes, time: bytes) -> bytes: ...
def add(est: Rt, gt: Rt, pts: bytes) -> float: ...
def adi(est: Rt, gt: Rt, pts: bytes) -> float: ...
def mssd(est: Rt, gt: Rt, pts: bytes, syms: bytes) -> float: ...
def mspd(est: Rt, gt: Rt, k: list[float], pts: bytes, syms: bytes) -> float: ...
def re(r_est: list[float], r_gt: list[float]) -> float: ...
def te(t_est: list[float], t_gt: list[float]) -> float: ...
def vsd(
    est: Rt,
    gt: Rt,
    depth: bytes,
    width: int,
    height: int,
    k: list[float],
    delta: float,
    taus: list[float],
    normalized_by_diameter: bool,
    diameter: float,
    pts: bytes,
    faces: bytes,
    visib_mode: str,
) -> list[float]: ...
def symmetry_transformations_of(
    symmetries_discrete: list[list[float]],
    symmetries_continuous: list[tuple[list[float], list[float]]],
    max_sym_disc_step: float,
) -> list[Rt]: ...
