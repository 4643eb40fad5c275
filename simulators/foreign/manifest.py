"""Freezing the foreign world's held-out draws (issue 29, item 4): a manifest that names the held-out
namespace's entropy, the draw ids per class, the world's version and, per draw, the sha256 of its quantised
measured channels, so that a world changed later (to fit an estimator) no longer reproduces them.

    .venv/bin/python -m simulators.foreign.manifest freeze --entropy new --per-class 40 --jobs 2 \
        --cache /tmp/foreign-cache --out benchmarks/heldout/manifest.json
    .venv/bin/python -m simulators.foreign.manifest verify --jobs 2     # regenerate all, compare hashes

`draw_files` simulates one draw into a cache folder (recording CSV and vehicle TOML in the project's formats,
written by the independent world's writer, and the truth record as JSON) or reads it from there; the
benchmark uses the same cache.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import platform
import secrets
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import scipy

from simulators.foreign.draws import CLASSES, DEV_ENTROPY, SWEEP_S, draw, realise
from simulators.foreign.world import measured_sha256
from simulators.independent.files import write_recording

WORLD_VERSION = "foreign-1"
MANIFEST = Path(__file__).resolve().parents[2] / "benchmarks" / "heldout" / "manifest.json"
PROBE_SWEEP_S, PROBE_SETTLE_S = 0.8, 0.1
"""The probes: draw 0 of every class, held-out parameters, on a short sweep (cheap enough for a test)."""


def load_manifest(path: Path = MANIFEST) -> dict[str, Any]:
    return json.loads(path.read_text())


def namespace_entropy(namespace: str, manifest_path: Path = MANIFEST) -> int:
    """DEV_ENTROPY for "dev", the manifest's entropy for "heldout"."""
    if namespace == "dev":
        return DEV_ENTROPY
    if namespace == "heldout":
        return int(load_manifest(manifest_path)["entropy"], 16)
    raise ValueError(f"unknown namespace {namespace!r}; expected dev or heldout")


def source_digest() -> str:
    """sha256 over the world's source files (this package and the independent modules it imports): recorded
    for information; the draws' hashes are what the test holds the world to."""
    root = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    files = sorted(root.glob("*.py")) + sorted((root.parent / "independent").glob("*.py"))
    for path in files:
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def draw_files(namespace: str, entropy: int, label: str, index: int, folder: Path | str) -> dict[str, Any]:
    """The truth record of one draw (with "csv", "toml", "sha256", "simulate_s", "solver_evaluations"),
    simulating it into `folder/namespace/` unless it is there already."""
    stem = Path(folder) / namespace / f"{label}_{index}"
    truth_path = stem.with_suffix(".truth.json")
    if truth_path.exists():
        return json.loads(truth_path.read_text())
    stem.parent.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    recording, truth = realise(draw(entropy, label, index, namespace))
    simulate_s = time.perf_counter() - start
    csv_path, toml_path = stem.with_suffix(".csv"), stem.with_suffix(".toml")
    write_recording(recording.world, csv_path, toml_path)
    truth |= {
        "csv": str(csv_path),
        "toml": str(toml_path),
        "sha256": measured_sha256(recording.world),
        "simulate_s": simulate_s,
        "solver_evaluations": recording.world.solver_evaluations,
    }
    truth_path.write_text(json.dumps(truth, default=float))
    return truth


def probe_sha256(entropy: int, label: str) -> str:
    recording, _ = realise(draw(entropy, label, 0, "heldout", PROBE_SWEEP_S, PROBE_SETTLE_S))
    return measured_sha256(recording.world)


def _work(per_class: int) -> list[tuple[str, int]]:
    """Index by index over all classes, so a run cut short still covers every class."""
    return [(label, index) for index in range(per_class) for label in CLASSES]


def freeze(entropy: int, per_class: int, jobs: int, cache: Path, out: Path) -> dict[str, Any]:
    start = time.perf_counter()
    work = _work(per_class)
    with ProcessPoolExecutor(jobs) as pool:
        futures = [pool.submit(draw_files, "heldout", entropy, label, index, cache) for label, index in work]
        truths = []
        for done, future in enumerate(futures, start=1):
            truths.append(future.result())
            print(
                f"[{done}/{len(work)}] {truths[-1]['id']} {truths[-1]['simulate_s']:.1f} s", file=sys.stderr
            )
        probes = {label: pool.submit(probe_sha256, entropy, label) for label in CLASSES}
        probe_hashes = {label: f.result() for label, f in probes.items()}
    times = [t["simulate_s"] for t in truths]
    manifest = {
        "world": "simulators/foreign",
        "world_version": WORLD_VERSION,
        "source_sha256": source_digest(),
        "entropy": f"{entropy:#034x}",
        "entropy_origin": "secrets.randbits(128), generated once when this manifest was frozen",
        "sweep_s": SWEEP_S,
        "per_class": per_class,
        "classes": {label: [f"heldout/{label}/{i}" for i in range(per_class)] for label in CLASSES},
        "draws": {
            t["id"]: {"sha256": t["sha256"], "solver_evaluations": t["solver_evaluations"]} for t in truths
        },
        "probes": {"sweep_s": PROBE_SWEEP_S, "settle_s": PROBE_SETTLE_S, "index": 0, "sha256": probe_hashes},
        "frozen": {
            "utc": datetime.now(UTC).strftime("%Y-%m-%d %H:%M"),
            "machine": f"{platform.machine()}, {platform.system()}",
            "python": platform.python_version(),
            "numpy": np.__version__,
            "scipy": scipy.__version__,
            "simulate_s_per_draw": {"median": statistics.median(times), "max": max(times)},
            "wall_s": time.perf_counter() - start,
            "jobs": jobs,
        },
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(manifest, indent=1) + "\n")
    return manifest


def verify(manifest_path: Path, jobs: int, cache: Path | None) -> list[str]:
    """Regenerate every held-out draw; the ids whose hash differs from the manifest's."""
    manifest = load_manifest(manifest_path)
    entropy = int(manifest["entropy"], 16)
    ids = [i for ids in manifest["classes"].values() for i in ids]
    folder = cache or Path(f"/tmp/foreign-verify-{int(time.time())}")
    with ProcessPoolExecutor(jobs) as pool:
        futures = {}
        for draw_id in ids:
            _, label, index = draw_id.split("/")
            futures[draw_id] = pool.submit(draw_files, "heldout", entropy, label, int(index), folder)
        return [i for i, f in futures.items() if f.result()["sha256"] != manifest["draws"][i]["sha256"]]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("command", choices=("freeze", "verify"))
    parser.add_argument(
        "--entropy", default=None, help='freeze: "new" (secrets.randbits(128)) or a hex number'
    )
    parser.add_argument("--per-class", type=int, default=40)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--cache", type=Path, default=None, help="folder for the simulated recordings")
    parser.add_argument("--out", type=Path, default=MANIFEST)
    args = parser.parse_args()
    if args.command == "freeze":
        if args.entropy is None:
            parser.error("freeze needs --entropy new (or the hex entropy to re-freeze with)")
        entropy = secrets.randbits(128) if args.entropy == "new" else int(args.entropy, 16)
        cache = args.cache or Path(f"/tmp/foreign-heldout-{entropy:x}")
        manifest = freeze(entropy, args.per_class, args.jobs, cache, args.out)
        print(f"froze {len(manifest['draws'])} draws, entropy {manifest['entropy']}, cache {cache}")
    else:
        changed = verify(args.out, args.jobs, args.cache)
        print(
            "all held-out draws reproduce their hashes" if not changed else f"changed: {', '.join(changed)}"
        )
        sys.exit(1 if changed else 0)


if __name__ == "__main__":
    main()
