"""`torquebench reproduce`: run the paper's scenes and write reports/paper_reproduction.md.

A view over the stage graph: each scene's ``paper_scores`` stage (fed by simulation → sensor_log
for a dynamic scene, static_holds for a static one), cached, asked by
torquebench.reports.reproduction.results, which also writes the report."""

from __future__ import annotations

from pathlib import Path

from userio.errors import InputError

HELP = "reproduce the paper's Tables III-V, the posture sweep and Fig. 4 (writes ./reproduction/paper_reproduction.md)"
EXAMPLES = """\
torquebench reproduce --scene paper_fixed_link1 --no-stiffness --out-dir out/repro
torquebench reproduce --quick
"""


def add_arguments(parser) -> None:
    parser.add_argument("--scene", action="append", metavar="NAME",
                        help="run only this shipped scene (repeatable; default: all), e.g. paper_fixed_link1")
    parser.add_argument("--out-dir", type=Path, default=None,
                        help="directory to write the report to, created if missing (default: "
                             "./reproduction/; the shipped reports/ only with --regenerate-shipped)")
    parser.add_argument("--regenerate-shipped", action="store_true",
                        help="replace the repository's reports/paper_reproduction.md (all scenes)")
    parser.add_argument("--no-stiffness", action="store_true",
                        help="skip the integrator × scene stiffness table")
    parser.add_argument("--quick", action="store_true",
                        help="a reduced stiffness table (one scene, BDF and RK4, 0.2 s)")
    parser.add_argument("--force", action="store_true",
                        help="replace report files in --out-dir that `reproduce` did not write there")


def run(args) -> int:
    from torquebench.io import REPO_ROOT, print_json
    from torquebench.reports import reproduction as rr

    names = args.scene or rr.ALL_SCENES
    for n in names:
        if n not in rr.ALL_SCENES:
            raise InputError(f"--scene: unknown scene {n!r}; known: {', '.join(rr.ALL_SCENES)}")
    if args.regenerate_shipped and (args.scene or args.quick):
        raise InputError("--regenerate-shipped: the shipped report covers every scene at full "
                         "settings; drop --scene/--quick or write elsewhere with --out-dir")
    from userio.outputs import Outputs, default_dir

    out_dir = default_dir(args.out_dir, default="reproduction", shipped_dir=REPO_ROOT / "reports",
                          regenerate=args.regenerate_shipped)
    plan = Outputs(force=args.force)
    plan.directory("--out-dir", out_dir, shipped=args.regenerate_shipped, names=["reproduction"])
    plan.check()                                       # created if missing; user files kept
    with plan.active():                                # every write obeys it
        return _reproduce(args, names, out_dir)


def _reproduce(args, names, out_dir) -> int:
    from torquebench.io import print_json
    from torquebench.reports import reproduction as rr

    results = rr.results(names, quick=args.quick, stiffness=not args.no_stiffness)
    paths = rr.write(results, Path(out_dir))
    summary = rr.summary(results)
    summary["written"] = [str(p) for p in paths]
    if args.json:
        print_json(summary)
    else:
        print(f"wrote {paths[0]} (+ {len(paths) - 1} PNG)")
        for name, tab in summary["tables"].items():
            if "dynamic" in tab:
                ours = 1e3 * tab["dynamic"]["mean"]["|p|"]
                theirs = f"{1e3 * tab['paper_table']['mean'][5]:.1f} mm" if tab["paper_table"] else "–"
                print(f"{name}: mean |p| error {ours:.2f} mm (ours, dynamic); paper: {theirs}")
            elif isinstance(tab, dict) and "max_location_error_mm" in tab:
                print(f"{name}: max location {tab['max_location_error_mm']:.2f} mm, "
                      f"max force {tab['max_force_error_N']:.3f} N, {tab['flagged']} flagged")
    return 0
