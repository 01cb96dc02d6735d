"""``poseboard-eval``: ``poseboard eval`` for those who installed the Python package.

Same flags, same table on stdout, same warnings on stderr, and byte for byte the same JSON in
``--out`` and ``--errors-out`` as the ``poseboard`` command of the service.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any, Optional, Sequence

import numpy as np

from . import _evaluate_json


def _floats(text: str) -> list[float]:
    return [float(v) for v in text.split(",")]


def _bool(text: str) -> bool:
    if text not in ("true", "false"):
        raise argparse.ArgumentTypeError(f"invalid value '{text}' (true or false)")
    return text == "true"


def _extra_errors(text: str) -> list[str]:
    names = text.split(",")
    for name in names:
        if name not in ("add", "adi", "ad"):
            raise argparse.ArgumentTypeError(f"invalid value '{name}' (add, adi or ad)")
    return names


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="poseboard-eval",
        description="Evaluate a BOP'19 result file on a BOP dataset (poseboard eval).",
    )
    p.add_argument(
        "--dataset",
        required=True,
        help="a BOP dataset folder (models/ or models_eval/, test/, test_targets_bop19.json)",
    )
    p.add_argument("--results", required=True, help="a result file in the BOP'19 CSV format")
    p.add_argument("--protocol", default="bop19", choices=["eccv18", "bop19"])
    p.add_argument(
        "--out",
        help="write the full report (every score, the parameters used) as JSON to this file",
    )
    p.add_argument(
        "--errors-out",
        help="write every evaluated estimate's errors against each ground-truth instance as JSON",
    )
    p.add_argument("--threads", type=int, help="worker threads (default: every core)")
    p.add_argument(
        "--visib-mode",
        choices=["bop18", "bop19"],
        help="VSD visibility: bop18 (the paper: missing depth hides) or bop19 (missing depth shows)",
    )
    p.add_argument(
        "--tau",
        type=_floats,
        action="append",
        help="VSD misalignment tolerance(s): mm, or fractions of the diameter when normalised",
    )
    p.add_argument(
        "--tau-normalized",
        type=_bool,
        help="whether --tau is a fraction of the object diameter (bop19's default) or mm (eccv18's)",
    )
    p.add_argument(
        "--theta", type=_floats, action="append", help="VSD threshold(s) of correctness theta"
    )
    p.add_argument("--delta", type=float, help="VSD visibility tolerance delta in mm")
    p.add_argument(
        "--n-top",
        type=int,
        help="estimates considered per target: N, -1 = as many as instances, 0 = all",
    )
    p.add_argument(
        "--visib-gt-min",
        type=float,
        help="minimum visible fraction of a ground-truth instance to be a target (-1: the inst_count most visible instances)",
    )
    p.add_argument(
        "--max-sym-disc-step",
        type=float,
        help="discretisation of continuous symmetries (fraction of the diameter)",
    )
    p.add_argument(
        "--extra-errors",
        type=_extra_errors,
        action="append",
        default=[],
        help="also compute these errors: add, adi, ad (ADI for objects with declared symmetries, ADD for the others), reported at --ad-threshold",
    )
    p.add_argument(
        "--ad-threshold",
        type=float,
        default=0.1,
        help="threshold of correctness of the extra errors, as a fraction of the object diameter",
    )
    return p


def _num(x: float) -> str:
    """A float as Rust's ``{}`` prints it: the shortest text that reads back, never an
    exponent, no ``.0`` on whole numbers."""
    return np.format_float_positional(x, unique=True, trim="-")


def table(r: dict[str, Any]) -> str:
    """The scores as ``poseboard eval`` prints them."""
    lines = [
        f"dataset {r['dataset']}  protocol {r['protocol']}  estimates {r['estimates_count']} "
        f"(evaluated {r['estimates_evaluated']}, ignored {r['estimates_ignored']})"
    ]
    if r["protocol"] == "eccv18":
        if "recall" in r:
            p = r["parameters"]
            lines.append(
                f"VSD recall (tau {_num(p['main_tau'])} mm, theta {_num(p['main_theta'])}): "
                f"{r['recall']:.4f}   [{r['tp_count']} of {r['targets_count']} targets]"
            )
            lines.append(f"mean object recall {r['mean_obj_recall']:.4f}")
            lines.append(f"{'object':>8}  {'recall':>8}")
            lines += [f"{o:>8}  {v:>8.4f}" for o, v in r["obj_recalls"].items()]
            lines.append(f"{'scene':>8}  {'recall':>8}")
            lines += [f"{o:>8}  {v:>8.4f}" for o, v in r["scene_recalls"].items()]
        if "average_time_per_target" in r:
            lines.append(f"average time per target: {r['average_time_per_target']:.3f} s")
    else:

        def f(key: str) -> str:
            return f"{r[key]:.4f}" if key in r else "-"

        lines.append(
            f"AR {f('bop19_average_recall')}   AR_VSD {f('bop19_average_recall_vsd')}   "
            f"AR_MSSD {f('bop19_average_recall_mssd')}   AR_MSPD {f('bop19_average_recall_mspd')}"
        )
        lines.append(f"{'object':>8}  {'AR':>8}")
        lines += [f"{o:>8}  {v:>8.4f}" for o, v in r.get("obj_average_recalls", {}).items()]
        if r.get("bop19_average_time_per_image", -1) >= 0:
            lines.append(f"average time per image: {r['bop19_average_time_per_image']:.3f} s")
    for name, ar in r["average_recalls"].items():
        # Errors beyond the protocol's own (e.g. ADD) get their average recall listed.
        if name not in ("vsd", "mssd", "mspd"):
            lines.append(f"average recall {name}: {ar:.4f}")
    return "".join(line + "\n" for line in lines)


def _flatten(groups: Optional[list[list[Any]]]) -> Optional[list[Any]]:
    """Repeated comma-separated flags (``--tau 0.1,0.2 --tau 0.3``) as one list, as clap's
    ``value_delimiter`` collects them."""
    return None if groups is None else [v for group in groups for v in group]


def _write(path: str, text: str) -> None:
    with open(path, "w", encoding="utf-8") as f:
        f.write(text + "\n")


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = parser().parse_args(argv)
    try:
        report_text, errors_text = _evaluate_json(
            args.dataset,
            args.results,
            args.protocol,
            threads=args.threads,
            with_errors=args.errors_out is not None,
            visib_mode=args.visib_mode,
            tau=_flatten(args.tau),
            tau_normalized=args.tau_normalized,
            theta=_flatten(args.theta),
            delta=args.delta,
            n_top=args.n_top,
            visib_gt_min=args.visib_gt_min,
            max_sym_disc_step=args.max_sym_disc_step,
            extra_errors=_flatten(args.extra_errors) or [],
            ad_threshold=args.ad_threshold,
        )
        report = json.loads(report_text)
        for warning in report["warnings"]:
            print(f"warning: {warning}", file=sys.stderr)
        sys.stdout.write(table(report))
        if args.out is not None:
            _write(args.out, report_text)
        if args.errors_out is not None and errors_text is not None:
            _write(args.errors_out, errors_text)
    except (OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
