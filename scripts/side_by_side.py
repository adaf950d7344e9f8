"""Shared by scripts/compare-peers and scripts/mrclam-leave-outs: whole processes timed
side by side, and the MRPT `kf-slam` peer prepared on MRCLAM dataset 6.

Not a script of its own; the two scripts import it from this folder.
"""

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TOOL = Path(sys.argv[0]).name


def datasets() -> Path:
    folder = Path(os.environ.get("SLAM_DATASETS", ROOT.parent / "shared" / "datasets"))
    if not folder.is_dir():
        sys.exit(f"{TOOL}: dataset folder {folder} not found (set SLAM_DATASETS)")
    return folder


def host_sim() -> Path:
    target = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    binary = target / "release" / "host-sim"
    if not binary.is_file():
        sys.exit(f"{TOOL}: {binary} not found: run `cargo build --release -p host-sim` first")
    return binary


def timed(cmd, cwd=None, env=None) -> float:
    """Seconds from starting `cmd` to its exit; a failed run ends the script with its stderr."""
    start = time.perf_counter()
    done = subprocess.run(cmd, cwd=cwd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                          stderr=subprocess.PIPE)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        sys.exit(f"{TOOL}: {' '.join(map(str, cmd))} failed ({done.returncode}):\n"
                 f"{done.stderr.decode(errors='replace')}")
    return elapsed


def warn_if_busy():
    """Both sides of a pairing must have the machine to themselves: say so when it is not."""
    try:
        load = os.getloadavg()[0]
    except OSError:
        return
    if load > 0.5:
        print(f"{TOOL}: warning: the machine is busy (load average {load:.1f} over the last "
              "minute); another process on the cores skews both sides differently", file=sys.stderr)


def kf_slam_peer(scratch: Path):
    """MRPT `kf-slam` on MRCLAM ds6 robot 1, prepared in `scratch`: (command, working folder)."""
    ds = datasets() / "mrclam" / "dataset6"
    peer_dir = ROOT.parent / "shared" / "peers" / "mrpt-kf-slam"
    missing = [tool for tool in ("kf-slam", "cmake", "make", "g++") if shutil.which(tool) is None]
    if missing:
        sys.exit(f"{TOOL}: {', '.join(missing)} not found; the MRPT peer needs "
                 "apt-get install mrpt-apps libmrpt-obs-dev libmrpt-maps-dev libmrpt-slam-dev g++ cmake "
                 f"(see {peer_dir / 'run.sh'})")
    work = scratch / "mrpt-kf"
    prepared = subprocess.run(["bash", str(peer_dir / "run.sh"), str(ds), "1", str(work)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    if prepared.returncode != 0:
        sys.exit(f"{TOOL}: preparing the MRPT peer ({peer_dir / 'run.sh'}) failed "
                 f"({prepared.returncode}):\n{prepared.stderr.decode(errors='replace')}")
    return ["kf-slam", "kf-slam.ini", "in.rawlog"], work


def mrclam_replay(binary: Path, out: Path):
    """`host-sim replay` of MRCLAM ds6 robot 1 as the pairing with `kf-slam` runs it: like
    with like, `kf-slam` writes its log and final state, no pictures; host-sim writes
    metrics.json, the two TUM trajectories and landmarks.csv without them."""
    return [str(binary), "replay", "-d", "mrclam:dataset6", "--quiet", "--no-plots", "--out", str(out)]
