"""One case as a real `torquebench` process in a fresh copy of the fixture: its files before and
after, its memory (the process group's RSS), its time, and the outcome it is classified as.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import signal
import stat
import subprocess
import threading
import time
from pathlib import Path

from hostile_cases import common
from hostile_cases.common import Case


def case_env(work: Path, extra: dict | None = None) -> dict:
    env = dict(os.environ, MPLBACKEND="Agg", PYVISTA_OFF_SCREEN="true", PYTHONPATH=str(common.REPO),
               TORQUEBENCH_CACHE=str(common.SHARED_CACHE))
    env.pop("TORQUEBENCH_DEBUG", None)
    env.update(extra or {})
    return env


def snapshot(root: Path) -> dict:
    """{relative path: ('l', target) | ('f', sha256) | ('d',) | ('o', mode)} of everything under root."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            rel = str(p.relative_to(root))
            if rel.startswith("shared-cache"):
                continue
            st = os.lstat(p)
            if stat.S_ISLNK(st.st_mode):
                out[rel] = ("l", os.readlink(p))
            elif stat.S_ISREG(st.st_mode):
                h = hashlib.sha256()
                with open(p, "rb") as f:
                    if st.st_size > (64 << 20):
                        h.update(f"{st.st_size}:{st.st_mtime_ns}".encode())
                    else:
                        h.update(f.read())
                out[rel] = ("f", h.hexdigest(), st.st_ino)
            elif stat.S_ISDIR(st.st_mode):
                out[rel] = ("d",)
            else:
                out[rel] = ("o", st.st_mode, st.st_rdev)
    return out


def rss_of_group(pgid: int) -> int:
    total = 0
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat") as f:
                parts = f.read().rsplit(")", 1)[1].split()
            if int(parts[2]) != pgid:
                continue
            total += int(parts[21]) * os.sysconf("SC_PAGE_SIZE")
        except (OSError, IndexError, ValueError):
            continue
    return total


_SETUP_LOCK = threading.Lock()


def run_case(case: Case, base: Path, fixture: Path, timeout: float, max_rss: float, index: int) -> dict:
    croot = base / f"case{index:04d}"
    work = croot / "a" / "b" / "work"
    work.parent.mkdir(parents=True)
    shutil.copytree(fixture, work, symlinks=True)
    with _SETUP_LOCK:                # a setup may chdir: the working directory is the process's, not a thread's
        cwd_before = os.getcwd()
        try:
            if case.setup is not None:
                case.setup(work)
        finally:
            os.chdir(cwd_before)
    before = snapshot(croot)
    env = case_env(work, case.env)
    start = time.perf_counter()
    proc = subprocess.Popen([common.PY, "-m", "torquebench", *case.argv], cwd=work, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    killed = None
    out_chunks = {"out": b"", "err": b""}
    import threading

    def pump(stream, key):
        out_chunks[key] = stream.read()
    ts = [threading.Thread(target=pump, args=(proc.stdout, "out")),
          threading.Thread(target=pump, args=(proc.stderr, "err"))]
    for t in ts:
        t.start()
    sent_int = False
    late = case.env.get("HOSTILE_LATE_FILE")
    late_done = False
    while proc.poll() is None:
        el = time.perf_counter() - start
        if late and not late_done and el > 1.0:
            (work / late).write_text("the user's file, written during the run\n")
            before[str((work / late).relative_to(croot))] = snapshot(croot).get(str((work / late).relative_to(croot)))
            late_done = True
        if case.sigint_after is not None and not sent_int and el > case.sigint_after:
            os.killpg(proc.pid, signal.SIGINT)
            sent_int = True
        if el > timeout:
            killed = "timeout"
        elif rss_of_group(proc.pid) > max_rss:
            killed = "memory"
        if killed:
            os.killpg(proc.pid, signal.SIGKILL)
            break
        time.sleep(0.05)
    proc.wait()
    for t in ts:
        t.join()
    elapsed = time.perf_counter() - start
    try:
        os.killpg(proc.pid, signal.SIGKILL)          # stray workers of the group
    except ProcessLookupError:
        pass
    after = snapshot(croot)
    rec = {"class": case.cls, "name": case.name, "argv": case.argv, "expect": case.expect,
           "exit": proc.returncode, "time_s": round(elapsed, 2), "killed": killed,
           "stdout": out_chunks["out"].decode("utf-8", "replace")[-3000:],
           "stderr": out_chunks["err"].decode("utf-8", "replace")[-3000:]}
    rec["changed"] = changes(before, after, case, work, croot)
    rec["outcome"] = classify(rec, case, work)
    shutil.rmtree(croot, ignore_errors=True)
    return rec


def changes(before, after, case, work, croot) -> list[str]:
    """Files that existed and changed/vanished (not allowed), and files outside the work dir."""
    wrel = str(work.relative_to(croot))
    bad = []
    allowed = {os.path.normpath(os.path.join(wrel, a)) for a in case.outputs}
    for rel, was in before.items():
        now = after.get(rel)
        if was is None or was[0] == "d":
            continue
        if now is None or now[:2] != was[:2]:
            if rel in allowed:          # a file the case names as replaceable (with --force)
                continue
            bad.append(f"{'removed' if now is None else 'changed'}: {rel}")
    for rel in after:
        if rel not in before and not (rel == wrel or rel.startswith(wrel + os.sep)):
            bad.append(f"created outside the work dir: {rel}")
    return bad


def classify(rec, case, work) -> str:
    err = rec["stderr"]
    lines = [ln for ln in err.splitlines() if ln.strip()]
    code = rec["exit"]
    if rec["killed"]:
        # a run the user asked to be long is fine once its estimated cost was shown first
        if case.expect == "cost" and "estimated" in err.lower() and rec["killed"] == "timeout":
            return "ok"
        return "runaway"
    if "Traceback (most recent call last)" in err or "internal error" in err or code == 1 or \
            (code is not None and code < 0 and case.expect != "interrupt"):
        return "traceback"
    if rec["changed"]:
        return "data_loss"
    if case.expect == "interrupt":      # one line about the interrupt, after any progress lines of the run
        if code == 130 and (len(lines) <= 1 or ("interrupted" in lines[-1]
                                                 and sum("interrupted" in ln for ln in lines) == 1)):
            return "ok"
        if code == 0:
            return "ok"                 # finished before the signal
        return "unclear"
    if code == 2 and len(lines) != 1:
        return "unclear"
    if code == 2 and "not found" in err.lower() and any((work / a).exists() for a in case.argv if isinstance(a, str)
                                                         and not a.startswith("-") and "/" not in a):
        return "unclear"
    text = (rec["stdout"] + err).lower()
    if case.expect == "ok":
        return "ok" if code == 0 else "refused_valid"
    if case.expect in ("refuse", "error") and code == 0 and "warning" not in text:
        return "silent"
    if case.expect == "cost" and code == 0 and "estimated" not in text:
        return "silent"
    return "ok"
