"""Outputs that are inputs under another name (sidecars, symlinks, hard links, ``..``), existing
files without --force, scene names that are paths, cache dirs with user files, .part captures
that are symlinks, directories and device nodes as outputs.
"""

from __future__ import annotations

import os
import shutil
import stat

from hostile_cases.common import Case, alias, chain, text_edit


def gen_paths(rng) -> list[Case]:
    cases = []
    # estimate --out over an input (sidecars, robot, the log) named any way
    for _ in range(22):
        target = rng.choice(["fixed.csv", "fixed.timing.toml", "fixed.noise.toml", "robot.toml"])
        p, setup, kind = alias(rng, target)
        argv = ["estimate", "fixed.csv", "--out", p, "--robot", "robot.toml"]
        force = rng.random() < 0.7
        cases.append(Case("paths", f"estimate --out={target} via {kind}", argv + (["--force"] if force else []),
                          setup, "error", force))
    # simulate: --out such that the truth/timing/noise names an input, or --out is an input
    for _ in range(14):
        choice = rng.choice(["robot_as_truth", "scene_as_out", "robot_as_timing", "sensor_as_noise", "log_link"])
        force = rng.random() < 0.6
        if choice == "robot_as_truth":      # scene robot = x.truth.csv; simulate --out x.csv
            setup = chain(lambda w: shutil.copy(w / "robot.toml", w / "sim.truth.csv"),
                           text_edit("scene.toml", "scene.toml",
                                      lambda s: s.replace('robot = "robot.toml"', 'robot = "sim.truth.csv"')))
            # a robot file named .csv is refused by the robot loader? it is TOML text: fine
            argv = ["simulate", "scene.toml", "--out", "sim.csv"]
        elif choice == "scene_as_out":
            p, s2, kind = alias(rng, "scene.toml")
            setup, argv = s2, ["simulate", "scene.toml", "--out", p]
        elif choice == "robot_as_timing":
            setup = chain(lambda w: shutil.copy(w / "robot.toml", w / "sim.timing.toml"),
                           text_edit("scene.toml", "scene.toml",
                                      lambda s: s.replace('robot = "robot.toml"', 'robot = "sim.timing.toml"')))
            argv = ["simulate", "scene.toml", "--out", "sim.csv"]
        elif choice == "sensor_as_noise":
            setup = chain(lambda w: shutil.copy(w / "robot.toml", w / "sim.noise.toml"),
                           text_edit("scene.toml", "scene.toml",
                                      lambda s: s.replace('robot = "robot.toml"', 'robot = "sim.noise.toml"')))
            argv = ["simulate", "scene.toml", "--out", "sim.csv"]
        else:
            p, s2, kind = alias(rng, "robot.toml")
            if rng.random() < 0.3:          # the alias's directory, a new name: a legitimate output (and sidecars)
                p, choice = p.replace(".toml", ".csv"), "log beside an aliased input"
            setup, argv = s2, ["simulate", "scene.toml", "--out", p]
        expect = "ok" if choice == "log beside an aliased input" else "error"
        cases.append(Case("paths", f"simulate {choice}", argv + (["--force"] if force else []), setup, expect, force))
    # calibrate / apply over inputs
    for _ in range(12):
        target = rng.choice(["session.csv", "cal.json", "readings.csv", "notes.md"])
        p, setup, kind = alias(rng, target)
        force = rng.random() < 0.6
        if rng.random() < 0.5:
            out = p if not p.endswith(".csv") else p
            argv = ["calibrate", "session.csv", "--out", out, "--max-steps", "3000", "--walkers", "16"]
            if target == "notes.md":        # the report of cal → notes.md
                argv[3] = p.replace("notes.md", "notes.json")
        else:
            argv = ["apply", "cal.json", "readings.csv", "--out", p]
        # a file that is not an input of the command, named as --out with --force: replacing it is
        # what was asked (the alias itself is the named output; a symlink's or hard link's target,
        # an input or not, must stay as it was)
        asked = force and target not in {"calibrate": ("session.csv",),
                                         "apply": ("cal.json", "readings.csv")}[argv[0]]
        cases.append(Case("paths", f"{argv[0]} over {target} via {kind}", argv + (["--force"] if force else []),
                          setup, "any" if asked else "error", force,
                          outputs=(argv[argv.index("--out") + 1],) if asked else ()))
    # existing user files at an output path, without --force (must be kept)
    for cmd in (["estimate", "fixed.csv", "--out", "existing.csv"],
                ["apply", "cal.json", "readings.csv", "--out", "existing.csv"],
                ["propagate", "--grid", "2", "--draws", "20", "--png", "existing.png"],
                ["compare", "e2e.toml", "--vary", "sensors.seed=1,2", "--png", "existing.png"],
                ["compare", "e2e.toml", "--vary", "sensors.seed=1,2", "--png", "e2e.toml"],
                ["simulate", "scene.toml", "--out", "existing.csv"],
                ["acquire", "--port", "loop://", "--out", "existing.csv", "--duration-s", "0.3"],
                ["acquire", "--port", "loop://", "--out", "cap.bin", "--csv", "existing.csv", "--duration-s", "0.3"]):
        cases.append(Case("paths", f"{cmd[0]} over an existing file", cmd, None, "error"))
    # demo / report / reproduce --out-dir holding the user's files of the same names
    for _ in range(6):
        name = rng.choice(["log.csv", "log.truth.csv", "estimate_dynamic.csv", "estimate_paper.csv"])
        cases.append(Case("paths", f"demo --out-dir with the user's {name}", ["demo", "--out-dir", "od"],
                          lambda w, n=name: ((w / "od").mkdir(), (w / "od" / n).write_text("mine\n")), "error"))
    for name in ("bridge.md", "bridge_noise.png", "README.md"):
        cases.append(Case("paths", f"report --out-dir with the user's {name}",
                          ["report", "--only", "bridge", "--out-dir", "od"],
                          lambda w, n=name: ((w / "od").mkdir(), (w / "od" / n).write_text("mine\n")), "error"))
    cases.append(Case("paths", "reproduce --out-dir with the user's report",
                      ["reproduce", "--scene", "paper_fixed_link1", "--no-stiffness", "--out-dir", "od"],
                      lambda w: ((w / "od").mkdir(), (w / "od" / "paper_reproduction.md").write_text("mine\n")),
                      "error"))
    # scene names that are paths, or the name of a user's file in the report dir
    for _ in range(10):
        name = rng.choice(["../../escaped", "../escaped", "/tmp/escaped_abs", "notes", "sub/../../x",
                           "..", ".", "a/b", "e2e", "..\\\\x"])
        def setup(w, name=name):
            s = (w / "e2e.toml").read_text()
            s = s.replace('name = "paper_floating_link2"', f'name = "{name}"')
            s += '\n[outputs]\nwant = ["report"]\nreports = ["bridge"]\ndir = "."\n' if rng.random() < 0.5 else \
                 '\n[outputs]\nwant = ["report"]\nreports = ["bridge"]\n'
            (w / "named.toml").write_text(s)
        cases.append(Case("paths", f"run scene name {name!r}", ["run", "named.toml"], setup, "any"))
    # cache clear on a directory holding the user's own .pkl files
    for _ in range(5):
        cases.append(Case("paths", "cache clear --cache-dir with user files",
                          ["cache", "clear", "--cache-dir", "mine"],
                          lambda w: ((w / "mine").mkdir(), (w / "mine" / "model.pkl").write_bytes(b"user"),
                                     (w / "mine" / f"{'a' * 64}.pkl").write_bytes(b"also user")), "any"))
    # acquire: an existing .part (kept by an interrupted run) and a .part that is a symlink
    cases.append(Case("paths", "acquire with a kept .part", ["acquire", "--port", "loop://", "--out", "cap.bin",
                                                             "--duration-s", "0.3"],
                      lambda w: (w / "cap.bin.part").write_bytes(b"\xa5\x5a earlier capture"), "any",
                      outputs=("cap.bin.part",)))      # moved into cap.bin with the new bytes appended
    cases.append(Case("paths", "acquire .part symlink onto notes", ["acquire", "--port", "loop://", "--out", "cap.bin",
                                                                    "--duration-s", "0.3"],
                      lambda w: os.symlink("notes.md", w / "cap.bin.part"), "any"))
    cases.append(Case("paths", "acquire .part symlink onto notes --force",
                      ["acquire", "--port", "loop://", "--out", "cap.bin", "--duration-s", "0.3", "--force"],
                      lambda w: os.symlink("notes.md", w / "cap.bin.part"), "any", True))
    # outputs that are directories or device nodes
    for cmd in (["estimate", "fixed.csv", "--out", "{dev}"], ["apply", "cal.json", "readings.csv", "--out", "{dev}"],
                ["simulate", "scene.toml", "--out", "{dev}"], ["estimate", "fixed.csv", "--out", "adir"],
                ["propagate", "--grid", "2", "--draws", "20", "--png", "{dev}"]):
        force = rng.random() < 0.5
        def setup(w):
            (w / "adir").mkdir()
            os.mknod(w / "nulldev", 0o666 | stat.S_IFCHR, os.makedev(1, 3))
        argv = [a.replace("{dev}", "nulldev") for a in cmd] + (["--force"] if force else [])
        cases.append(Case("paths", f"{cmd[0]} --out a device/dir", argv, setup, "error", force))
    # a file created at --out while the run is going (not replaced without --force)
    cases.append(Case("paths", "estimate --out appears during the run",
                      ["estimate", "float.csv", "--out", "late.csv", "--chunk-samples", "64"],
                      None, "any", env={"HOSTILE_LATE_FILE": "late.csv"}))
    return cases
