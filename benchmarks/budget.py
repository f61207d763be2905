"""Does a render's cost follow its budget at any size? Wall time and peak memory of a short render at
1920 x 1080 and 3840 x 2160.

    .venv/bin/python benchmarks/budget.py [--scene hud-direct] [--seconds 2] [--workers 2]
                                          [--sizes 1920x1080 3840x2160] [--method backward] [--repeat 1]

For each size, the scene (a preset, written by ``hud-trace export``) gets that retina resolution (its
field of view kept) and ``hud-trace render SCENE --seconds S --workers W`` runs as a command, in a
session of its own. Every 100 ms the benchmark reads the proportional set size (PSS,
/proc/PID/smaps_rollup: shared pages split between the processes that share them) of every process of
that session (the command and its worker processes; a sample costs about 14 ms of CPU at 4K), and
every 5 ms it looks for report.json in the output folder (the image set is written). Per size it
prints the wall time from the command's start until the image set is written and until the command
ends (the analysis follows the image into report.json); the peak of the summed PSS over the whole
command and until the image was written; the peaks of the command's own process and of the largest
worker; and the render's figures from report.json (rays, samples per pixel, setup, the analysis's
seconds). Linux only (/proc).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Seconds between two memory samples: reading every process's smaps_rollup takes about 14 ms of CPU
#: at 4K, which at 20 ms intervals slowed the measured render by a third of a core (0.4 to 0.6 s).
MEMORY_EVERY_S = 0.1
HUD_TRACE = Path(sys.executable).with_name("hud-trace")


def _session_pss_bytes(sid: int) -> dict[int, int]:
    """PSS (bytes) of each process of session ``sid``."""
    out = {}
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            stat = Path(entry.path, "stat").read_text()
            if int(stat.rsplit(")", 1)[1].split()[3]) != sid:  # field 6: the session
                continue
            for line in Path(entry.path, "smaps_rollup").read_text().splitlines():
                if line.startswith("Pss:"):
                    out[int(entry.name)] = int(line.split()[1]) * 1024
                    break
        except (OSError, ValueError, IndexError):
            continue
    return out


def measure(scene: Path, out: Path, seconds: float, workers: int, method: str) -> dict:
    cmd = [str(HUD_TRACE), "render", str(scene), "--method", method, "--seconds", str(seconds),
           "--workers", str(workers), "--out", str(out), "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    peak = peak_image = 0
    each: dict[int, int] = {}
    image_at = None
    sampled = 0.0
    while proc.poll() is None:
        if image_at is None and (out / "report.json").exists():
            image_at = time.perf_counter() - t0
            peak_image = peak
        if time.perf_counter() - sampled >= MEMORY_EVERY_S:
            sampled = time.perf_counter()
            now = _session_pss_bytes(proc.pid)
            peak = max(peak, sum(now.values()))
            for pid, v in now.items():
                each[pid] = max(each.get(pid, 0), v)
        time.sleep(0.005)
    ended = time.perf_counter() - t0
    err = proc.stderr.read()
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} exited {proc.returncode}:\n{err}")
    report = json.loads((out / "report.json").read_text())
    spp = report["image"].get("samples_per_pixel", {}).get("mean", report["method_details"].get("samples_per_pixel"))
    workers = [v for k, v in each.items() if k != proc.pid]
    return {"image_written_s": image_at if image_at is not None else ended, "ended_s": ended,
            "peak_pss_gb": peak / 1e9, "peak_until_image_gb": (peak_image or peak) / 1e9,
            "command_peak_gb": each.get(proc.pid, 0) / 1e9, "worker_peak_gb": max(workers, default=0) / 1e9,
            "rays": report["rays"], "render_s": report["seconds"],
            "setup_s": report["method_details"].get("setup_seconds"),
            "analysis_s": report.get("analysis_seconds"), "samples_per_pixel": spp}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="hud-direct")
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--method", default="backward")
    ap.add_argument("--sizes", nargs="+", default=["1920x1080", "3840x2160"])
    ap.add_argument("--repeat", type=int, default=1, help="runs per size (the table gives each)")
    args = ap.parse_args()
    print(f"{args.scene}, {args.method}, --seconds {args.seconds:g}, --workers {args.workers}; {os.cpu_count()} cores")
    print(f"{'size':>10} {'image written':>14} {'command ends':>13} {'peak PSS':>9} {'to image':>8} {'command':>8} "
          f"{'worker':>7} {'rays':>11} {'spp':>6} {'setup':>6} {'analysis':>8}")
    with tempfile.TemporaryDirectory() as tmp:
        for size in args.sizes:
            w, h = (int(v) for v in size.lower().split("x"))
            folder = Path(tmp) / f"{args.scene}-{size}"
            subprocess.run([str(HUD_TRACE), "export", args.scene, str(folder)], check=True, capture_output=True)
            raw = json.loads((folder / "scene.json").read_text())
            raw["eye"]["resolution"] = [w, h]
            (folder / "scene.json").write_text(json.dumps(raw, indent=1))
            for k in range(args.repeat):
                m = measure(folder, Path(tmp) / f"out-{size}-{k}", args.seconds, args.workers, args.method)
                print(f"{size:>10} {m['image_written_s']:>12.2f} s {m['ended_s']:>11.2f} s "
                      f"{m['peak_pss_gb']:>6.2f} GB {m['peak_until_image_gb']:>5.2f} GB "
                      f"{m['command_peak_gb']:>5.2f} GB {m['worker_peak_gb']:>4.2f} GB {m['rays']:>11,} "
                      + (f"{m['samples_per_pixel']:>6.3f} " if m["samples_per_pixel"] is not None else f"{'-':>6} ") +
                      f"{m['setup_s']:>5.2f}s {m['analysis_s'] or 0:>7.2f}s", flush=True)


if __name__ == "__main__":
    main()
