"""``lidarstat evaluate RESULT --reference REF``: filter errors, confusion matrix, kappa."""

from __future__ import annotations

import json

import numpy as np

from . import _options as opt

def _run(args):
    from ..classify import class_scores, filter_errors
    from ..errors import InvalidParameterError
    from ..io import read
    from ._app import Output, check_plan

    check_plan([args.result, args.reference], Output("--json", args.json, "json"))
    res = read(args.result)
    ref = read(args.reference)
    if len(res) != len(ref):
        raise InvalidParameterError(
            f"{args.result}: {len(res)} points but the reference {args.reference} has "
            f"{len(ref)}; evaluate compares the same points in the same order")
    r = np.asarray(res[args.field]).astype(np.int64)
    t = np.asarray(ref[args.reference_field]).astype(np.int64)
    gcodes = args.ground_codes
    rg = np.isin(r, gcodes)
    tg = np.isin(t, gcodes if args.reference_ground_codes is None
                 else args.reference_ground_codes)
    fe = filter_errors(rg, tg)
    out = {"result": str(args.result), "reference": str(args.reference),
           "field": args.field, "reference_field": args.reference_field,
           "ground_codes": list(gcodes), "ground_object": fe.to_dict()}
    if args.classes:
        out["classes"] = class_scores(r, t).to_dict()
    if args.json:
        from .._shared._atomic import atomic_path

        with atomic_path(args.json) as tmp:
            tmp.write_text(json.dumps(out, indent=2))
    if not args.quiet:
        cm = fe.confusion
        print(f"{args.result} vs {args.reference}  ({fe.n} points)")
        print(f"  Type I  (ground -> object) {100 * fe.type_i:6.2f} %")
        print(f"  Type II (object -> ground) {100 * fe.type_ii:6.2f} %")
        print(f"  total error                {100 * fe.total:6.2f} %")
        print(f"  kappa                      {fe.kappa:6.3f}")
        print("  confusion (rows reference, columns result):")
        print(f"              ground    object\n  ground  {cm[0, 0]:>9} {cm[0, 1]:>9}\n"
              f"  object  {cm[1, 0]:>9} {cm[1, 1]:>9}")
        if args.classes:
            cs = out["classes"]
            labels = cs["labels"]
            print(f"  classes: accuracy {cs['accuracy']:.4f}, kappa {cs['kappa']:.4f}")
            print("  ref\\res " + "".join(f"{v:>9}" for v in labels))
            for lab, row in zip(labels, cs["confusion"]):
                print(f"  {lab:>7} " + "".join(f"{v:>9}" for v in row))
    return 0


def register(sub):
    """Add the ``evaluate`` subcommand."""
    s = sub.add_parser("evaluate", help="Type I/II/total error, confusion matrix and kappa",
                       description="Compare the classes of RESULT with those of REF (same "
                       "points, same order): ground/object errors as defined by Sithole and "
                       "Vosselman (2004), their confusion matrix and Cohen's kappa; "
                       "--classes adds the full multi-class comparison.")
    s.add_argument("result")
    s.add_argument("--reference", required=True)
    s.add_argument("--field", default="classification", help="class field of RESULT")
    s.add_argument("--reference-field", default="classification",
                   help="class field of REF")
    s.add_argument("--ground-codes", type=opt.codes_list, default="2,8,9,11",
                   help="codes counted as ground (comma-separated)")
    s.add_argument("--reference-ground-codes", type=opt.codes_list, default=None,
                   help="ground codes of REF when they differ")
    s.add_argument("--classes", action="store_true", help="full multi-class comparison")
    s.add_argument("--json", default=None, help="write the scores as JSON here")
    s.add_argument("-q", "--quiet", action="store_true")
    s.set_defaults(func=_run)
