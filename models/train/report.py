#!/usr/bin/env python3
"""Prints the test accuracies and calibration recorded in model-set manifests as the
Markdown tables of models/README.md.

Usage: report.py models/default [models/w10-h10 ...]
"""
import json
import sys


def pct(v):
    return "–" if v is None else f"{100 * v:.1f}"


def main():
    for path in sys.argv[1:]:
        with open(f"{path}/manifest.json") as f:
            m = json.load(f)
        acc = m["evaluation"]["accuracy"]
        frames = m.get("frames", m["window"])
        print(f"\n#### `{m['name']}`: W = {m['window']} ticks ({frames} frames), H = {m['horizon']}\n")
        kinds = [k for k in ("gcn", "ego", "collective", "cnn1d") if k in acc]
        print("| scenario | " + " | ".join(f"{k} t | {k} future" if k != "gcn" else "gcn t" for k in kinds) + " |")
        print("|---" * (1 + sum(1 if k == "gcn" else 2 for k in kinds)) + "|")
        for scenario in sorted(acc["gcn"]):
            cells = []
            for k in kinds:
                a = acc[k][scenario]
                cells.append(pct(a["t"]) if k == "gcn" else f"{pct(a['t'])} | {pct(a['future'])}")
            print(f"| {scenario.split('_')[1]} | " + " | ".join(cells) + " |")
        cal = m["evaluation"]["calibration"]
        print()
        for k, c in cal.items():
            print(f"- {k}: T = {c['temperature']}, ECE at t (test) {c['ece_test_before']} → {c['ece_test_after']}")
        print(f"- trained in {m['training']['seconds']} s (GCN: {m['training']['gcn']['seconds']} s)")


if __name__ == "__main__":
    main()
