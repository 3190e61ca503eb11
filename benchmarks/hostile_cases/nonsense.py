"""Logs in wrong units or with swapped/dead channels, absurd options and file fields.
"""

from __future__ import annotations


from hostile_cases.common import Case, const, csv_edit, csv_edit_commented, scale_cols, swap, text_edit


def gen_nonsense(rng) -> list[Case]:
    cases = []
    # logs in wrong units / swapped / dead
    transforms = [
        ("tau in N·mm", lambda: scale_cols(["tau1", "tau2"], 1000.0)),
        ("tau in kN·m", lambda: scale_cols(["tau1", "tau2"], 1e-3)),
        ("wrench in kN", lambda: scale_cols(["Fx", "Fz", "My"], 1e-3)),
        ("wrench in mN", lambda: scale_cols(["Fx", "Fz", "My"], 1e3)),
        ("Fx/Fz swapped", lambda: swap("Fx", "Fz")),
        ("tau1/tau2 swapped", lambda: swap("tau1", "tau2")),
        ("dead tau2", lambda: const("tau2", 0.0)),
        ("dead tau1", lambda: const("tau1", 0.0)),
        ("dead Fz", lambda: const("Fz", 0.0)),
        ("constant Fz", lambda: const("Fz", 3.0)),
        ("all zero", lambda: (lambda d: d.assign(**{c: 0.0 for c in d.columns if c != "t"}))),
        ("angles in degrees", lambda: scale_cols(["q1", "q2"], 57.29577951308232)),
        ("rates in deg/s", lambda: scale_cols(["dq1", "dq2"], 57.29577951308232)),
        ("Fz sign flipped", lambda: scale_cols(["Fz"], -1.0)),
        ("torques sign flipped", lambda: scale_cols(["tau1", "tau2"], -1.0)),
        ("My in N·mm", lambda: scale_cols(["My"], 1000.0)),
        ("random channel ×1e3", None),
        ("random channel ×1e-3", None),
    ]
    for _ in range(70):
        label, make = rng.choice(transforms)
        log = rng.choice(["fixed", "float", "poke"])
        if make is None:
            col = rng.choice(["tau1", "tau2", "Fx", "Fz", "My"])
            fn = scale_cols([col], 1e3 if "×1e3" in label else 1e-3)
            label = label.replace("random channel", col)
        else:
            fn = make()
        if log == "float" and "angles" in label and rng.random() < 0.5:
            fn = scale_cols(["q1", "q2", "theta"], 57.29577951308232)
        argv = ["estimate", "bad.csv"] + (["--json"] if rng.random() < 0.3 else []) + \
            (["--method", "paper"] if rng.random() < 0.2 else [])
        cases.append(Case("nonsense", f"estimate {log} log with {label}", argv,
                          csv_edit(f"{log}.csv", "bad.csv", fn), "refuse"))
    # absurd estimate options
    opts = [("--gain", ["1e-300", "1e-9", "1e9", "1e300", "1e-6"]),
            ("--torque-sigma", ["1e300", "1e-300", "1e-30", "1e30", "1e6,1e-300"]),
            ("--ft-sigma", ["1e300,1e300,1e300", "1e-300,0.1,0.01", "0.1,0.1,1e300", "1e-30,1e-30,1e-30"]),
            ("--velocity-sigma", ["1e300", "1e30"]),
            ("--encoder-counts", ["1e300", "0.5", "1e30", "3"]),
            ("--timing", ["delay:1e300", "delay:100", "delay:1e9", "delay:5", "delay:1e-300x"]),
            ("--false-alarm-rate", ["1e-300/h", "1e-300/sample", "1e300/h"]),
            ("--threshold", ["1e300", "1e-300"]),
            ("--quiet-window", ["0.55:0.95", "0.6:0.9", "0.5:1.0", "0.3:1.2", "0:1.5", "0.4:1.1"])]
    for _ in range(50):
        opt, vals = rng.choice(opts)
        v = rng.choice(vals)
        log = "fixed" if opt == "--quiet-window" else rng.choice(["fixed", "float"])
        cases.append(Case("nonsense", f"estimate {opt} {v}", ["estimate", f"{log}.csv", f"{opt}={v}"], None,
                          "refuse"))
    # sidecars and robot files with absurd fields
    sidecars = [("fixed.timing.toml", "[timing]\ndefault = \"delay:100\"\n"),
                ("fixed.timing.toml", "[timing]\nwrench = \"delay:1e300\"\n"),
                ("fixed.timing.toml", "[timing]\ntau = \"delay:1e9\"\n"),
                ("fixed.noise.toml", "[noise]\ntorque_sigma_Nm = [1e300]\nft_sigma = [0.1, 0.1, 0.01]\n"),
                ("fixed.noise.toml", "[noise]\ntorque_sigma_Nm = [1e-300]\nft_sigma = [0.1, 0.1, 0.01]\n"),
                ("fixed.noise.toml", "[noise]\ntorque_sigma_Nm = [0.01]\nft_sigma = [1e-300, 1e-300, 1e-300]\n"),
                ("fixed.noise.toml", "[noise]\ntorque_sigma_Nm = [0.01]\nft_sigma = [0.1, 0.1, 0.01]\n"
                                     "encoder_counts = 1000000000000000000\n")]
    for _ in range(14):
        name, text = rng.choice(sidecars)
        cases.append(Case("nonsense", f"estimate with {name}: {text.splitlines()[-1][:40]}",
                          ["estimate", "fixed.csv"], lambda w, n=name, t=text: (w / n).write_text(t), "refuse"))
    robot_edits = [("length_m = 0.205", "length_m = 1e300"), ("length_m = 0.205", "length_m = 205.0"),
                   ("length_m = 0.215", "length_m = 1e-300"), ("mass_kg = 0.351", "mass_kg = 1e300"),
                   ("mass_kg = 0.351", "mass_kg = 351.0"), ("mass_kg = 0.080", "mass_kg = 1e-12"),
                   ("gravity_m_per_s2 = 9.81", "gravity_m_per_s2 = 0.0"),
                   ("gravity_m_per_s2 = 9.81", "gravity_m_per_s2 = 9810.0"),
                   ("gravity_m_per_s2 = 9.81", "gravity_m_per_s2 = 1e-300"),
                   ("inertia_kgm2 = 0.00207", "inertia_kgm2 = 1e300"),
                   ("inertia_kgm2 = 0.00207", "inertia_kgm2 = 2070.0"),
                   ("stiffness = [5000.0, 5000.0, 500.0]", "stiffness = [1e300, 5000.0, 500.0]"),
                   ("com_m = 0.171", "com_m = 171.0")]
    for _ in range(26):
        a, b = rng.choice(robot_edits)
        cmd = rng.choice([["estimate", "float.csv", "--robot", "robot.toml"],
                          ["simulate", "scene.toml", "--out", "o.csv"],
                          ["propagate", "--robot", "robot.toml", "--grid", "2", "--draws", "20"]])
        cases.append(Case("nonsense", f"{cmd[0]} robot {b}", cmd,
                          text_edit("robot.toml", "robot.toml", lambda s, a=a, b=b: s.replace(a, b, 1)), "refuse"))
    scene_edits = [("kp = 500.0", "kp = 1e12"), ("kp = 500.0", "kp = 1e300"), ("kd = 10.0", "kd = 1e300"),
                   ("q0_rad = [-0.4, -0.8]", "q0_rad = [-23.0, -46.0]"),
                   ("q0_rad = [-0.4, -0.8]", "q0_rad = [-0.4, -0.8]\namplitude_rad = [0.1, 0.1]\nfrequency_Hz = [1e6, 1e6]"),
                   ("t_on_s = 0.1", "t_on_s = 5.0"), ("t_off_s = 0.2", "t_off_s = 50.0"),
                   ("magnitude_N = 5.0", "magnitude_N = 1e300"), ("magnitude_N = 5.0", "magnitude_N = 5e6"),
                   ("sample_rate_Hz = 1000.0", "sample_rate_Hz = 1e9"),
                   ("sample_rate_Hz = 1000.0", "sample_rate_Hz = 1e-3"),
                   ("ft_noise = [0.1, 0.1, 0.01]", "ft_noise = [1e300, 0.1, 0.01]"),
                   ("ft_noise = [0.1, 0.1, 0.01]", "ft_noise = [1e-300, 1e-300, 1e-300]"),
                   ('torque_model = "bridge"', 'torque_model = "gaussian"\ntorque_noise_Nm = 1e300'),
                   ("duration_s = 0.3", "duration_s = 1e9"), ("seed = 11", "seed = -1"),
                   ("rtol = 1e-6", "rtol = 1e-300")]
    for _ in range(30):
        a, b = rng.choice(scene_edits)
        cmd = rng.choice([["simulate", "scene.toml", "--out", "o.csv"], ["run", "scene.toml", "--only", "estimates"]])
        cases.append(Case("nonsense", f"{cmd[0]} scene {b.splitlines()[-1]}", cmd,
                          text_edit("scene.toml", "scene.toml", lambda s, a=a, b=b: s.replace(a, b, 1)), "refuse"))
    # calibrate / apply / acquire
    cal_cases = [
        (["calibrate", "session.csv", "--out", "c.json", "--lever-arm-m", "205"], None),
        (["calibrate", "session.csv", "--out", "c.json", "--lever-arm-m", "1e300"], None),
        (["calibrate", "session.csv", "--out", "c.json", "--lever-arm-m", "1e-300"], None),
        (["calibrate", "session.csv", "--out", "c.json", "--mass-std-g", "1e300"], None),
        (["calibrate", "lever.csv", "--out", "c.json"],
         text_edit("session.csv", "lever.csv", lambda s: s.replace(",0.205,", ",205,"))),
        (["calibrate", "lever.csv", "--out", "c.json"],
         text_edit("session.csv", "lever.csv", lambda s: s.replace(",0.205,", ",1e300,"))),
        (["apply", "cal.json", "counts.csv"],
         text_edit("readings.csv", "counts.csv", lambda s: s.replace("reading_unit=mV", "reading_unit=counts"))),
        (["apply", "cal.json", "counts.csv"],
         csv_edit_commented("readings.csv", "counts.csv", lambda d: d.assign(reading=d["reading"] * 8.4e5))),
        (["acquire", "--port", "loop://", "--out", "cap.bin", "--guided", "0,10", "--lever-arm-m", "205"], None),
        (["propagate", "--contact", "2,0.8,1", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--contact", "2,0.8,1,7", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--force", "7,1,3", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--gain", "1e-300", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--rate", "1e-9", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--ft-noise", "1e300,1e300,1e300", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--ft-noise", "1e-300,1e-300,1e-300", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--torque-noise-Nm", "1e-300", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--force", "1e300,0", "--grid", "2", "--draws", "20"], None),
        (["bridge", "--bandwidth-Hz", "1e300"], None),
        (["bridge", "--strain-per-Nm", "1e-300"], None),
        (["bridge", "--averaging", "1000000000000"], None),
        (["bridge", "s2.toml"], text_edit("sensor.toml", "s2.toml", lambda s: s.replace("gain = 1.0", "gain = 1e300"))),
        (["bridge", "s2.toml"], text_edit("sensor.toml", "s2.toml", lambda s: s.replace("excitation_V = 5.0", "excitation_V = 5e6"))),
        (["bridge", "s2.toml"], text_edit("sensor.toml", "s2.toml", lambda s: s.replace("gain = 1.0", "gain = 1e-300"))),
        (["bridge", "s2.toml"], text_edit("sensor.toml", "s2.toml", lambda s: s.replace("temperature_K = 300.0", "temperature_K = 1e300"))),
        (["flexure", "d2.toml", "--single-level"], text_edit("design.toml", "d2.toml",
                                                             lambda s: s.replace('preset = "6061-T6"', 'preset = "6061-T6"\nE_GPa = 68.9e9'))),
        (["flexure", "d2.toml", "--single-level"], text_edit("design.toml", "d2.toml",
                                                             lambda s: s.replace("thickness_mm = 2.2", "thickness_mm = 1e300"))),
        (["flexure", "d2.toml", "--single-level"], text_edit("design.toml", "d2.toml",
                                                             lambda s: s.replace("rated_torque_Nm = 2.0", "rated_torque_Nm = 1e300"))),
        (["simulate", "scene.toml", "--out", "o.csv", "--duration", "1e9"], None),
        (["run", "scene.toml", "--seed", "-1", "--only", "estimates"], None),
        (["run", "e2e.toml", "--seed", "-1"], None),
        (["demo", "--seed", "-1"], None),
    ]
    for argv, setup in cal_cases:
        cases.append(Case("nonsense", " ".join(argv[:1] + argv[2:])[:70], argv, setup, "refuse"))
    # compare / sweep: every point failing must not exit 0
    for cmd in ("compare", "sweep"):
        for vary in ("sensors.sample_rate_Hz=-1,-2", "controller.kp=-5", "nosuch.key=1,2"):
            cases.append(Case("nonsense", f"{cmd} all points fail {vary}",
                              [cmd, "e2e.toml", "--vary", vary, "--executor", "local"], None, "error"))
    return cases
