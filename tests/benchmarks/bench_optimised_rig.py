"""Paper D sec. 5.3 on Paper D's rig chain: the nominal stitched catenary and its optimised designs OC1
(heights) and OC2 (spacing), cases paper_d_stitched{,_oc1,_oc2}_300_rig, each run as a virtual HIL of FMUs
and against `pantohil rig-emulator` (the rig file's chain) model-paced (lockstep) and rig-paced (the
emulator's real-time clock). Prints per run the status, spans, the force's std/max/min (as reported, 20 Hz),
the std's and the span's difference from the virtual run in % of its std, the reductions of OC1 and OC2
against the nominal per way of running, and the machine's load. Not a timed test.

    python tests/benchmarks/bench_optimised_rig.py [--pacing model rig] [--repeats 1]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

CASES_DIR = Path(__file__).resolve().parents[2] / "models" / "data" / "cases"
DESIGNS = {"nominal": "paper_d_stitched_300_rig", "OC1": "paper_d_stitched_oc1_300_rig",
           "OC2": "paper_d_stitched_oc2_300_rig"}


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pantohil.orchestrator.cli", *args], capture_output=True, text=True)


def result(out: Path, proc: subprocess.CompletedProcess) -> dict:
    if not (out / "summary.json").exists():
        raise SystemExit(f"{out.name}: no summary.json (exit {proc.returncode}): {proc.stderr.strip()[-400:]}")
    s = json.loads((out / "summary.json").read_text())
    span = np.loadtxt(out / "steady_span.csv", delimiter=",", skiprows=1)[:, 3] if s["spans"] else None
    f = s["contact_force"]["filtered_20hz"]
    return {"exit": proc.returncode, "status": s["status"], "spans": s["spans"], "std": f["std_N"], "max": f["max_N"],
            "min": f["min_N"], "span": span, "link": s.get("link", {})}


def on_rig(tmp: Path, case: Path, pacing: str, tag: str) -> dict:
    emu = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "rig-emulator", "--listen",
                            "127.0.0.1:0", "--paced-by", pacing, "--case", str(case)],
                           stdout=subprocess.PIPE, text=True)
    try:
        address = emu.stdout.readline().split("listening on ")[1].split()[0]
        out = tmp / tag
        proc = cli("run", str(case), "--hardware", address, "--paced-by", pacing, "--out", str(out), "--quiet",
                   "--set", "link.receive_timeout_s=1.0")
    finally:
        emu.terminate()
        emu.wait()
    return result(out, proc)


def difference(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(((a - a.mean()) - (b - b.mean())) ** 2)) / b.std())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pacing", nargs="+", choices=("model", "rig"), default=["model", "rig"])
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args()
    print(f"uptime: {os.popen('uptime').read().strip()}", flush=True)
    table: dict[str, dict[str, list[dict]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for design, name in DESIGNS.items():
            case = CASES_DIR / f"{name}.toml"
            out = tmp / f"{design}-virtual"
            virtual = result(out, cli("run", str(case), "--out", str(out), "--quiet"))
            table[design] = {"virtual": [virtual]}
            print(f"{design} ({name}) virtual: {virtual['status']} after {virtual['spans']} spans, std "
                  f"{virtual['std']:.4f} N, max {virtual['max']:.2f} N, min {virtual['min']:.2f} N", flush=True)
            for pacing in args.pacing:
                for i in range(args.repeats):
                    load = os.getloadavg()[0]
                    r = on_rig(tmp, case, pacing, f"{design}-{pacing}-{i}")
                    table[design].setdefault(pacing, []).append(r)
                    ok = virtual["span"] is not None and r["span"] is not None
                    std_pct = 100 * (r["std"] / virtual["std"] - 1)
                    span_pct = 100 * difference(r["span"], virtual["span"]) if ok else float("nan")
                    ln = r["link"]
                    print(f"{design} {pacing}-paced run {i}: exit {r['exit']}, {r['status']} after {r['spans']} spans, "
                          f"std {r['std']:.4f} N ({std_pct:+.3f} % of the virtual), max {r['max']:.2f}, min "
                          f"{r['min']:.2f}; span {span_pct:.3f} % rms of the virtual std; link lost {ln.get('lost')}, "
                          f"late {ln.get('late')}, predicted {ln.get('predicted')}, uncovered {ln.get('uncovered')}; "
                          f"load {load:.1f} -> {os.getloadavg()[0]:.1f}", flush=True)
    for way in ["virtual", *args.pacing]:
        nominal = np.median([r["std"] for r in table["nominal"][way]])
        cut = {d: 100 * (1 - np.median([r["std"] for r in table[d][way]]) / nominal) for d in ("OC1", "OC2")}
        print(f"{way}: std reduction against the nominal catenary OC1 {cut['OC1']:.2f} %, OC2 {cut['OC2']:.2f} % "
              f"(Paper D Table 2, DSA-380 on its rig: 11.24 %, 21.87 %)", flush=True)
    print(f"uptime: {os.popen('uptime').read().strip()}", flush=True)


if __name__ == "__main__":
    main()
