"""poseboard: the BOP 6D object pose evaluation of the poseboard service, offline.

The numbers are the server's: the same Rust evaluator computes them, so a researcher gets the
leaderboard's scores on a laptop, in seconds, without an OpenGL context::

    import poseboard
    report = poseboard.evaluate("bop/ycbv", "mymethod_ycbv-test.csv")
    print(report["bop19_average_recall"])

The report has the keys of the JSON that ``poseboard eval --out`` writes (bop_toolkit's names
where the quantity is the same). The pose errors (``vsd``, ``mssd``, ``mspd``, ``add``,
``adi``, ``re``, ``te``) take numpy arrays with the signatures of bop_toolkit's ``pose_error``
module, for evaluation loops of one's own.
"""

from __future__ import annotations

import json
import os
from typing import Any, Callable, Iterable, Mapping, Optional, Sequence, Union

import numpy as np

from . import _native

__all__ = [
    "Dataset",
    "evaluate",
    "check_results",
    "vsd",
    "mssd",
    "mspd",
    "add",
    "adi",
    "re",
    "te",
    "get_symmetry_transformations",
    "EVALUATOR_VERSION",
]

#: The version of the evaluator inside, as the report's ``evaluator_version`` gives it.
EVALUATOR_VERSION: str = _native.EVALUATOR_VERSION

PathLike = Union[str, "os.PathLike[str]"]


class Dataset:
    """A BOP dataset folder, loaded once.

    Loading reads every model and the ground truth of the test targets; pass a ``Dataset``
    instead of a folder to :func:`evaluate` to pay for that once when evaluating often (e.g.
    after every training epoch). The folder holds ``models_eval/`` (or ``models/``),
    ``test/`` and ``test_targets_bop19.json``; for ``protocol="bop24"`` load it with
    ``targets_file="test_targets_bop24.json"`` (the images of 6D detection).
    """

    def __init__(self, path: PathLike, targets_file: Optional[str] = None) -> None:
        self._native = _native.Dataset(os.fspath(path), targets_file)

    @property
    def name(self) -> str:
        """The folder name, which is the dataset name in result file names."""
        return self._native.name

    @property
    def path(self) -> str:
        return os.fspath(self._native.root)

    @property
    def obj_ids(self) -> list[int]:
        return self._native.obj_ids

    def model(self, obj_id: int) -> dict[str, np.ndarray]:
        """The object model as bop_toolkit's ``inout.load_ply`` gives it: ``pts`` (n x 3
        float64, mm) and ``faces`` (m x 3 triangle corners), what :func:`vsd` renders."""
        pts, faces = self._native.model(obj_id)
        return {
            "pts": np.frombuffer(pts, dtype=np.float64).reshape(-1, 3),
            "faces": np.frombuffer(faces, dtype=np.uint32).reshape(-1, 3),
        }

    def model_info(self, obj_id: int) -> dict[str, Any]:
        """The object's entry of ``models_info.json``: ``diameter`` and its symmetries, the
        input of :func:`get_symmetry_transformations`."""
        diameter, discrete, continuous = self._native.model_info(obj_id)
        return {
            "diameter": diameter,
            "symmetries_discrete": [list(m) for m in discrete],
            "symmetries_continuous": [
                {"axis": list(axis), "offset": list(offset)} for axis, offset in continuous
            ],
        }

    def load_depth(self, scene_id: int, im_id: int) -> np.ndarray:
        """The depth image of a test image in mm (float32, height x width, 0 = no
        measurement): the PNG scaled by the image's ``depth_scale``, as VSD sees it."""
        data, width, height = self._native.load_depth(scene_id, im_id)
        return np.frombuffer(data, dtype=np.float32).reshape(height, width)

    def __repr__(self) -> str:
        return f"poseboard.Dataset({self.path!r})"


def _dataset_arg(dataset: Union[PathLike, Dataset]) -> Any:
    return dataset._native if isinstance(dataset, Dataset) else os.fspath(dataset)


def _floats(values: Any, n: int, width: int, name: str) -> np.ndarray:
    """``values`` as a C-contiguous n x width float64 array, or a ValueError naming the row."""
    try:
        array = np.asarray(values, dtype=np.float64)
        if array.size == n * width:
            return np.ascontiguousarray(array.reshape(n, width))
    except (TypeError, ValueError):
        pass
    # Rows of different shapes (3x1 and 3, say) or a row of the wrong size: one at a time.
    out = np.empty((n, width))
    for i, v in enumerate(values):
        try:
            row = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise ValueError(f"row {i}: {name} is not numbers ({e})") from None
        if row.size != width:
            raise ValueError(f"row {i}: {name} has {row.size} numbers, expected {width}")
        out[i] = row.reshape(width)
    return out


def _ids(values: Any, name: str) -> np.ndarray:
    array = np.asarray(values)
    if array.dtype.kind in "iu":
        return array.astype(np.int64)
    if array.dtype.kind == "f":
        whole = np.isfinite(array) & (array == np.floor(array))
        if not whole.all():
            i = int(np.argmin(whole))
            raise ValueError(f"row {i}: {name} {array[i]!r} is not an integer")
        return array.astype(np.int64)
    raise ValueError(f"{name} must be integers")


def _rows_csv(results: Any) -> bytes:
    """Rows (mappings, as bop_toolkit's ``inout.load_bop_results`` returns them) or a numpy
    structured array as the text of a result file, so they pass the checks a file passes."""
    rows: Any
    columns: dict[str, Any] = {}
    if isinstance(results, np.ndarray):
        names = results.dtype.names or ()
        missing = [f for f in ("scene_id", "im_id", "obj_id", "score", "R", "t") if f not in names]
        if missing:
            raise ValueError(f"the results array has no field {', '.join(missing)}")
        rows = results.reshape(-1)
        columns = {f: rows[f] for f in names}
        n = len(rows)
        time: Any = columns["time"] if "time" in names else np.full(n, -1.0)
    else:
        rows = list(results)
        n = len(rows)
        for field in ("scene_id", "im_id", "obj_id", "score", "R", "t"):
            try:
                columns[field] = [row[field] for row in rows]
            except KeyError:
                i = next(i for i, row in enumerate(rows) if field not in row)
                raise ValueError(f"row {i} has no {field!r}") from None
        time = [row["time"] if "time" in row else -1.0 for row in rows]
    ids = np.stack([_ids(columns[f], f) for f in ("scene_id", "im_id", "obj_id")], axis=-1).reshape(
        n, 3
    )
    return _native.results_csv(
        np.ascontiguousarray(ids).tobytes(),
        _floats(columns["score"], n, 1, "score").tobytes(),
        _floats(columns["R"], n, 9, "R").tobytes(),
        _floats(columns["t"], n, 3, "t").tobytes(),
        _floats(time, n, 1, "time").tobytes(),
    )


def _floats_list(value: Union[float, Sequence[float], None]) -> Optional[list[float]]:
    if value is None:
        return None
    return [float(v) for v in np.atleast_1d(np.asarray(value, dtype=np.float64))]


def _evaluate_json(
    dataset: Union[PathLike, Dataset],
    results: Any,
    protocol: str = "bop19",
    *,
    threads: Optional[int] = None,
    progress: Optional[Callable[[int, int], Any]] = None,
    with_errors: bool = False,
    prepared: Optional[PathLike] = None,
    unprepared: bool = False,
    visib_mode: Optional[str] = None,
    tau: Union[float, Sequence[float], None] = None,
    tau_normalized: Optional[bool] = None,
    theta: Union[float, Sequence[float], None] = None,
    delta: Optional[float] = None,
    n_top: Optional[int] = None,
    visib_gt_min: Optional[float] = None,
    max_sym_disc_step: Optional[float] = None,
    extra_errors: Union[str, Sequence[str]] = (),
    ad_threshold: float = 0.1,
    max_estimates_per_image: Optional[int] = None,
) -> tuple[str, Optional[str]]:
    """:func:`evaluate`, returning the JSON texts ``poseboard eval`` writes (``--out``, and
    with ``with_errors`` ``--errors-out``)."""
    results_path, results_csv = None, None
    if isinstance(results, (str, os.PathLike)):
        results_path = os.fspath(results)
    else:
        results_csv = _rows_csv(results)
    return _native.evaluate(
        _dataset_arg(dataset),
        protocol,
        threads=threads,
        progress=progress,
        with_errors=with_errors,
        prepared=None if prepared is None else os.fspath(prepared),
        unprepared=unprepared,
        visib_mode=visib_mode,
        tau=_floats_list(tau),
        tau_normalized=tau_normalized,
        theta=_floats_list(theta),
        delta=delta,
        n_top=n_top,
        visib_gt_min=visib_gt_min,
        max_sym_disc_step=max_sym_disc_step,
        extra_errors=[extra_errors] if isinstance(extra_errors, str) else list(extra_errors),
        ad_threshold=ad_threshold,
        max_estimates_per_image=max_estimates_per_image,
        results_path=results_path,
        results_csv=results_csv,
    )


def evaluate(
    dataset: Union[PathLike, Dataset],
    results: Union[PathLike, Iterable[Mapping[str, Any]], np.ndarray],
    protocol: str = "bop19",
    *,
    threads: Optional[int] = None,
    progress: Optional[Callable[[int, int], Any]] = None,
    prepared: Optional[PathLike] = None,
    unprepared: bool = False,
    visib_mode: Optional[str] = None,
    tau: Union[float, Sequence[float], None] = None,
    tau_normalized: Optional[bool] = None,
    theta: Union[float, Sequence[float], None] = None,
    delta: Optional[float] = None,
    n_top: Optional[int] = None,
    visib_gt_min: Optional[float] = None,
    max_sym_disc_step: Optional[float] = None,
    extra_errors: Union[str, Sequence[str]] = (),
    ad_threshold: float = 0.1,
    max_estimates_per_image: Optional[int] = None,
) -> dict[str, Any]:
    """Evaluates pose estimates on a BOP dataset; returns the report ``poseboard eval --out``
    writes, parsed.

    :param dataset: a BOP dataset folder, or a :class:`Dataset` loaded before.
    :param results: a BOP'19 result file (``scene_id,im_id,obj_id,score,R,t,time``); or the
        estimates themselves: an iterable of mappings with those keys (what bop_toolkit's
        ``inout.load_bop_results`` returns; ``R`` 3x3 or 9 numbers, ``t`` 3 numbers, ``time``
        optional, -1 = not measured), or a numpy structured array with those fields. Rows pass
        the checks of a file; in messages, row i is line i + 1.
    :param protocol: ``"bop19"`` (the BOP Challenge's average recall over VSD, MSSD and MSPD),
        ``"eccv18"`` (the paper: VSD recall) or ``"bop24"`` (6D detection: average precision
        from MSSD and MSPD, keys ``bop24_mAP``, ``bop24_mAP_mssd``, ``bop24_mAP_mspd``,
        ``bop24_mAP_mssd_mm``, ``bop25_mAP``, ``bop25_mAP_mm``,
        ``bop24_average_time_per_image``; a folder is read with its
        ``test_targets_bop24.json``, and the options below except ``threads``, ``progress`` and
        ``max_estimates_per_image`` do not apply).
    :param threads: worker threads; default every core.
    :param progress: called as ``progress(done, total)`` (estimates) from the calling thread
        while the evaluation runs, and once at its end. An exception it raises (and Ctrl-C)
        stops the evaluation and is raised here.
    :param prepared: the dataset's prepared form (``poseboard dataset prepare``); by default
        the dataset's ``poseboard_prepared`` folder when there is one. Scores are the same to
        the bit without it; one that is stale, made for other content or damaged is not used
        (a UserWarning says why).
    :param unprepared: compute everything from the dataset even when a prepared form is there.
    :param visib_mode: VSD visibility, ``"bop18"`` (missing depth hides) or ``"bop19"``
        (missing depth shows).
    :param tau: VSD misalignment tolerance(s): mm, or fractions of the diameter when
        normalised.
    :param tau_normalized: whether ``tau`` is a fraction of the object diameter (bop19's
        default) or mm (eccv18's).
    :param theta: VSD threshold(s) of correctness.
    :param delta: VSD visibility tolerance in mm.
    :param n_top: estimates considered per target: N, -1 = as many as instances, 0 = all.
    :param visib_gt_min: minimum visible fraction of a ground-truth instance to be expected
        (-1: the ``inst_count`` most visible instances).
    :param max_sym_disc_step: discretisation of continuous symmetries (fraction of the
        diameter).
    :param extra_errors: also compute ``"add"``, ``"adi"`` and/or ``"ad"`` (ADI for objects with
        declared symmetries, ADD for the others), reported at ``ad_threshold``.
    :param ad_threshold: threshold of correctness of the extra errors, as a fraction of the
        object diameter.
    :param max_estimates_per_image: ``bop24``: estimates kept per image, the best-scored over
        all objects (default: bop_toolkit's, 200 on ``xyzibd`` and 100 elsewhere).

    The GIL is released while the evaluation runs. Raises ValueError for invalid results
    (listing every problem with its line; the list is also in the exception's ``problems``
    attribute as ``(line, message)`` pairs) or parameters, OSError for files that cannot be
    read.
    """
    report, _ = _evaluate_json(
        dataset,
        results,
        protocol,
        threads=threads,
        progress=progress,
        prepared=prepared,
        unprepared=unprepared,
        visib_mode=visib_mode,
        tau=tau,
        tau_normalized=tau_normalized,
        theta=theta,
        delta=delta,
        n_top=n_top,
        visib_gt_min=visib_gt_min,
        max_sym_disc_step=max_sym_disc_step,
        extra_errors=extra_errors,
        ad_threshold=ad_threshold,
        max_estimates_per_image=max_estimates_per_image,
    )
    parsed: dict[str, Any] = json.loads(report)
    return parsed


def check_results(
    path: PathLike, dataset_dir: Union[PathLike, Dataset, None] = None
) -> dict[str, Any]:
    """Validates a BOP'19 result file without evaluating it.

    Raises ValueError listing every problem with its line number (also as ``(line, message)``
    pairs in the exception's ``problems``). Returns ``estimates`` and ``images`` counts; with a
    dataset also ``targets``, ``targets_without_estimate`` and ``estimates_ignored`` (estimates
    for images or objects that are not test targets).
    """
    dataset = None if dataset_dir is None else _dataset_arg(dataset_dir)
    return _native.check_results(os.fspath(path), dataset)


# Pose errors -----------------------------------------------------------------------------


def _mat3(value: Any, name: str) -> list[float]:
    a = np.asarray(value, dtype=np.float64)
    if a.size != 9:
        raise ValueError(f"{name} must be a 3x3 matrix, got shape {a.shape}")
    return a.reshape(9).tolist()


def _vec3(value: Any, name: str) -> list[float]:
    a = np.asarray(value, dtype=np.float64)
    if a.size != 3:
        raise ValueError(f"{name} must have 3 elements, got shape {a.shape}")
    return a.reshape(3).tolist()


def _pose(R: Any, t: Any, which: str) -> tuple[list[float], list[float]]:
    return _mat3(R, f"R_{which}"), _vec3(t, f"t_{which}")


def _points(pts: Any) -> bytes:
    a = np.ascontiguousarray(pts, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] == 0:
        raise ValueError(f"pts must be a non-empty n x 3 array, got shape {a.shape}")
    return a.tobytes()


def _syms(syms: Sequence[Mapping[str, Any]]) -> bytes:
    if len(syms) == 0:
        raise ValueError("syms must hold at least one transformation (the identity)")
    Rs = np.asarray([s["R"] for s in syms], dtype=np.float64).reshape(len(syms), 9)
    ts = np.asarray([s["t"] for s in syms], dtype=np.float64).reshape(len(syms), 3)
    return np.ascontiguousarray(np.hstack([Rs, ts])).tobytes()


def vsd(
    R_est: np.ndarray,
    t_est: np.ndarray,
    R_gt: np.ndarray,
    t_gt: np.ndarray,
    depth_test: np.ndarray,
    K: np.ndarray,
    delta: float,
    taus: Union[float, Sequence[float]],
    normalized_by_diameter: bool,
    diameter: float,
    model: Mapping[str, np.ndarray],
    visib_mode: str = "bop19",
) -> list[float]:
    """Visible Surface Discrepancy (Hodan et al., ECCV'18), one error per tau.

    bop_toolkit's ``pose_error.vsd`` with the model in place of its ``renderer, obj_id``:
    ``model`` has ``pts`` (n x 3) and ``faces`` (m x 3), as bop_toolkit's ``inout.load_ply``
    or :meth:`Dataset.model` give it; the model is rendered on the CPU with the conventions of
    bop_toolkit's renderer. ``depth_test`` is the test depth image in mm (height x width);
    ``visib_mode`` is ``"bop19"`` (bop_toolkit's, missing depth shows) or ``"bop18"`` (the
    paper's). The step cost is used (``cost_type="step"``).

    Unlike the evaluation, this always renders: bop_toolkit's evaluation (and poseboard's) sets
    VSD to 1 without rendering when the projected bounding spheres of the two poses cannot
    overlap.
    """
    depth = np.ascontiguousarray(depth_test, dtype=np.float32)
    if depth.ndim != 2:
        raise ValueError(f"depth_test must be a 2-D image, got shape {depth.shape}")
    faces = np.asarray(model["faces"])
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.dtype.kind not in "iu":
        raise ValueError("model['faces'] must be an m x 3 array of point indices")
    if faces.size and faces.min() < 0:
        raise ValueError("model['faces'] has negative point indices")
    return _native.vsd(
        _pose(R_est, t_est, "est"),
        _pose(R_gt, t_gt, "gt"),
        depth.tobytes(),
        depth.shape[1],
        depth.shape[0],
        _mat3(K, "K"),
        float(delta),
        _floats_list(taus) or [],
        bool(normalized_by_diameter),
        float(diameter),
        _points(model["pts"]),
        np.ascontiguousarray(faces, dtype=np.uint32).tobytes(),
        visib_mode,
    )


def mssd(
    R_est: np.ndarray,
    t_est: np.ndarray,
    R_gt: np.ndarray,
    t_gt: np.ndarray,
    pts: np.ndarray,
    syms: Sequence[Mapping[str, np.ndarray]],
) -> float:
    """Maximum Symmetry-Aware Surface Distance (BOP'19) in mm: the largest distance of a
    model point between the two poses, minimised over ``syms`` (dicts with ``R`` and ``t``,
    from :func:`get_symmetry_transformations` or bop_toolkit's)."""
    return _native.mssd(
        _pose(R_est, t_est, "est"), _pose(R_gt, t_gt, "gt"), _points(pts), _syms(syms)
    )


def mspd(
    R_est: np.ndarray,
    t_est: np.ndarray,
    R_gt: np.ndarray,
    t_gt: np.ndarray,
    K: np.ndarray,
    pts: np.ndarray,
    syms: Sequence[Mapping[str, np.ndarray]],
) -> float:
    """Maximum Symmetry-Aware Projection Distance (BOP'19) in pixels: the largest distance of
    a projected model point between the two poses, minimised over ``syms``."""
    return _native.mspd(
        _pose(R_est, t_est, "est"),
        _pose(R_gt, t_gt, "gt"),
        _mat3(K, "K"),
        _points(pts),
        _syms(syms),
    )


def add(
    R_est: np.ndarray, t_est: np.ndarray, R_gt: np.ndarray, t_gt: np.ndarray, pts: np.ndarray
) -> float:
    """Average Distance of model points (ADD, Hinterstoisser et al.) in mm."""
    return _native.add(_pose(R_est, t_est, "est"), _pose(R_gt, t_gt, "gt"), _points(pts))


def adi(
    R_est: np.ndarray, t_est: np.ndarray, R_gt: np.ndarray, t_gt: np.ndarray, pts: np.ndarray
) -> float:
    """Average distance to the closest model point (ADI or ADD-S, for symmetric objects) in mm."""
    return _native.adi(_pose(R_est, t_est, "est"), _pose(R_gt, t_gt, "gt"), _points(pts))


def re(R_est: np.ndarray, R_gt: np.ndarray) -> float:
    """Rotation error in degrees."""
    return _native.re(_mat3(R_est, "R_est"), _mat3(R_gt, "R_gt"))


def te(t_est: np.ndarray, t_gt: np.ndarray) -> float:
    """Translation error (in the unit of t)."""
    return _native.te(_vec3(t_est, "t_est"), _vec3(t_gt, "t_gt"))


def get_symmetry_transformations(
    model_info: Mapping[str, Any], max_sym_disc_step: float = 0.01
) -> list[dict[str, np.ndarray]]:
    """The symmetry transformations of an object (bop_toolkit's
    ``misc.get_symmetry_transformations``): dicts with ``R`` (3x3) and ``t`` (3x1), the identity
    first, continuous symmetries sampled so that the farthest point moves at most
    ``max_sym_disc_step`` of the diameter per step. ``model_info`` is the object's entry of
    ``models_info.json``."""
    discrete = [
        np.asarray(m, dtype=np.float64).reshape(16).tolist()
        for m in model_info.get("symmetries_discrete", [])
    ]
    continuous = [
        (_vec3(s["axis"], "axis"), _vec3(s["offset"], "offset"))
        for s in model_info.get("symmetries_continuous", [])
    ]
    return [
        {"R": np.array(R).reshape(3, 3), "t": np.array(t).reshape(3, 1)}
        for R, t in _native.symmetry_transformations_of(
            discrete, continuous, float(max_sym_disc_step)
        )
    ]
