"""Fans a scene's dataset out over Ray: one task per sequence, each running the `mochi` binary
(`mochi dataset SCENE --out DIR --sequence NAME`) on whichever node Ray gives it. Run by
scripts/ray-dataset.sh, which makes its virtual environment.

    python scripts/ray_dataset.py SCENE --out DIR [--address ADDR] [--mochi PATH] [--retries N]
        [--no-shared-path]
    python scripts/ray_dataset.py --self-check [--mochi PATH]

Sequences are independent and deterministic (the energies are summed in a fixed order, the
files carry no timings), so any node makes a sequence's exact bytes, and `mochi dataset`
skips sequences already complete in DIR: running this again after a failure redoes only
what is missing. With a shared path (the default; one machine, or a cluster with a network
file system) tasks write into DIR themselves and record their sequence in DIR's manifest
under a lock. With `--no-shared-path` each task makes its sequence in a directory of its own
node and returns the file and its manifest record through Ray's object store; the driver
writes them into DIR. A task whose worker dies or whose `mochi` fails is retried (`--retries`,
default 3); progress is one line per finished sequence.

The self-check starts a local Ray cluster of a head (no CPUs, so it runs no task) and one
worker node of two CPUs, makes a small dataset through it, kills one worker process running
a task once, and checks the dataset is byte for byte the one `mochi dataset` makes in one
process; then the same without a shared path. Prints `ray self-check: P passed, F failed`.
"""

import argparse
import os
import pathlib
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import tomllib

import ray

MANIFEST = "manifest.toml"


def plan(mochi, scene):
    """The dataset's sequences, `(name, split, frames)`, from `mochi dataset --plan`."""
    out = subprocess.run([mochi, "dataset", scene, "--plan"], check=True, capture_output=True, text=True).stdout
    return [(n, s, int(f)) for n, s, f in (line.split() for line in out.splitlines() if line.strip())]


@ray.remote
def make_shared(mochi, scene, out, name, pid_dir):
    """One sequence into the shared directory `out`; returns its name and seconds."""
    if pid_dir:
        pathlib.Path(pid_dir, f"{name}.pid").write_text(str(os.getpid()))
    start = time.perf_counter()
    run = subprocess.run([mochi, "dataset", scene, "--out", out, "--sequence", name], capture_output=True, text=True)
    if run.returncode != 0:
        raise RuntimeError(f"mochi dataset --sequence {name} failed on {socket.gethostname()}:\n{run.stderr[-2000:]}")
    return name, time.perf_counter() - start


@ray.remote
def make_here(mochi, scene, name):
    """One sequence in a directory of this node; returns its name, the file's bytes, its
    manifest record (as TOML text) and the manifest's header, and seconds."""
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        run = subprocess.run([mochi, "dataset", scene, "--out", tmp, "--sequence", name], capture_output=True, text=True)
        if run.returncode != 0:
            raise RuntimeError(f"mochi dataset --sequence {name} failed on {socket.gethostname()}:\n{run.stderr[-2000:]}")
        data = pathlib.Path(tmp, f"{name}.npz").read_bytes()
        manifest = tomllib.loads(pathlib.Path(tmp, MANIFEST).read_text())
    return name, data, manifest, time.perf_counter() - start


def toml_value(v):
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    return repr(v)


def merge_manifest(out, manifest):
    """Adds the task's sequence records to `out`'s manifest (the same scene, solver and
    version, or refused), written whole."""
    path = pathlib.Path(out, MANIFEST)
    header = {k: v for k, v in manifest.items() if k != "sequences"}
    if path.exists():
        current = tomllib.loads(path.read_text())
        mine = {k: v for k, v in current.items() if k != "sequences"}
        if mine != header:
            raise RuntimeError(f"{path}: made from {mine}, the task from {header}")
        records = [r for r in current.get("sequences", []) if r["name"] not in {s["name"] for s in manifest["sequences"]}]
    else:
        records = []
    records += manifest["sequences"]
    text = "".join(f"{k} = {toml_value(v)}\n" for k, v in header.items())
    for r in records:
        text += "\n[[sequences]]\n" + "".join(f"{k} = {toml_value(v)}\n" for k, v in r.items())
    partial = path.with_suffix(".toml.partial")
    partial.write_text(text)
    partial.replace(path)


def complete(out, names):
    """Sequences `out`'s manifest records as written (the rest is `mochi dataset`'s to judge)."""
    path = pathlib.Path(out, MANIFEST)
    if not path.exists():
        return set()
    return {r["name"] for r in tomllib.loads(path.read_text()).get("sequences", [])} & set(names)


def run(scene, out, mochi, address=None, retries=3, shared=True, pid_dir=None, on_done=None):
    """Makes `scene`'s dataset in `out` through Ray; returns seconds."""
    start = time.perf_counter()
    names = [n for n, _, _ in plan(mochi, scene)]
    os.makedirs(out, exist_ok=True)
    ray.init(address=address, logging_level="ERROR", log_to_driver=False)
    try:
        todo = [n for n in names if n not in complete(out, names)]
        print(f"{scene}: {len(names)} sequences, {len(names) - len(todo)} recorded as complete, "
              f"{len(todo)} as Ray tasks on {int(ray.cluster_resources().get('CPU', 0))} CPUs", flush=True)
        if shared:
            # An absolute path: a task's working directory is Ray's, not this one.
            pending = [make_shared.options(max_retries=retries, retry_exceptions=True)
                       .remote(mochi, scene, os.path.abspath(out), n, pid_dir) for n in todo]
        else:
            pending = [make_here.options(max_retries=retries, retry_exceptions=True).remote(mochi, scene, n) for n in todo]
        done = 0
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            result = ray.get(ready[0])
            if shared:
                name, seconds = result
            else:
                name, data, manifest, seconds = result
                target = pathlib.Path(out, f"{name}.npz")
                partial = target.with_suffix(".npz.partial")
                partial.write_bytes(data)
                partial.replace(target)
                merge_manifest(out, manifest)
            done += 1
            print(f"  {name} done ({done}/{len(todo)}) in {seconds:.1f} s", flush=True)
            if on_done:
                on_done(name)
    finally:
        ray.shutdown()
    # Whatever a task left unrecorded (a worker killed after writing) is made or checked here.
    final = subprocess.run([mochi, "dataset", scene, "--out", out], capture_output=True, text=True)
    if final.returncode != 0:
        raise RuntimeError(f"checking {out}: {final.stderr}")
    return time.perf_counter() - start


SELF_CHECK_SCENE = """
name = "ray-check"
gravity = [0.0, -9.81, 0.0]
[mesh]
type = "box"
min = [0.0, -0.05, -0.05]
max = [0.6, 0.05, 0.05]
cells = [16, 3, 3]
[material]
youngs = 2e5
poisson = 0.3
density = 500.0
[[handles]]
name = "clamp"
select = { side = { axis = 0, end = "min" } }
[handles.motion]
directions = [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
speed = [0.1, 0.5]
segment_frames = [5, 10]
[dataset]
train = 4
test = 2
validation = 1
frames = 120
test_frames = 120
"""


def ray_cli(*args):
    return subprocess.run([str(pathlib.Path(sys.executable).parent / "ray"), *args], capture_output=True, text=True)


def self_check(mochi):
    passed = failed = 0
    # The check's own cluster, whatever this machine's Ray state: token authentication off for
    # the head, the worker and the driver alike (a token file that a local `ray.init` left in
    # ~/.ray would otherwise switch the head to it, and the worker could not join).
    os.environ["RAY_AUTH_MODE"] = "disabled"

    def check(ok, what):
        nonlocal passed, failed
        passed += bool(ok)
        failed += not ok
        print(("ok   " if ok else "FAIL ") + what, flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        scene = os.path.join(tmp, "ray-check.toml")
        pathlib.Path(scene).write_text(SELF_CHECK_SCENE)
        alone = os.path.join(tmp, "alone")
        start = time.perf_counter()
        subprocess.run([mochi, "dataset", scene, "--out", alone], check=True, capture_output=True)
        single = time.perf_counter() - start
        files = sorted(p.name for p in pathlib.Path(alone).glob("*.npz"))

        def same(out):
            return [p.name for p in sorted(pathlib.Path(out).glob("*.npz"))] == files and all(
                pathlib.Path(out, f).read_bytes() == pathlib.Path(alone, f).read_bytes() for f in files)

        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        head = f"127.0.0.1:{port}"
        env_tmp = os.path.join(tmp, "ray")
        started = ray_cli("start", "--head", f"--port={port}", "--num-cpus=0", "--node-ip-address=127.0.0.1",
                          f"--temp-dir={env_tmp}", "--include-dashboard=false", "--disable-usage-stats")
        check(started.returncode == 0, "a head node starts" + ("" if started.returncode == 0 else f": {started.stderr[-500:]}"))
        worker = ray_cli("start", f"--address={head}", "--num-cpus=2", "--node-ip-address=127.0.0.1",
                         "--disable-usage-stats")
        check(worker.returncode == 0, "a worker node of 2 CPUs joins it" + ("" if worker.returncode == 0 else f": {worker.stderr[-500:]}"))
        try:
            # A shared path; one worker process running a task killed once, mid-run.
            out = os.path.join(tmp, "ray")
            pids = os.path.join(tmp, "pids")
            os.makedirs(pids)
            killed = []

            def kill_one(name):
                if killed:
                    return
                # Another task's worker, still running (its pid file written, its file not yet).
                for pid_file in sorted(pathlib.Path(pids).glob("*.pid")):
                    other = pid_file.stem
                    if other != name and not pathlib.Path(out, f"{other}.npz").exists():
                        try:
                            os.kill(int(pid_file.read_text()), signal.SIGKILL)
                            killed.append(other)
                        except ProcessLookupError:
                            continue
                        return

            seconds = run(scene, out, mochi, address=head, pid_dir=pids, on_done=kill_one)
            check(len(killed) == 1, f"one worker killed mid-run (its task: {killed[0] if killed else 'none'})")
            check(same(out), f"through Ray ({seconds:.1f} s; one process {single:.1f} s) the dataset is the bytes of one process")
            again = run(scene, out, mochi, address=head)
            check(same(out), f"run again, it finds every sequence complete ({again:.1f} s)")
            # No shared path: files through the object store.
            out = os.path.join(tmp, "ray-store")
            seconds = run(scene, out, mochi, address=head, shared=False)
            check(same(out), f"without a shared path ({seconds:.1f} s) the dataset is the same bytes")
        except Exception as e:  # a crash is a failed check, counted in the closing line
            check(False, f"the run through Ray failed: {type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}")
        finally:
            ray_cli("stop", "--force")
    print(f"ray self-check: {passed} passed, {failed} failed", flush=True)
    return failed == 0


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", nargs="?")
    parser.add_argument("--out")
    parser.add_argument("--address", help="a Ray cluster's address (default: a local instance)")
    parser.add_argument("--mochi", default="target/release/mochi", help="the mochi binary on every node")
    parser.add_argument("--retries", type=int, default=3)
    parser.add_argument("--no-shared-path", action="store_true")
    parser.add_argument("--self-check", action="store_true")
    args = parser.parse_args()
    mochi = os.path.abspath(args.mochi)
    if not os.access(mochi, os.X_OK):
        sys.exit(f"{mochi}: no mochi binary there (cargo build --release -p mochi-trainer, or --mochi PATH)")
    if args.self_check:
        sys.exit(0 if self_check(mochi) else 1)
    if not args.scene or not args.out:
        parser.error("SCENE and --out are needed")
    seconds = run(args.scene, args.out, mochi, args.address, args.retries, not args.no_shared_path)
    print(f"{args.scene}: dataset in {args.out} in {seconds:.1f} s")


if __name__ == "__main__":
    main()
