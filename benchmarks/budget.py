"""Does a render's cost follow its budget at any size? Wall time and peak memory of a short render at
1920 x 1080 and 3840 x 2160.

    .venv/bin/python benchmarks/budget.py [--scene hud-direct] [--seconds 2] [--workers 2]
                                          [--sizes 1920x1080 3840x2160] [--method backward] [--repeat 1]

For each size, the scene (a preset, written by ``hud-trace export``) gets that retina resolution (its
field of view kept) and ``hud-trace render SCENE --seconds S --workers W`` runs as a command, in a
session of its own. Every 20 ms the benchmark sums the proportional set size (PSS, /proc/PID/smaps_rollup:
shared pages split between the processes that share them) of every process of that session (the command
and its worker processes), and notes when image.exr appears in the output folder. It prints, per size:
the wall time from the command's start until image.exr, preview.png and report.json are written (the
image); until the command ends (with the analysis that follows the image into report.json); the peak
of the summed PSS; and the render's own figures from report.json (rays, samples per pixel, setup).
Linux only (/proc).
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
HUD_TRACE = Path(sys.executable).with_name("hud-trace")


def _session_pss_bytes(sid: int) -> int:
    """Summed PSS (bytes) of the processes of session ``sid``."""
    total = 0
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            stat = Path(entry.path, "stat").read_text()
            if int(stat.rsplit(")", 1)[1].split()[3]) != sid:  # field 6: the session
                continue
            for line in Path(entry.path, "smaps_rollup").read_text().splitlines():
                if line.startswith("Pss:"):
                    total += int(line.split()[1]) * 1024
                    break
        except (OSError, ValueError, IndexError):
            continue
    return total


def measure(scene: Path, out: Path, seconds: float, workers: int, method: str) -> dict:
    cmd = [str(HUD_TRACE), "render", str(scene), "--method", method, "--seconds", str(seconds),
           "--workers", str(workers), "--out", str(out), "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    peak = 0
    image_at = None
    while proc.poll() is None:
        peak = max(peak, _session_pss_bytes(proc.pid))
        if image_at is None and (out / "report.json").exists():
            image_at = time.perf_counter() - t0
        time.sleep(0.02)
    ended = time.perf_counter() - t0
    err = proc.stderr.read()
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} exited {proc.returncode}:\n{err}")
    report = json.loads((out / "report.json").read_text())
    spp = report["image"].get("samples_per_pixel", {}).get("mean", report["method_details"].get("samples_per_pixel"))
    return {"image_written_s": image_at if image_at is not None else ended, "ended_s": ended,
            "peak_pss_gb": peak / 1e9, "rays": report["rays"], "render_s": report["seconds"],
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
    print(f"{'size':>10} {'image written':>14} {'command ends':>13} {'peak PSS':>9} {'rays':>11} {'spp':>6} "
          f"{'setup':>6} {'analysis':>8}")
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
                print(f"{size:>10} {m['image_written_s']:>12.2f} s {m['ended_s']:>11.2f} s {m['peak_pss_gb']:>6.2f} GB "
                      f"{m['rays']:>11,} {m['samples_per_pixel']:>6.3f} {m['setup_s']:>5.2f}s "
                      f"{m['analysis_s'] or 0:>7.2f}s", flush=True)


if __name__ == "__main__":
    main()
