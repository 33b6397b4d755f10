"""``helmet-anc batch``: identify many sessions at once, locally or on a Dask cluster."""

from __future__ import annotations

import sys

from sysid.core.errors import HelmetAncError
from sysid.estimation.grid import parse_range
from sysid.identify import IdentificationOptions

ORDER = 60


def register(commands) -> None:
    parser = commands.add_parser("batch", help="identify every session of a folder or CSV manifest; "
                                               "nominal model and uncertainty bound per helmet")
    parser.add_argument("sessions", metavar="SESSIONS",
                        help="folder of session folders (HELMET/HEAD[/CONDITION][/fb|ff]) or CSV manifest "
                             "(helmet, head, condition, path, noise, sweep1, sweep2)")
    parser.add_argument("-o", "--output", required=True, metavar="OUTDIR",
                        help="output folder (new, or an earlier batch output to resume)")
    parser.add_argument("--workers", type=int, metavar="N", help="local worker processes (default: the cores)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="run on this Dask distributed scheduler (tcp://host:8786); workers must see "
                             "the session files and OUTDIR under the same paths")
    parser.add_argument("--refine", action="store_true", help="diagnose and refine each model (refine --auto)")
    parser.add_argument("--force", action="store_true",
                        help="write into OUTDIR even when it holds files helmet-anc batch did not write "
                             "(they are left as they are)")
    parser.add_argument("--gammas", default="10:1000:10", metavar="A:B:STEP", help="smoothing widths (default 10:1000:10)")
    parser.add_argument("--orders", default="1:20", metavar="A:B", help="model orders (default 1:20)")
    parser.set_defaults(handler=run)


def _progress(done: int, total: int, row: dict) -> None:
    if row["status"] == "skipped":
        # A folder with some session files but not all: listed before any work, never silently left out.
        sys.stderr.write(f"skipped {row['session']}: {row['reason']}\n")
        sys.stderr.flush()
        return
    state = "resumed" if row.get("resumed") else row["status"]
    if row["status"] != "ok":
        detail = f": {row['reason']}"
    else:
        ratio = row["rms_over_floor"]
        detail = f", order {row['order']}" + (f", rms {ratio:.2f}x noise floor" if ratio is not None else "")
    sys.stderr.write(f"[{done}/{total}] {row['session']} {state}{detail}\n")
    sys.stderr.flush()


def run(args) -> int:
    from batch import run_batch

    if args.workers is not None and args.workers < 1:
        raise HelmetAncError(f"--workers must be at least 1; found {args.workers}")
    if args.workers is not None and args.scheduler:
        raise HelmetAncError("give --workers (local pool) or --scheduler (Dask cluster), not both")
    options = IdentificationOptions(gammas=parse_range(args.gammas, "--gammas", True),
                                    orders=parse_range(args.orders, "--orders", False))
    result = run_batch(args.sessions, args.output, workers=args.workers, scheduler=args.scheduler,
                       refine=args.refine, options=options, progress=_progress, force=args.force)
    layout = result.layout
    print(f"{len(result.rows)} session(s): {len(result.rows) - result.failed} identified "
          f"({result.resumed} from an earlier run), {result.failed} failed"
          + (f"; {len(result.skipped)} folder(s) skipped: " + "; ".join(f"{s.folder} {s.reason}" for s in result.skipped)
             if result.skipped else ""))
    for (helmet, path), nominal in result.nominals.items():
        info = nominal.model.identification
        print(f"helmet {helmet} {path}: nominal order {nominal.model.order}, bound mean {info['mean_relative_bound']:.3g}, "
              f"largest {info['max_relative_bound']:.3g}")
    print(f"wrote {layout.table_csv}, {layout.table_json}, {layout.summary} and models/, results/, nominal/ in {layout.root}")
    if result.failed:
        sys.stderr.write(f"helmet-anc batch: {result.failed} session(s) failed; see the reason column of {layout.table_csv}\n")
        return 1
    return 0
