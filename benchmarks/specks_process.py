"""Planning a mask of 2000 specks, as whole processes: the code before and after, in one run.

Issue 43: on a raw mask of about 2000 specks the lawnmower's plan step took 274-394 ms
(target <= 50 ms), and the denoise stage reported 0.8-1.2 s with ``--no-denoise``. This
runs ``dyntarget plan IMAGE --mask MASK --no-denoise --planner P`` in fresh processes,
alternating between source trees so both see the same machine load:

* ``before``: ``src/`` as committed (``git archive HEAD``), unless ``--before DIR`` names
  another tree;
* ``after``: this working tree's ``src/``;
* ``after + PATCH`` for each ``--patch FILE`` (a unified diff against this tree's ``src/``,
  applied to a copy: a proposed change measured without touching the checkout).

Masks (512 x 512 WFOV px, plan at factor 1, a random image under them):
``specks-1px``: 2000 isolated one-pixel specks, 3 px apart (``plan_speed.specks``);
``specks-2px``: 2000 isolated two-pixel pairs. Each process prints its stage times
(``denoise X ms, plan Y ms``); the table gives the median over ``--repeats`` processes and
the process's wall time.

    python benchmarks/specks_process.py --repeats 5 --out docs/benchmarks/specks_process.json
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from plan_speed import specks  # noqa: E402

_STAGES = re.compile(r"denoise ([\d.]+) ms, plan ([\d.]+) ms")


def pairs(n: int = 2000, size: int = 512, seed: int = 0) -> np.ndarray:
    """``n`` isolated horizontal two-pixel pairs on a ``size`` grid (4 px apart at least)."""
    rng = np.random.default_rng(seed)
    cells = size // 4
    sites = rng.choice(cells * cells, n, replace=False)
    m = np.zeros((size, size), bool)
    r, c = (sites // cells) * 4 + 1, (sites % cells) * 4 + 1
    m[r, c] = m[r, c + 1] = True
    return m


def write_inputs(folder: Path) -> dict[str, tuple[Path, Path]]:
    import rasterio

    img = np.random.default_rng(0).uniform(0.05, 0.3, (4, 512, 512)).astype(np.float32)
    image = folder / "image.tif"
    prof = {"driver": "GTiff", "width": 512, "height": 512, "count": 4, "dtype": "float32"}
    with rasterio.open(image, "w", **prof) as dst:
        dst.write(img)
    out = {}
    for name, mask in (("specks-1px", specks()), ("specks-2px", pairs())):
        path = folder / f"{name}.tif"
        with rasterio.open(path, "w", **{**prof, "count": 1, "dtype": "uint8"}) as dst:
            dst.write(mask.astype(np.uint8), 1)
        out[name] = (image, path)
    return out


def trees(work: Path, before: str | None, patches: list[str]) -> dict[str, Path]:
    out = {}
    if before:
        out["before"] = Path(before)
    else:
        dest = work / "before"
        dest.mkdir()
        archive = subprocess.run(
            ["git", "-C", str(ROOT), "archive", "HEAD", "src/dyntarget"],
            capture_output=True, check=True,
        )  # fmt: skip
        subprocess.run(["tar", "-x", "-C", str(dest)], input=archive.stdout, check=True)
        out["before"] = dest / "src"
    out["after"] = ROOT / "src"
    for patch in patches:
        dest = work / f"patched-{Path(patch).stem}"
        shutil.copytree(ROOT / "src", dest / "src")
        subprocess.run(
            ["patch", "-s", "-p1", "-d", str(dest), "-i", str(Path(patch).resolve())], check=True
        )
        out[f"after + {Path(patch).name}"] = dest / "src"
    return out


def run_once(src: Path, image: Path, mask: Path, planner: str, out: Path) -> dict[str, float]:
    env = {**os.environ, "PYTHONPATH": str(src), "PYTHONWARNINGS": "ignore"}
    cmd = [sys.executable, "-m", "dyntarget", "plan", str(image), "--mask", str(mask)]
    cmd += ["--no-denoise", "--planner", planner, "--out", str(out)]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    wall = time.perf_counter() - t0
    m = _STAGES.search(done.stderr)
    if done.returncode != 0 or m is None:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{done.stderr[-2000:]}")
    return {"denoise_ms": float(m.group(1)), "plan_ms": float(m.group(2)), "wall_s": wall}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--planner", default="lawnmower-transect")
    p.add_argument("--before", help="a src/ tree for 'before' (default: git HEAD's)")
    p.add_argument("--patch", action="append", default=[], help="also measure this patch")
    p.add_argument("--out", help="write the results as JSON here")
    args = p.parse_args(argv)
    from dyntarget.evaluate.bench import machine

    with tempfile.TemporaryDirectory(prefix="specks-") as tmp:
        work = Path(tmp)
        inputs = write_inputs(work)
        variants = trees(work, args.before, args.patch)
        runs: dict[str, dict[str, list[dict[str, float]]]] = {
            m: {v: [] for v in variants} for m in inputs
        }
        load_before = os.getloadavg()[0]
        for _ in range(args.repeats):  # alternate: every variant sees the same load
            for mask_name, (image, mask) in inputs.items():
                for name, src in variants.items():
                    rec = run_once(src, image, mask, args.planner, work / "out.geojson")
                    runs[mask_name][name].append(rec)
        load_after = os.getloadavg()[0]
    rows = []
    for mask_name, by in runs.items():
        for name, recs in by.items():
            rows.append(
                {
                    "mask": mask_name,
                    "code": name,
                    **{
                        f"{k}_median": round(float(np.median([r[k] for r in recs])), 4)
                        for k in ("denoise_ms", "plan_ms", "wall_s")
                    },
                    "runs": recs,
                }
            )
    print(f"| mask | code | denoise (ms) | plan {args.planner} (ms) | process (s) |")
    print("|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['mask']} | {r['code']} | {r['denoise_ms_median']:.1f} | "
            f"{r['plan_ms_median']:.1f} | {r['wall_s_median']:.2f} |"
        )
    doc = {
        "command": "python benchmarks/specks_process.py " + " ".join(argv or sys.argv[1:]),
        "machine": machine(),
        "load_1min_before_after": [round(load_before, 2), round(load_after, 2)],
        "planner": args.planner,
        "repeats": args.repeats,
        "rows": rows,
    }
    if args.out:
        Path(args.out).write_text(json.dumps(doc, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
